//! A vector step as Gymnasium's vector API returns it, built in Rust: NumPy arrays for the
//! observations, rewards and flags, and the infos batched the way Gymnasium's
//! `VectorEnv._add_info` batches the copies' info dicts (gymnasium/vector/vector_env.py): every
//! leaf becomes an array over the copies with a boolean mask `_key` beside it, a copy whose
//! episode ended has its last info under `final_info` and its last observation under `final_obs`.
//! Building them here instead of in Python takes most of the Python side out of a step, which is
//! the part a second thread cannot share (`python/bench_speed.py` measures both).
use locobench::envs::{Info, VecStep};
use numpy::{Element, PyArray1, PyArray2, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::intern;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

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
    keys: &mut Option<InfoKeys>,
    info_dict: impl Fn(&Info) -> PyResult<Bound<'py, PyDict>>,
) -> PyResult<GymStep<'py>> {
    // One object per array: `from_vec` would add a base object to each, and `reshape` a view.
    let observations =
        PyArray2::from_vec2(py, &s.observations).map_err(|e| PyValueError::new_err(e.to_string()))?.into_any();
    let rewards = PyArray1::from_slice(py, &s.rewards);
    let terminated = PyArray1::from_slice(py, &s.terminated);
    let truncated = PyArray1::from_slice(py, &s.truncated);
    let infos = if columns_line_up(&s.infos) {
        if !keys.as_ref().is_some_and(|k| k.fit(&s.infos[0])) {
            *keys = Some(InfoKeys::new(py, &s.infos[0]));
        }
        batched_infos(py, &s, keys.as_ref().expect("made above"))?.into_any()
    } else {
        let finals =
            PyList::new(py, s.final_observations.iter().map(|o| o.as_ref().map(|o| PyArray1::from_slice(py, o))))?;
        let dicts = PyList::new(py, s.infos.iter().map(info_dict).collect::<PyResult<Vec<_>>>()?)?;
        (finals, dicts).into_pyobject(py)?.into_any()
    };
    Ok((observations, rewards, terminated, truncated, infos))
}

/// Each copy's action from a float64 or float32 array of `shape` (`[copies, action dim]`; float32
/// widened exactly, as NumPy's `astype` does), or None for anything else, which the vector env's
/// Python side then checks and converts.
pub(crate) fn action_rows(actions: &Bound<'_, PyAny>, shape: [usize; 2]) -> Option<Vec<Vec<f64>>> {
    fn rows<T: Element + Copy + Into<f64>>(a: &Bound<'_, PyArray2<T>>, shape: [usize; 2]) -> Option<Vec<Vec<f64>>> {
        if a.shape() != shape {
            return None;
        }
        // SAFETY: read while this thread holds the GIL and copied before anything else runs, so no
        // Python code and no other borrow writes the array meanwhile. (A `PyReadonlyArray`
        // would register a borrow for this, a cost on every step.)
        Some(unsafe { a.as_array() }.rows().into_iter().map(|r| r.iter().map(|&x| x.into()).collect()).collect())
    }
    if let Ok(a) = actions.cast::<PyArray2<f64>>() {
        rows(a, shape)
    } else if let Ok(a) = actions.cast::<PyArray2<f32>>() {
        rows(a, shape)
    } else {
        None
    }
}

/// One of an info's lists of named values.
type Named = fn(&Info) -> &[(&'static str, f64)];

/// The batched infos' keys for the reward terms and metrics, `name` and `_name`, as Python
/// strings made once for an env's names instead of on every step (a step of Minitaur has 14).
/// Interned, so their hashes are kept too.
pub(crate) struct InfoKeys {
    terms: Vec<&'static str>,
    metrics: Vec<&'static str>,
    term_keys: Vec<KeyPair>,
    metric_keys: Vec<KeyPair>,
}

/// A value's key and its mask's key: `name` and `_name`.
type KeyPair = [Py<PyString>; 2];

impl InfoKeys {
    fn new(py: Python<'_>, info: &Info) -> InfoKeys {
        let names = |pairs: &[(&'static str, f64)]| pairs.iter().map(|(k, _)| *k).collect::<Vec<_>>();
        let keys = |names: &[&str]| {
            names
                .iter()
                .map(|n| [PyString::intern(py, n).unbind(), PyString::intern(py, &format!("_{n}")).unbind()])
                .collect()
        };
        let (terms, metrics) = (names(&info.reward_terms), names(&info.metrics));
        InfoKeys { term_keys: keys(&terms), metric_keys: keys(&metrics), terms, metrics }
    }

    /// Whether these are the keys of `info`'s names.
    fn fit(&self, info: &Info) -> bool {
        named(&info.reward_terms, self.terms.iter().copied()) && named(&info.metrics, self.metrics.iter().copied())
    }
}

/// Whether `pairs` are named `names`, in that order.
fn named<'a>(pairs: &[(&str, f64)], names: impl ExactSizeIterator<Item = &'a str>) -> bool {
    pairs.len() == names.len() && pairs.iter().zip(names).all(|((k, _), n)| *k == n)
}

fn columns_line_up(infos: &[Info]) -> bool {
    let first = &infos[0];
    infos.iter().all(|i| {
        named(&i.reward_terms, first.reward_terms.iter().map(|(k, _)| *k))
            && named(&i.metrics, first.metrics.iter().map(|(k, _)| *k))
    })
}

fn batched_infos<'py>(py: Python<'py>, s: &VecStep, keys: &InfoKeys) -> PyResult<Bound<'py, PyDict>> {
    let ended: Vec<bool> = s.final_observations.iter().map(Option::is_some).collect();
    let infos = PyDict::new(py);
    if !ended.iter().all(|&e| e) {
        let running: Vec<bool> = ended.iter().map(|&e| !e).collect();
        masked_info(py, &infos, &s.infos, &running, keys)?;
    }
    if ended.iter().any(|&e| e) {
        let finals: Vec<Py<PyAny>> = s
            .final_observations
            .iter()
            .map(|o| o.as_ref().map_or_else(|| py.None(), |o| PyArray1::from_slice(py, o).into_any().unbind()))
            .collect();
        infos.set_item(intern!(py, "final_obs"), PyArray1::from_vec(py, finals))?;
        infos.set_item(intern!(py, "_final_obs"), PyArray1::from_slice(py, &ended))?;
        let final_info = PyDict::new(py);
        masked_info(py, &final_info, &s.infos, &ended, keys)?;
        infos.set_item(intern!(py, "final_info"), final_info)?;
        infos.set_item(intern!(py, "_final_info"), PyArray1::from_slice(py, &ended))?;
    }
    Ok(infos)
}

/// `value` of each copy in `mask`, the type's zero for the others (as `_add_info` leaves them).
fn masked<T: Default>(infos: &[Info], mask: &[bool], value: impl Fn(&Info) -> T) -> Vec<T> {
    infos.iter().zip(mask).map(|(info, &m)| if m { value(info) } else { T::default() }).collect()
}

/// The batched infos of the copies in `mask` (the others' entries zero and masked out), into `out`.
fn masked_info<'py>(
    py: Python<'py>,
    out: &Bound<'py, PyDict>,
    infos: &[Info],
    mask: &[bool],
    keys: &InfoKeys,
) -> PyResult<()> {
    let mask_array = || PyArray1::from_slice(py, mask);
    let group = |[key, mask_key]: [&Bound<'py, PyString>; 2], names: &[KeyPair], pick: Named| -> PyResult<()> {
        let group = PyDict::new(py);
        for (j, [name, name_mask]) in names.iter().enumerate() {
            group.set_item(name.bind(py), PyArray1::from_slice(py, &masked(infos, mask, |i| pick(i)[j].1)))?;
            group.set_item(name_mask.bind(py), mask_array())?;
        }
        out.set_item(key, group)?;
        out.set_item(mask_key, mask_array())
    };
    group([intern!(py, "reward_terms"), intern!(py, "_reward_terms")], &keys.term_keys, |i| &i.reward_terms)?;
    group([intern!(py, "metrics"), intern!(py, "_metrics")], &keys.metric_keys, |i| &i.metrics)?;
    let clipped = masked(infos, mask, |i| i.clipped_actions as i64);
    out.set_item(intern!(py, "clipped_actions"), PyArray1::from_slice(py, &clipped))?;
    out.set_item(intern!(py, "_clipped_actions"), mask_array())?;
    out.set_item(intern!(py, "unstable"), PyArray1::from_slice(py, &masked(infos, mask, |i| i.unstable)))?;
    out.set_item(intern!(py, "_unstable"), mask_array())?;
    let warned = masked(infos, mask, |i| !i.warnings.is_empty());
    if warned.contains(&true) {
        let warnings = infos
            .iter()
            .zip(&warned)
            .map(|(i, &w)| if w { Ok(PyList::new(py, &i.warnings)?.into_any().unbind()) } else { Ok(py.None()) })
            .collect::<PyResult<Vec<Py<PyAny>>>>()?;
        out.set_item(intern!(py, "warnings"), PyArray1::from_vec(py, warnings))?;
        out.set_item(intern!(py, "_warnings"), PyArray1::from_slice(py, &warned))?;
    }
    Ok(())
}
