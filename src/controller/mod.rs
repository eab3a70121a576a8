//! The conventional baseline: Raibert-style gaits with QP force distribution (Raibert 1986; MIT Cheetah-Software's BalanceController; docs/controller.md).
//! Gait scheduling, Raibert foot placement, Minitaur four-bar leg kinematics, the stance-force
//! QP (clarabel), and the Minitaur and Ant controllers, which implement the same `Policy`
//! interface as every other policy and run through the same `Env`, scored by the same reward.
pub(crate) mod active_set;
pub mod ant;
pub mod ant_row;
pub mod baseline;
pub mod command;
mod follow;
pub mod force_qp;
pub mod fourbar;
pub mod gait;
pub mod measure;
pub mod minitaur;

/// Raibert's foothold relative to the hip: p_f = (T_st / 2) v + k (v - v_des), per horizontal
/// axis; add the hip position for a world target.
pub(crate) fn raibert_foothold(stance_duration: f64, velocity: [f64; 2], desired: [f64; 2], gain: f64) -> [f64; 2] {
    std::array::from_fn(|i| 0.5 * stance_duration * velocity[i] + gain * (velocity[i] - desired[i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn foothold_formula() {
        // At the set-point the foot lands half a stance stride ahead of the hip.
        let p = raibert_foothold(0.25, [0.4, 0.0], [0.4, 0.0], 0.03);
        assert!((p[0] - 0.05).abs() < 1e-12 && p[1] == 0.0);
        // Too fast: step further ahead to brake; too slow: less far.
        let fast = raibert_foothold(0.25, [0.6, 0.0], [0.4, 0.0], 0.03);
        assert!((fast[0] - (0.075 + 0.006)).abs() < 1e-12);
        let slow = raibert_foothold(0.25, [0.2, -0.1], [0.4, 0.0], 0.03);
        assert!((slow[0] - (0.025 - 0.006)).abs() < 1e-12);
        assert!((slow[1] - (-0.0125 - 0.003)).abs() < 1e-12);
    }
}
