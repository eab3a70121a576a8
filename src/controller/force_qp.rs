//! Stance-force distribution (REFERENCE §4): find ground reaction forces f at the stance feet
//! that best produce a desired body wrench b,
//!     minimise (A f - b)' S (A f - b) + alpha |f|^2
//!     subject to |f_x|, |f_y| <= mu f_z and f_min <= f_z <= f_max,
//! with A = [I ... I; [r_1]x ... [r_n]x] (r_i: foot position relative to the centre of mass).
//! Solved by clarabel. `Planar` has no lateral foot forces (Minitaur has no abduction): forces
//! (f_x, f_z) per foot, wrench (F_x, F_z, M_x, M_y, M_z); roll is still controlled through the
//! vertical forces of feet on either side, and yaw through the fore-aft forces of feet on either
//! side.
use anyhow::{bail, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use std::collections::HashMap;

use nalgebra::{DMatrix, DVector, Vector3};

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Dimension {
    /// Forces (f_x, f_y, f_z) per foot; wrench (F_x, F_y, F_z, M_x, M_y, M_z).
    Spatial,
    /// Forces (f_x, f_z) per foot; wrench (F_x, F_z, M_x, M_y, M_z).
    Planar,
}

pub struct ForceQp {
    pub dimension: Dimension,
    pub friction: f64,
    pub f_min: f64,
    pub f_max: f64,
    /// Weight of each wrench row (S diagonal).
    pub wrench_weights: Vec<f64>,
    /// Regularisation alpha on |f|^2.
    pub regularisation: f64,
    /// clarabel's default settings (tolerances 1e-8, equilibration, iterative refinement)
    /// instead of the faster ones used per control tick; the reference the fast ones are
    /// tested against.
    pub precise: bool,
    /// Cached solvers by number of stance feet (see `solve`).
    solvers: HashMap<usize, DefaultSolver<f64>>,
}

impl ForceQp {
    pub fn new(
        dimension: Dimension,
        friction: f64,
        f_min: f64,
        f_max: f64,
        wrench_weights: Vec<f64>,
        regularisation: f64,
    ) -> ForceQp {
        ForceQp {
            dimension,
            friction,
            f_min,
            f_max,
            wrench_weights,
            regularisation,
            precise: false,
            solvers: HashMap::new(),
        }
    }

    fn force_dim(&self) -> usize {
        match self.dimension {
            Dimension::Spatial => 3,
            Dimension::Planar => 2,
        }
    }

    /// Rows of A for one foot at `r` (relative to the centre of mass).
    fn wrench_map(&self, r: Vector3<f64>) -> DMatrix<f64> {
        let cross = r.cross_matrix();
        match self.dimension {
            Dimension::Spatial => {
                let mut m = DMatrix::zeros(6, 3);
                m.view_mut((0, 0), (3, 3)).copy_from(&nalgebra::Matrix3::identity());
                m.view_mut((3, 0), (3, 3)).copy_from(&cross);
                m
            }
            // Forces f_x, f_z (f_y = 0); rows F_x, F_z, M_x, M_y, M_z.
            Dimension::Planar => DMatrix::from_row_slice(
                5,
                2,
                &[
                    1.0,
                    0.0,
                    0.0,
                    1.0,
                    cross[(0, 0)],
                    cross[(0, 2)],
                    cross[(1, 0)],
                    cross[(1, 2)],
                    cross[(2, 0)],
                    cross[(2, 2)],
                ],
            ),
        }
    }

    /// The cost the QP minimises, for forces `forces`.
    pub fn objective(&self, feet: &[Vector3<f64>], wrench: &[f64], forces: &[f64]) -> f64 {
        let err = self.wrench(feet, forces) - DVector::from_column_slice(wrench);
        let weighted: f64 = err.iter().zip(&self.wrench_weights).map(|(e, w)| w * e * e).sum();
        weighted + self.regularisation * forces.iter().map(|f| f * f).sum::<f64>()
    }

    /// The wrench a set of foot forces produces.
    pub fn wrench(&self, feet: &[Vector3<f64>], forces: &[f64]) -> DVector<f64> {
        let a = self.stacked_map(feet);
        &a * DVector::from_column_slice(forces)
    }

    fn stacked_map(&self, feet: &[Vector3<f64>]) -> DMatrix<f64> {
        let k = self.force_dim();
        let rows = if k == 3 { 6 } else { 5 };
        let mut a = DMatrix::zeros(rows, k * feet.len());
        for (i, r) in feet.iter().enumerate() {
            a.view_mut((0, k * i), (rows, k)).copy_from(&self.wrench_map(*r));
        }
        a
    }

    /// Forces for the stance feet at `feet` (flattened per foot), or an error when the solver
    /// fails; callers fall back to a safe default and count it.
    pub fn solve(&mut self, feet: &[Vector3<f64>], wrench: &[f64]) -> Result<Vec<f64>> {
        let k = self.force_dim();
        let n = k * feet.len();
        if feet.is_empty() {
            bail!("no stance feet");
        }
        let a = self.stacked_map(feet);
        if wrench.len() != a.nrows() || self.wrench_weights.len() != a.nrows() {
            bail!("wrench and weights must have {} entries", a.nrows());
        }
        let s = DMatrix::from_diagonal(&DVector::from_column_slice(&self.wrench_weights));
        let b = DVector::from_column_slice(wrench);
        let p = (a.transpose() * &s * &a + DMatrix::identity(n, n) * self.regularisation) * 2.0;
        let q = -(a.transpose() * &s * &b) * 2.0;

        // Inequalities G f <= h, per foot: friction pyramid faces and normal-force bounds.
        let mut g_rows: Vec<Vec<(usize, f64)>> = Vec::new();
        let mut h = Vec::new();
        for foot in 0..feet.len() {
            let base = k * foot;
            let z = base + k - 1;
            for t in 0..k - 1 {
                g_rows.push(vec![(base + t, 1.0), (z, -self.friction)]);
                g_rows.push(vec![(base + t, -1.0), (z, -self.friction)]);
                h.extend([0.0, 0.0]);
            }
            g_rows.push(vec![(z, 1.0)]);
            h.push(self.f_max);
            g_rows.push(vec![(z, -1.0)]);
            h.push(-self.f_min);
        }
        let q = q.as_slice().to_vec();
        let values = upper_triangle_values(&p);
        // One solver per number of stance feet, built once: later ticks only update P and q
        // (the constraints depend on the foot count alone). Presolve must be off for updates.
        let solver = match self.solvers.entry(feet.len()) {
            std::collections::hash_map::Entry::Occupied(e) => {
                let s = e.into_mut();
                s.update_P(&values).map_err(|e| anyhow::anyhow!("QP update failed: {e:?}"))?;
                s.update_q(&q).map_err(|e| anyhow::anyhow!("QP update failed: {e:?}"))?;
                s
            }
            std::collections::hash_map::Entry::Vacant(v) => {
                let p_upper = dense_pattern_upper(n, values);
                let g = rows_to_csc(&g_rows, n);
                let cones = [SupportedConeT::NonnegativeConeT(h.len())];
                let settings = if self.precise {
                    DefaultSettingsBuilder::default().verbose(false).presolve_enable(false).build()
                } else {
                    DefaultSettingsBuilder::default()
                        .verbose(false)
                        .max_iter(50)
                        .presolve_enable(false)
                        // An absolute duality gap of 1e-6 (the relative one stays at 1e-8: the
                        // solver's objective omits b'Sb, so a relative test would stop early)
                        // and no iterative refinement: about half the solve time
                        // (benches/controller.rs, README), same cost to 1e-4 (tests below).
                        .tol_gap_abs(1e-6)
                        .tol_feas(1e-6)
                        .iterative_refinement_enable(false)
                        .build()
                }
                .expect("valid settings");
                let solver = DefaultSolver::new(&p_upper, &q, &g, &h, &cones, settings)
                    .map_err(|e| anyhow::anyhow!("QP setup failed: {e:?}"))?;
                v.insert(solver)
            }
        };
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(solver.solution.x.clone()),
            status => bail!("QP not solved: {status:?}"),
        }
    }
}

/// The upper triangle of a square matrix, column by column, zeros included (a fixed pattern,
/// so a cached solver can take new values).
fn upper_triangle_values(m: &DMatrix<f64>) -> Vec<f64> {
    (0..m.ncols()).flat_map(|c| (0..=c).map(move |r| m[(r, c)])).collect()
}

fn dense_pattern_upper(n: usize, values: Vec<f64>) -> CscMatrix<f64> {
    let (mut colptr, mut rowval) = (vec![0], Vec::new());
    for c in 0..n {
        rowval.extend(0..=c);
        colptr.push(rowval.len());
    }
    CscMatrix::new(n, n, colptr, rowval, values)
}

fn rows_to_csc(rows: &[Vec<(usize, f64)>], ncols: usize) -> CscMatrix<f64> {
    let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); ncols];
    for (r, row) in rows.iter().enumerate() {
        for &(c, v) in row {
            cols[c].push((r, v));
        }
    }
    let (mut colptr, mut rowval, mut nzval) = (vec![0], Vec::new(), Vec::new());
    for col in cols {
        for (r, v) in col {
            rowval.push(r);
            nzval.push(v);
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows.len(), ncols, colptr, rowval, nzval)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feet() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(0.2, 0.1, -0.2),
            Vector3::new(-0.2, 0.1, -0.2),
            Vector3::new(0.2, -0.1, -0.2),
            Vector3::new(-0.2, -0.1, -0.2),
        ]
    }

    fn qp() -> ForceQp {
        ForceQp::new(Dimension::Spatial, 0.6, 1.0, 100.0, vec![1.0; 6], 1e-6)
    }

    fn check_constraints(qp: &ForceQp, f: &[f64]) {
        let k = qp.force_dim();
        for foot in f.chunks(k) {
            let fz = foot[k - 1];
            assert!(fz >= qp.f_min - 1e-6 && fz <= qp.f_max + 1e-6, "{foot:?}");
            for t in &foot[..k - 1] {
                assert!(t.abs() <= qp.friction * fz + 1e-6, "friction cone violated: {foot:?}");
            }
        }
    }

    #[test]
    fn reproduces_a_feasible_wrench_inside_the_cones() {
        let mut qp = qp();
        // A wrench made from forces that satisfy the constraints is feasible.
        let truth = [2.0, 1.0, 20.0, -1.0, 0.5, 15.0, 3.0, -2.0, 18.0, 0.0, 1.0, 12.0];
        let wrench = qp.wrench(&feet(), &truth);
        let f = qp.solve(&feet(), wrench.as_slice()).unwrap();
        check_constraints(&qp, &f);
        let got = qp.wrench(&feet(), &f);
        assert!((got - &wrench).norm() < 1e-3 * wrench.norm(), "wrench not reproduced");
    }

    #[test]
    fn infeasible_wrench_is_approximated_within_the_constraints() {
        let mut qp = qp();
        // Pulling the robot down and sideways harder than friction allows.
        let f = qp.solve(&feet(), &[50.0, 0.0, -10.0, 0.0, 0.0, 0.0]).unwrap();
        check_constraints(&qp, &f);
        let f = qp.solve(&feet()[..2], &[0.0, 0.0, 500.0, 0.0, 0.0, 0.0]).unwrap();
        check_constraints(&qp, &f);
        assert!(f.chunks(3).all(|c| (c[2] - qp.f_max).abs() < 1e-3));
    }

    /// The per-tick settings against clarabel's defaults on random stance configurations:
    /// wrenches made from admissible forces (feasible) and arbitrary ones (not reproducible).
    #[test]
    fn fast_settings_match_the_default_solver_on_random_cases() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for dimension in [Dimension::Spatial, Dimension::Planar] {
            let rows = if dimension == Dimension::Spatial { 6 } else { 5 };
            let make = |precise| ForceQp {
                dimension,
                wrench_weights: vec![1.0, 1.0, 1.0, 10.0, 10.0, 10.0][..rows].to_vec(),
                precise,
                ..ForceQp::new(dimension, 0.7, 0.5, 80.0, vec![], 1e-4)
            };
            let (mut fast, mut reference) = (make(false), make(true));
            let k = fast.force_dim();
            for case in 0..200 {
                let n = rng.random_range(2..=4);
                let feet: Vec<Vector3<f64>> = (0..n)
                    .map(|_| {
                        Vector3::new(
                            rng.random_range(-0.3..0.3),
                            rng.random_range(-0.15..0.15),
                            rng.random_range(-0.25..-0.15),
                        )
                    })
                    .collect();
                let wrench: Vec<f64> = if case % 2 == 0 {
                    let forces: Vec<f64> = (0..n)
                        .flat_map(|_| {
                            let fz: f64 = rng.random_range(1.0..60.0);
                            let mut f: Vec<f64> = (0..k - 1).map(|_| rng.random_range(-0.6..0.6) * fz).collect();
                            f.push(fz);
                            f
                        })
                        .collect();
                    fast.wrench(&feet, &forces).iter().copied().collect()
                } else {
                    (0..rows).map(|_| rng.random_range(-80.0..120.0)).collect()
                };
                let a = fast.solve(&feet, &wrench).unwrap();
                let b = reference.solve(&feet, &wrench).unwrap();
                check_constraints(&fast, &a);
                let (ja, jb) = (fast.objective(&feet, &wrench, &a), reference.objective(&feet, &wrench, &b));
                assert!(ja - jb <= 1e-4 * (1.0 + jb), "case {case} ({dimension:?}): cost {ja} vs default {jb}");
                // Forces may differ along directions the cost barely sees (the regularisation is
                // 1e-4); the wrench they produce may not.
                let gap = (fast.wrench(&feet, &a) - reference.wrench(&feet, &b)).amax();
                assert!(gap < 1e-2, "case {case} ({dimension:?}): wrenches differ by {gap}");
            }
        }
    }

    #[test]
    fn an_unsolvable_problem_is_an_error_not_a_panic() {
        // Normal force bounds that exclude each other: no admissible force exists.
        let mut qp = ForceQp { f_min: 10.0, f_max: 5.0, ..qp() };
        assert!(qp.solve(&feet(), &[0.0, 0.0, 60.0, 0.0, 0.0, 0.0]).is_err());
    }

    #[test]
    fn planar_version_for_minitaur() {
        let mut qp = ForceQp { dimension: Dimension::Planar, wrench_weights: vec![1.0; 5], ..qp() };
        // A trot's diagonal pair: front-left and back-right.
        let feet = [Vector3::new(0.21, 0.09, -0.2), Vector3::new(-0.21, -0.09, -0.2)];
        // Roll and pitch are tied on a diagonal pair; a wrench made from admissible forces is
        // reachable and must be reproduced.
        let truth = [2.0, 35.0, -1.0, 25.0];
        let wrench = qp.wrench(&feet, &truth);
        let f = qp.solve(&feet, wrench.as_slice()).unwrap();
        check_constraints(&qp, &f);
        let w = qp.wrench(&feet, &f);
        assert!((w - &wrench).norm() < 1e-3 * wrench.norm(), "{wrench} vs {f:?}");
        assert!(wrench[2].abs() > 0.5 && wrench[3].abs() > 0.5, "the test wrench should roll and pitch");
        assert!(qp.solve(&[], &[0.0, 60.0, 0.0, 0.0, 0.0]).is_err());
        assert!(qp.solve(&feet, &[0.0, 60.0]).is_err());
    }
}
