//! PyBullet's Minitaur leg model (bullet3's `pybullet_envs/bullet/minitaur.py`, `ConvertFromLegModel`): per leg one
//! swing and one extension command in [-1, 1] become the two motors' desired angles.
use std::f64::consts::PI;

/// Motor `i` belongs to leg `i / 2`; legs are FL, BL, FR, BR.
pub(crate) const NUM_MOTORS: usize = 8;
pub(crate) const NUM_LEGS: usize = 4;

/// Sign of the swing term for motor `i`: (-1)^i on the left legs, -(-1)^i on the right legs.
pub(crate) fn swing_sign(motor: usize) -> f64 {
    let alternating = if motor.is_multiple_of(2) { 1.0 } else { -1.0 };
    if motor < 4 {
        alternating
    } else {
        -alternating
    }
}

/// `action[0..4]` swing the legs, `action[4..8]` extend them.
pub fn motor_angles_from_leg_model(action: &[f64]) -> [f64; NUM_MOTORS] {
    assert_eq!(action.len(), NUM_MOTORS);
    let mut angles = [0.0; NUM_MOTORS];
    for (i, angle) in angles.iter_mut().enumerate() {
        let leg = i / 2;
        let extension = action[NUM_LEGS + leg];
        let swing = action[leg];
        *angle = PI - (PI / 4.0) * (extension + 1.5) + swing_sign(i) * (PI / 4.0) * swing;
    }
    angles
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_action_is_five_eighths_pi() {
        for a in motor_angles_from_leg_model(&[0.0; 8]) {
            assert!((a - 5.0 * PI / 8.0).abs() < 1e-12);
        }
    }

    #[test]
    fn swing_moves_the_two_motors_of_a_leg_apart() {
        let mut action = [0.0; 8];
        action[0] = 0.5; // front-left swing
        action[6] = 0.5; // front-right extension
        let a = motor_angles_from_leg_model(&action);
        let base = 5.0 * PI / 8.0;
        assert!((a[0] - (base + PI / 8.0)).abs() < 1e-12);
        assert!((a[1] - (base - PI / 8.0)).abs() < 1e-12);
        // The other legs are untouched except front-right, whose extension shrinks both angles.
        assert!((a[2] - base).abs() < 1e-12 && (a[3] - base).abs() < 1e-12);
        assert!((a[4] - (base - PI / 8.0)).abs() < 1e-12 && (a[5] - (base - PI / 8.0)).abs() < 1e-12);
        assert_eq!([swing_sign(4), swing_sign(5), swing_sign(6), swing_sign(7)], [-1.0, 1.0, -1.0, 1.0]);
    }
}
