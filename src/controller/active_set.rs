//! A dense primal active-set solver for small strictly convex QPs,
//!     minimise 1/2 x' H x + g' x   subject to   A x <= b,
//! started from a feasible point (Nocedal & Wright, "Numerical Optimization", 2nd ed.,
//! Algorithm 16.3). Each iteration solves the equality-constrained problem on the working set
//! through the Schur complement of H (one Cholesky factorisation of H per solve).
//!
//! Why not clarabel here: the stance-force QP has at most 12 variables and 24 rows and is solved
//! every control tick; an interior-point method pays for its generality (about 60 us per solve,
//! `cargo bench --bench controller`), while this method, warm-started from the previous tick's
//! working set, usually needs one or two linear solves of that size. It is tested against
//! clarabel's solution in `force_qp`.
use anyhow::{bail, Result};
use nalgebra::{DMatrix, DVector};

/// Solution and the constraints active at it (the next solve's warm start).
#[derive(Debug, Clone)]
pub(crate) struct ActiveSetSolution {
    pub x: DVector<f64>,
    pub active: Vec<usize>,
    /// Iterations the solve took; the warm-start test bounds it.
    #[cfg_attr(not(test), allow(dead_code))]
    pub(crate) iterations: usize,
}

/// Solves the QP from `x0`, which must satisfy `A x0 <= b`, with `working` the constraints
/// assumed active at `x0` (empty, or the previous solution's set when `x0` is that solution).
pub fn solve(
    h: &DMatrix<f64>,
    g: &DVector<f64>,
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    x0: DVector<f64>,
    working: Vec<usize>,
) -> Result<ActiveSetSolution> {
    let (n, m) = (h.nrows(), a.nrows());
    if h.ncols() != n || g.len() != n || a.ncols() != n || b.len() != m || x0.len() != n {
        bail!("QP dimensions do not agree");
    }
    let scale = 1.0 + b.amax() + x0.amax();
    let violation = (a * &x0 - b).max();
    if m > 0 && violation > 1e-9 * scale {
        bail!("the starting point violates a constraint by {violation:.3e}: no admissible point given");
    }
    let Some(chol) = h.clone().cholesky() else { bail!("the QP's Hessian is not positive definite") };
    let mut x = x0;
    let mut working = working;
    let max_iterations = 10 * (n + m);
    // After a full step without a blocking constraint, x minimises over the working set; the
    // step computed there is rounding noise and must not be taken again.
    let mut at_subspace_minimum = false;
    for iteration in 1..=max_iterations {
        let c = h * &x + g;
        let hinv_c = chol.solve(&c);
        let (p, multipliers) = if working.is_empty() {
            (-hinv_c, DVector::zeros(0))
        } else {
            let gw = DMatrix::from_fn(working.len(), n, |r, col| a[(working[r], col)]);
            let hinv_gwt = chol.solve(&gw.transpose());
            let schur = &gw * &hinv_gwt;
            let Some(schur_chol) = schur.cholesky() else {
                bail!("the working set became linearly dependent");
            };
            let lambda = schur_chol.solve(&(-(&gw * &hinv_c)));
            (-(hinv_c + &hinv_gwt * &lambda), lambda)
        };

        if at_subspace_minimum || p.amax() <= 1e-12 * (1.0 + x.amax()) {
            at_subspace_minimum = false;
            // x minimises over the working set: optimal if every multiplier is >= 0, else
            // release the constraint with the most negative one.
            let (worst, &lowest) = match multipliers.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1)) {
                Some(w) => w,
                None => return Ok(ActiveSetSolution { x, active: working, iterations: iteration }),
            };
            if lowest >= -1e-9 * (1.0 + multipliers.amax()) {
                return Ok(ActiveSetSolution { x, active: working, iterations: iteration });
            }
            working.remove(worst);
            continue;
        }

        // Longest step along p that stays feasible; the first constraint hit joins the set.
        let (ap, ax) = (a * &p, a * &x);
        let mut step = 1.0;
        let mut blocking = None;
        for i in (0..m).filter(|i| !working.contains(i)) {
            if ap[i] > 1e-14 * scale {
                let t = (b[i] - ax[i]).max(0.0) / ap[i];
                if t < step {
                    step = t;
                    blocking = Some(i);
                }
            }
        }
        x += step * &p;
        match blocking {
            Some(i) => working.push(i),
            None => at_subspace_minimum = true,
        }
    }
    bail!("the active-set method did not converge in {max_iterations} iterations")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_box_constrained_quadratic_by_hand() {
        // minimise (x - 2)^2 + (y + 1)^2 subject to x <= 1, y >= 0: solution (1, 0), with
        // multipliers 2 and 2 on the two active bounds.
        let h = DMatrix::from_diagonal_element(2, 2, 2.0);
        let g = DVector::from_vec(vec![-4.0, 2.0]);
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        let b = DVector::from_vec(vec![1.0, 0.0]);
        let s = solve(&h, &g, &a, &b, DVector::from_vec(vec![0.0, 0.5]), vec![]).unwrap();
        assert!((s.x[0] - 1.0).abs() < 1e-12 && s.x[1].abs() < 1e-12, "{}", s.x);
        let mut active = s.active.clone();
        active.sort();
        assert_eq!(active, vec![0, 1]);
        // Warm-started at the solution with its working set, it stops at once.
        let again = solve(&h, &g, &a, &b, s.x.clone(), s.active).unwrap();
        assert_eq!(again.iterations, 1);
        assert_eq!(again.x, s.x);
    }

    #[test]
    fn inactive_constraints_leave_the_unconstrained_minimum() {
        let h = DMatrix::from_row_slice(2, 2, &[4.0, 1.0, 1.0, 3.0]);
        let g = DVector::from_vec(vec![-1.0, -2.0]);
        let a = DMatrix::from_row_slice(1, 2, &[1.0, 1.0]);
        let b = DVector::from_vec(vec![10.0]);
        let s = solve(&h, &g, &a, &b, DVector::zeros(2), vec![]).unwrap();
        let exact = h.clone().cholesky().unwrap().solve(&(-&g));
        assert!((s.x - exact).amax() < 1e-12);
        assert!(s.active.is_empty());
    }

    #[test]
    fn an_infeasible_start_or_an_indefinite_hessian_is_an_error() {
        let a = DMatrix::from_row_slice(1, 1, &[1.0]);
        let b = DVector::from_vec(vec![0.0]);
        let h = DMatrix::from_row_slice(1, 1, &[1.0]);
        let g = DVector::zeros(1);
        assert!(solve(&h, &g, &a, &b, DVector::from_vec(vec![1.0]), vec![]).is_err());
        let indefinite = DMatrix::from_row_slice(1, 1, &[-1.0]);
        assert!(solve(&indefinite, &g, &a, &b, DVector::zeros(1), vec![]).is_err());
    }
}
