//! Minitaur leg kinematics: a diamond four-bar with a zero-length ground link. Two motors on one
//! axis swing upper links of length `UPPER`; lower links of length `LOWER` meet at the foot.
//!
//! Leg frame: origin on the motor axis, x forward, z up. Motor angles use the observation's
//! convention (radians from straight up; the outer motor's knee swings to the front, the inner
//! motor's to the back), so a symmetric leg has equal angles and pi points it straight down.

/// Motor axis to knee (m), as in `models/minitaur.xml`.
pub(crate) const UPPER: f64 = 0.1177;
/// Knee to foot (m).
pub(crate) const LOWER: f64 = 0.2;

fn knees(outer: f64, inner: f64) -> ([f64; 2], [f64; 2]) {
    ([UPPER * outer.sin(), UPPER * outer.cos()], [-UPPER * inner.sin(), UPPER * inner.cos()])
}

/// Foot position for motor angles (outer, inner); None where the lower links cannot meet.
pub fn forward(outer: f64, inner: f64) -> Option<[f64; 2]> {
    let (a, b) = knees(outer, inner);
    let (dx, dz) = (b[0] - a[0], b[1] - a[1]);
    let d = (dx * dx + dz * dz).sqrt();
    if !(1e-12..=2.0 * LOWER).contains(&d) {
        return None;
    }
    let h = (LOWER * LOWER - 0.25 * d * d).sqrt();
    let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
    // The two circle intersections lie on the perpendicular bisector; the foot is the lower one.
    let n = [dz / d, -dx / d];
    let n = if n[1] > 0.0 { [-n[0], -n[1]] } else { n };
    Some([mid[0] + h * n[0], mid[1] + h * n[1]])
}

/// Motor angles (outer, inner) that put the foot at `foot`; None when out of reach.
pub(crate) fn inverse(foot: [f64; 2]) -> Option<[f64; 2]> {
    let r = (foot[0] * foot[0] + foot[1] * foot[1]).sqrt();
    if r <= LOWER - UPPER || r >= LOWER + UPPER {
        return None;
    }
    // Angle of the hip-to-foot line from straight down, positive towards the front.
    let swing = foot[0].atan2(-foot[1]);
    // Angle between that line and each upper link (law of cosines).
    let spread = ((UPPER * UPPER + r * r - LOWER * LOWER) / (2.0 * UPPER * r)).clamp(-1.0, 1.0).acos();
    let pi = std::f64::consts::PI;
    Some([pi - (swing + spread), pi - spread + swing])
}

/// d(foot) / d(motor angles): rows x, z; columns outer, inner.
pub(crate) fn jacobian(outer: f64, inner: f64) -> Option<[[f64; 2]; 2]> {
    let h = 1e-6;
    let d_outer = (forward(outer + h, inner)?, forward(outer - h, inner)?);
    let d_inner = (forward(outer, inner + h)?, forward(outer, inner - h)?);
    let col = |(p, m): ([f64; 2], [f64; 2]), k: usize| (p[k] - m[k]) / (2.0 * h);
    Some([[col(d_outer, 0), col(d_inner, 0)], [col(d_outer, 1), col(d_inner, 1)]])
}

/// Motor torques (outer, inner) that make the ground push on the foot with `force` (x, z):
/// tau = -J^T f.
pub(crate) fn torques_for_ground_force(outer: f64, inner: f64, force: [f64; 2]) -> Option<[f64; 2]> {
    let j = jacobian(outer, inner)?;
    Some([-(j[0][0] * force[0] + j[1][0] * force[1]), -(j[0][1] * force[0] + j[1][1] * force[1])])
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn symmetric_leg_points_straight_down() {
        for theta in [PI / 2.0, 5.0 * PI / 8.0, 0.75 * PI] {
            let f = forward(theta, theta).unwrap();
            let depth = -UPPER * theta.cos() + (LOWER * LOWER - (UPPER * theta.sin()).powi(2)).sqrt();
            assert!(f[0].abs() < 1e-12 && (f[1] + depth).abs() < 1e-12, "{theta}: {f:?}");
        }
        // Zero leg-model action (5pi/8) puts the foot about 0.213 m below the axis (PyBullet's minitaur.py: 0.215).
        assert!((forward(5.0 * PI / 8.0, 5.0 * PI / 8.0).unwrap()[1] + 0.2129).abs() < 1e-3);
    }

    #[test]
    fn inverse_round_trips() {
        for x in [-0.08, -0.03, 0.0, 0.05, 0.09] {
            for z in [-0.14, -0.18, -0.22, -0.26] {
                let q = inverse([x, z]).unwrap();
                let p = forward(q[0], q[1]).unwrap();
                assert!((p[0] - x).abs() < 1e-9 && (p[1] - z).abs() < 1e-9, "({x}, {z}) -> {q:?} -> {p:?}");
            }
        }
        assert!(inverse([0.0, -0.5]).is_none());
        assert!(inverse([0.0, -0.05]).is_none());
    }

    #[test]
    fn positive_swing_moves_the_foot_back_and_torques_do_virtual_work() {
        let t = 5.0 * PI / 8.0;
        let p = forward(t + 0.1, t - 0.1).unwrap();
        assert!(p[0] < -0.01, "{p:?}");
        // Virtual work: tau . dq = -f . dp for any small motion.
        let f = [3.0, 20.0];
        let tau = torques_for_ground_force(t, t + 0.05, f).unwrap();
        let dq = [1e-5, -2e-5];
        let p0 = forward(t, t + 0.05).unwrap();
        let p1 = forward(t + dq[0], t + 0.05 + dq[1]).unwrap();
        let work_joint = tau[0] * dq[0] + tau[1] * dq[1];
        let work_foot = -(f[0] * (p1[0] - p0[0]) + f[1] * (p1[1] - p0[1]));
        assert!((work_joint - work_foot).abs() < 1e-8, "{work_joint} vs {work_foot}");
    }
}
