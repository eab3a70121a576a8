//! Stance-force distribution (Cheetah-Software's BalanceController, mit-biomimetics/Cheetah-Software): find ground reaction forces f at the stance feet
//! that best produce a desired body wrench b,
//!     minimise (A f - b)' S (A f - b) + alpha |f|^2
//!     subject to |f_x|, |f_y| <= mu f_z and f_min <= f_z <= f_max,
//! with A = [I ... I; [r_1]x ... [r_n]x] (r_i: foot position relative to the centre of mass).
//! Solved per tick by a warm-started dense active-set method (`active_set`), with clarabel as
//! the fallback and the reference it is tested against. `Planar` has no lateral foot forces (Minitaur has no abduction): forces
//! (f_x, f_z) per foot, wrench (F_x, F_z, M_x, M_y, M_z); roll is still controlled through the
//! vertical forces of feet on either side, and yaw through the fore-aft forces of feet on either
//! side.
use anyhow::{bail, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use std::collections::HashMap;

use nalgebra::{DMatrix, DVector, Vector3};

use super::active_set::{self, ActiveSetSolution};

/// How `ForceQp::solve` solves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpMethod {
    /// The dense active-set method warm-started from the previous solve (clarabel with the
    /// per-tick settings if it fails). The default.
    ActiveSet,
    /// clarabel with per-tick settings (absolute gap 1e-6, no iterative refinement).
    Clarabel,
    /// clarabel's default settings (tolerances 1e-8, equilibration, iterative refinement): the
    /// reference the others are tested against.
    ClarabelReference,
}

/// Whether feet push in 3D or in the sagittal plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Dimension {
    /// Forces (f_x, f_y, f_z) per foot; wrench (F_x, F_y, F_z, M_x, M_y, M_z).
    Spatial,
    /// Forces (f_x, f_z) per foot; wrench (F_x, F_z, M_x, M_y, M_z).
    Planar,
}

/// The stance-force QP: foot forces that best produce a desired body wrench within friction cones and force
/// limits.
pub struct ForceQp {
    /// 3D or planar forces.
    pub dimension: Dimension,
    /// Friction coefficient of the linearised cone.
    pub friction: f64,
    /// Least normal force per stance foot (N).
    pub f_min: f64,
    /// Largest normal force per stance foot (N).
    pub f_max: f64,
    /// Weight of each wrench row (S diagonal).
    pub wrench_weights: Vec<f64>,
    /// Regularisation alpha on |f|^2.
    pub regularisation: f64,
    /// Which solver solves it.
    pub method: QpMethod,
    /// Cached clarabel solvers by number of stance feet (see `solve_clarabel`).
    solvers: HashMap<usize, DefaultSolver<f64>>,
    /// The previous active-set solution (foot count, forces, active rows): the warm start.
    warm: Option<(usize, ActiveSetSolution)>,
}

/// The QP of one tick in dense form: minimise 1/2 f'Pf + q'f subject to G f <= h.
struct Problem {
    p: DMatrix<f64>,
    q: DVector<f64>,
    g: DMatrix<f64>,
    h: DVector<f64>,
}

impl ForceQp {
    /// A QP with these limits and weights, solved by the active-set method.
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
            method: QpMethod::ActiveSet,
            solvers: HashMap::new(),
            warm: None,
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
    #[cfg(test)]
    pub(crate) fn objective(&self, feet: &[Vector3<f64>], wrench: &[f64], forces: &[f64]) -> f64 {
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

    /// Forces for the stance feet at `feet` (flattened per foot), or an error when no solver
    /// succeeds; callers fall back to a safe default and count it.
    pub fn solve(&mut self, feet: &[Vector3<f64>], wrench: &[f64]) -> Result<Vec<f64>> {
        let problem = self.problem(feet, wrench)?;
        match self.method {
            QpMethod::ActiveSet => match self.solve_active_set(feet.len(), &problem) {
                Ok(f) => Ok(f),
                Err(_) => self.solve_clarabel(feet.len(), &problem, false),
            },
            QpMethod::Clarabel => self.solve_clarabel(feet.len(), &problem, false),
            QpMethod::ClarabelReference => self.solve_clarabel(feet.len(), &problem, true),
        }
    }

    /// The active-set method alone (no fallback), for tests and benches.
    #[cfg(test)]
    pub(crate) fn solve_with_active_set(&mut self, feet: &[Vector3<f64>], wrench: &[f64]) -> Result<Vec<f64>> {
        let problem = self.problem(feet, wrench)?;
        self.solve_active_set(feet.len(), &problem)
    }

    fn problem(&self, feet: &[Vector3<f64>], wrench: &[f64]) -> Result<Problem> {
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
        let rows_per_foot = 2 * (k - 1) + 2;
        let mut g = DMatrix::zeros(rows_per_foot * feet.len(), n);
        let mut h = DVector::zeros(rows_per_foot * feet.len());
        for foot in 0..feet.len() {
            let (base, row) = (k * foot, rows_per_foot * foot);
            let z = base + k - 1;
            for t in 0..k - 1 {
                for (j, sign) in [1.0, -1.0].into_iter().enumerate() {
                    g[(row + 2 * t + j, base + t)] = sign;
                    g[(row + 2 * t + j, z)] = -self.friction;
                }
            }
            g[(row + rows_per_foot - 2, z)] = 1.0;
            h[row + rows_per_foot - 2] = self.f_max;
            g[(row + rows_per_foot - 1, z)] = -1.0;
            h[row + rows_per_foot - 1] = -self.f_min;
        }
        Ok(Problem { p, q, g, h })
    }

    fn solve_active_set(&mut self, feet: usize, problem: &Problem) -> Result<Vec<f64>> {
        // The constraints depend on the foot count alone, so the previous solution with the
        // same count is feasible: start there with its active set. Otherwise start from
        // vertical forces at f_min.
        let (x0, working) = match self.warm.take() {
            Some((count, previous)) if count == feet => (previous.x, previous.active),
            _ => {
                let k = self.force_dim();
                (DVector::from_fn(k * feet, |i, _| if i % k == k - 1 { self.f_min } else { 0.0 }), Vec::new())
            }
        };
        let solution = active_set::solve(&problem.p, &problem.q, &problem.g, &problem.h, x0, working)?;
        let forces = solution.x.as_slice().to_vec();
        self.warm = Some((feet, solution));
        Ok(forces)
    }

    fn solve_clarabel(&mut self, feet: usize, problem: &Problem, reference: bool) -> Result<Vec<f64>> {
        let n = problem.q.len();
        let q = problem.q.as_slice().to_vec();
        let values = upper_triangle_values(&problem.p);
        // One solver per number of stance feet and setting, built once: later ticks only update
        // P and q (the constraints depend on the foot count alone). Presolve must be off for
        // updates.
        let solver = match self.solvers.entry(feet) {
            std::collections::hash_map::Entry::Occupied(e) => {
                let s = e.into_mut();
                s.update_P(&values).map_err(|e| anyhow::anyhow!("QP update failed: {e:?}"))?;
                s.update_q(&q).map_err(|e| anyhow::anyhow!("QP update failed: {e:?}"))?;
                s
            }
            std::collections::hash_map::Entry::Vacant(v) => {
                let p_upper = dense_pattern_upper(n, values);
                let g = dense_to_csc(&problem.g);
                let h = problem.h.as_slice().to_vec();
                let cones = [SupportedConeT::NonnegativeConeT(h.len())];
                let settings = if reference {
                    DefaultSettingsBuilder::default().verbose(false).presolve_enable(false).build()
                } else {
                    DefaultSettingsBuilder::default()
                        .verbose(false)
                        .max_iter(50)
                        .presolve_enable(false)
                        // An absolute duality gap of 1e-6 (the relative one stays at 1e-8: the
                        // solver's objective omits b'Sb, so a relative test would stop early)
                        // and no iterative refinement: about half the solve time
                        // (benches/controller.rs), same cost to 1e-4 (tests below).
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

/// The nonzeros of a dense matrix in compressed-column form.
fn dense_to_csc(m: &DMatrix<f64>) -> CscMatrix<f64> {
    let (mut colptr, mut rowval, mut nzval) = (vec![0], Vec::new(), Vec::new());
    for c in 0..m.ncols() {
        for r in 0..m.nrows() {
            if m[(r, c)] != 0.0 {
                rowval.push(r);
                nzval.push(m[(r, c)]);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(m.nrows(), m.ncols(), colptr, rowval, nzval)
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

    /// The active-set method (warm-started whenever consecutive cases have the same foot
    /// count) and clarabel's per-tick settings against clarabel's defaults on random stance
    /// configurations: wrenches made from admissible forces (feasible) and arbitrary ones (not
    /// reproducible).
    #[test]
    fn active_set_and_fast_settings_match_the_default_solver_on_random_cases() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for dimension in [Dimension::Spatial, Dimension::Planar] {
            let rows = if dimension == Dimension::Spatial { 6 } else { 5 };
            let make = |method| ForceQp {
                dimension,
                wrench_weights: vec![1.0, 1.0, 1.0, 10.0, 10.0, 10.0][..rows].to_vec(),
                method,
                ..ForceQp::new(dimension, 0.7, 0.5, 80.0, vec![], 1e-4)
            };
            let mut active_set = make(QpMethod::ActiveSet);
            let mut fast = make(QpMethod::Clarabel);
            let mut reference = make(QpMethod::ClarabelReference);
            let k = fast.force_dim();
            for case in 0..300 {
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
                let b = reference.solve(&feet, &wrench).unwrap();
                let jb = reference.objective(&feet, &wrench, &b);
                let exact = active_set.solve_with_active_set(&feet, &wrench).unwrap();
                check_constraints(&active_set, &exact);
                let je = active_set.objective(&feet, &wrench, &exact);
                // Feasible (checked above) and exact up to rounding: it may not cost more than the
                // interior-point solution, and less only within clarabel's tolerance (its gap is
                // relative to an objective without the constant b'Sb).
                assert!(
                    je <= jb + 1e-9 * (1.0 + jb) && je >= jb - 1e-4 * (1.0 + jb),
                    "case {case} ({dimension:?}): active set {je} vs {jb}"
                );
                let gap = (active_set.wrench(&feet, &exact) - reference.wrench(&feet, &b)).amax();
                assert!(gap < 1e-3, "case {case} ({dimension:?}): active-set wrench differs by {gap}");

                let a = fast.solve(&feet, &wrench).unwrap();
                check_constraints(&fast, &a);
                let ja = fast.objective(&feet, &wrench, &a);
                assert!(ja - jb <= 1e-4 * (1.0 + jb), "case {case} ({dimension:?}): cost {ja} vs default {jb}");
                // Forces may differ along directions the cost barely sees (the regularisation is
                // 1e-4); the wrench they produce may not.
                let gap = (fast.wrench(&feet, &a) - reference.wrench(&feet, &b)).amax();
                assert!(gap < 1e-2, "case {case} ({dimension:?}): wrenches differ by {gap}");
            }
        }
    }

    /// Over a gait-like sequence (feet drifting, the wrench changing a little each tick) the warm
    /// start keeps the solve to a few iterations and agrees with a cold solve.
    #[test]
    fn warm_started_solves_agree_with_cold_ones_along_a_gait() {
        let mut warm = qp();
        for tick in 0..200 {
            let t = tick as f64 * 0.01;
            let feet: Vec<Vector3<f64>> =
                feet().iter().map(|f| f + Vector3::new(-0.1 * t.sin(), 0.0, 0.01 * t)).collect();
            let wrench = [8.0 * t.cos(), 3.0 * t.sin(), 55.0 + 10.0 * t.sin(), 2.0 * t.cos(), 1.5, -0.5 * t];
            let f = warm.solve_with_active_set(&feet, &wrench).unwrap();
            let iterations = warm.warm.as_ref().unwrap().1.iterations;
            let cold = qp().solve_with_active_set(&feet, &wrench).unwrap();
            let diff = f.iter().zip(&cold).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(diff < 1e-6, "tick {tick}: warm and cold solutions differ by {diff}");
            if tick > 0 {
                assert!(iterations <= 6, "tick {tick}: {iterations} iterations from the warm start");
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
