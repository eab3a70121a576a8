//! A vector step as Gymnasium's vector API returns it, built in Rust: NumPy arrays for the
//! observations, rewards and flags, and the infos batched the way Gymnasium's
//! `VectorEnv._add_info` batches the copies' info dicts (gymnasium/vector/vector_env.py): every
//! leaf becomes an array over the copies with a boolean mask `_key` beside it, a copy whose
//! episode ended has its last info under `final_info` and its last observation under `final_obs`.
//! Building them here instead of in Python takes most of the Python side out of a step, which is
//! the part a second thread cannot share (`python/bench_speed.py` measures both).
use locobench::envs::{Info, VecStep};
use numpy::{Element, PyArray1, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// What the vector step hands to Python: `(observations, rewards, terminated, truncated, infos)`,
/// `infos` batched; or, where the copies' infos differ in their term or metric names (so columns
/// do not line up), `infos` as `(final observations, one info dict per copy)` for Python's
/// `_add_info` to batch.
pub(crate) type GymStep<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyAny>,
);

pub(crate) fn gym_step<'py>(
    py: Python<'py>,
    s: VecStep,
    info_dict: impl Fn(&Info) -> PyResult<Bound<'py, PyDict>>,
) -> PyResult<GymStep<'py>> {
    // One object per array: `from_vec` would add a base object to each, and `reshape` a view.
    let observations =
        PyArray2::from_vec2(py, &s.observations).map_err(|e| PyValueError::new_err(e.to_string()))?.into_any();
    let rewards = PyArray1::from_slice(py, &s.rewards);
    let terminated = PyArray1::from_slice(py, &s.terminated);
    let truncated = PyArray1::from_slice(py, &s.truncated);
    let infos = if columns_line_up(&s.infos) {
        batched_infos(py, &s)?.into_any()
    } else {
        let finals =
            PyList::new(py, s.final_observations.iter().map(|o| o.as_ref().map(|o| PyArray1::from_slice(py, o))))?;
        let dicts = PyList::new(py, s.infos.iter().map(info_dict).collect::<PyResult<Vec<_>>>()?)?;
        (finals, dicts).into_pyobject(py)?.into_any()
    };
    Ok((observations, rewards, terminated, truncated, infos))
}

/// Each copy's action from a float64 or float32 `[copies, action dim]` array (float32 widened
/// exactly, as NumPy's `astype` does); any other type is refused. The vector env's Python side
/// converts other inputs and checks the shape before.
pub(crate) fn action_rows(actions: &Bound<'_, PyAny>) -> PyResult<Vec<Vec<f64>>> {
    fn rows<T: Element + Copy + Into<f64>>(a: &Bound<'_, PyArray2<T>>) -> Vec<Vec<f64>> {
        // SAFETY: read while this thread holds the GIL and copied before anything else runs, so no
        // Python code and no other borrow writes the array meanwhile. (A `PyReadonlyArray`
        // would register a borrow for this, a cost on every step.)
        unsafe { a.as_array() }.rows().into_iter().map(|r| r.iter().map(|&x| x.into()).collect()).collect()
    }
    if let Ok(a) = actions.cast::<PyArray2<f64>>() {
        Ok(rows(a))
    } else if let Ok(a) = actions.cast::<PyArray2<f32>>() {
        Ok(rows(a))
    } else {
        Err(PyTypeError::new_err(format!(
            "actions must be a float64 or float32 array of shape (copies, action dim), not {}",
            actions.get_type().name()?
        )))
    }
}

/// One of an info's lists of named values.
type Named = fn(&Info) -> &[(&'static str, f64)];

fn columns_line_up(infos: &[Info]) -> bool {
    let names = |pairs: &[(&'static str, f64)]| pairs.iter().map(|(k, _)| *k).collect::<Vec<_>>();
    let (terms, metrics) = (names(&infos[0].reward_terms), names(&infos[0].metrics));
    infos.iter().all(|i| names(&i.reward_terms) == terms && names(&i.metrics) == metrics)
}

fn batched_infos<'py>(py: Python<'py>, s: &VecStep) -> PyResult<Bound<'py, PyDict>> {
    let ended: Vec<bool> = s.final_observations.iter().map(Option::is_some).collect();
    let infos = PyDict::new(py);
    if !ended.iter().all(|&e| e) {
        let running: Vec<bool> = ended.iter().map(|&e| !e).collect();
        masked_info(py, &infos, &s.infos, &running)?;
    }
    if ended.iter().any(|&e| e) {
        let finals: Vec<Py<PyAny>> = s
            .final_observations
            .iter()
            .map(|o| o.as_ref().map_or_else(|| py.None(), |o| PyArray1::from_slice(py, o).into_any().unbind()))
            .collect();
        infos.set_item("final_obs", PyArray1::from_vec(py, finals))?;
        infos.set_item("_final_obs", PyArray1::from_slice(py, &ended))?;
        let final_info = PyDict::new(py);
        masked_info(py, &final_info, &s.infos, &ended)?;
        infos.set_item("final_info", final_info)?;
        infos.set_item("_final_info", PyArray1::from_slice(py, &ended))?;
    }
    Ok(infos)
}

/// `value` of each copy in `mask`, the type's zero for the others (as `_add_info` leaves them).
fn masked<T: Default>(infos: &[Info], mask: &[bool], value: impl Fn(&Info) -> T) -> Vec<T> {
    infos.iter().zip(mask).map(|(info, &m)| if m { value(info) } else { T::default() }).collect()
}

/// The batched infos of the copies in `mask` (the others' entries zero and masked out), into `out`.
fn masked_info<'py>(py: Python<'py>, out: &Bound<'py, PyDict>, infos: &[Info], mask: &[bool]) -> PyResult<()> {
    let mask_array = || PyArray1::from_slice(py, mask);
    let groups: [(&str, Named); 2] = [("reward_terms", |i| &i.reward_terms), ("metrics", |i| &i.metrics)];
    for (key, pick) in groups {
        let group = PyDict::new(py);
        for (j, (name, _)) in pick(&infos[0]).iter().enumerate() {
            group.set_item(*name, PyArray1::from_slice(py, &masked(infos, mask, |i| pick(i)[j].1)))?;
            group.set_item(format!("_{name}"), mask_array())?;
        }
        out.set_item(key, group)?;
        out.set_item(format!("_{key}"), mask_array())?;
    }
    out.set_item("clipped_actions", PyArray1::from_slice(py, &masked(infos, mask, |i| i.clipped_actions as i64)))?;
    out.set_item("_clipped_actions", mask_array())?;
    out.set_item("unstable", PyArray1::from_slice(py, &masked(infos, mask, |i| i.unstable)))?;
    out.set_item("_unstable", mask_array())?;
    let warned = masked(infos, mask, |i| !i.warnings.is_empty());
    if warned.contains(&true) {
        let warnings = infos
            .iter()
            .zip(&warned)
            .map(|(i, &w)| if w { Ok(PyList::new(py, &i.warnings)?.into_any().unbind()) } else { Ok(py.None()) })
            .collect::<PyResult<Vec<Py<PyAny>>>>()?;
        out.set_item("warnings", PyArray1::from_vec(py, warnings))?;
        out.set_item("_warnings", PyArray1::from_slice(py, &warned))?;
    }
    Ok(())
}
