//! Python bindings: the environments, the controller and trained policies. The Python package
//! (`python/locobench/`) wraps these in Gymnasium's API; this module only moves numbers across
//! and turns every Rust error into a Python exception carrying its message.
use std::path::PathBuf;
use std::sync::Mutex;

use locobench::controller::baseline::{baseline_controller_for, baseline_env, parse_gait, RAMP_TIME};
use locobench::controller::command::{Command, SpeedProfile};
use locobench::envs::{env_names, make, reward_weight_option, EnvConfig, VecEnv};
use locobench::policy::Policy;
use locobench::runtime::Runtime;
use pyo3::exceptions::{PyFileNotFoundError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// `{:#}` prints an anyhow error with its causes, as the command line does.
fn runtime_error(e: anyhow::Error) -> PyErr {
    PyRuntimeError::new_err(format!("{e:#}"))
}

/// One environment. Options are `key = TOML value` text pairs (the Python side writes them),
/// reward weights go by term name.
#[pyclass(name = "Env", module = "locobench._core")]
struct PyEnv {
    // A pyclass must be Sync; the lock is only ever taken by the thread holding the object.
    env: Mutex<Box<dyn locobench::envs::Env>>,
    config: EnvConfig,
}

impl PyEnv {
    fn env(&self) -> std::sync::MutexGuard<'_, Box<dyn locobench::envs::Env>> {
        self.env.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

#[pymethods]
impl PyEnv {
    #[new]
    #[pyo3(signature = (name, options = Vec::new(), reward = Vec::new()))]
    fn new(name: &str, options: Vec<(String, String)>, reward: Vec<(String, f64)>) -> PyResult<Self> {
        let config = env_config(name, options, reward)?;
        let env = make(&config).map_err(value_error)?;
        Ok(PyEnv { env: Mutex::new(env), config })
    }

    #[getter]
    fn name(&self) -> String {
        self.env().spec().name.to_string()
    }

    /// (low, high) of the observation space.
    #[getter]
    fn observation_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let env = self.env();
        let s = &env.spec().observation_space;
        (s.low.clone(), s.high.clone())
    }

    /// (low, high) of the action space.
    #[getter]
    fn action_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let env = self.env();
        let s = &env.spec().action_space;
        (s.low.clone(), s.high.clone())
    }

    /// Seconds of simulated time per step.
    #[getter]
    fn dt(&self) -> f64 {
        self.env().spec().dt
    }

    #[getter]
    fn max_episode_steps(&self) -> usize {
        self.env().spec().max_episode_steps
    }

    #[getter]
    fn reward_terms(&self) -> Vec<String> {
        self.env().spec().reward_terms.iter().map(|t| t.to_string()).collect()
    }

    /// One resolved option's value as TOML text, or None for an unknown key.
    fn option_value(&self, key: &str) -> PyResult<Option<String>> {
        let table = self.config.resolved_options().map_err(value_error)?;
        Ok(table.get(key).map(|v| v.to_string()))
    }

    /// The resolved options as TOML text.
    #[getter]
    fn options(&self) -> PyResult<String> {
        let table = self.config.resolved_options().map_err(value_error)?;
        Ok(toml_text(&table))
    }

    /// Overwrites positions and velocities mid-episode (Gymnasium's `set_state`).
    fn set_state(&self, qpos: Vec<f64>, qvel: Vec<f64>) -> PyResult<()> {
        self.env().set_state(&qpos, &qvel).map_err(value_error)
    }

    /// Positions and velocities of the simulation now.
    #[getter]
    fn state(&self) -> (Vec<f64>, Vec<f64>) {
        let env = self.env();
        (env.data().qpos().to_vec(), env.data().qvel().to_vec())
    }

    /// Starts an episode: (observation, info). The GIL is released while MuJoCo runs.
    #[pyo3(signature = (seed = None))]
    fn reset<'py>(&self, py: Python<'py>, seed: Option<u64>) -> PyResult<(Vec<f64>, Bound<'py, PyDict>)> {
        let env = &self.env;
        let (obs, info) =
            py.detach(|| env.lock().unwrap_or_else(|p| p.into_inner()).reset(seed)).map_err(value_error)?;
        Ok((obs, info_dict(py, &info, false)?))
    }

    /// Steps `n` times with one action, resetting whenever an episode ends, all in Rust: what
    /// stepping costs without crossing into Python (the speed benchmark's baseline).
    fn step_repeat(&self, py: Python<'_>, action: Vec<f64>, n: usize) -> PyResult<()> {
        let env = &self.env;
        py.detach(|| {
            let mut env = env.lock().unwrap_or_else(|p| p.into_inner());
            for _ in 0..n {
                let s = env.step(&action)?;
                if s.terminated || s.truncated {
                    env.reset(None)?;
                }
            }
            Ok::<(), locobench::envs::EnvError>(())
        })
        .map_err(value_error)
    }

    /// One step: (observation, reward, terminated, truncated, info). The GIL is released while
    /// MuJoCo runs.
    fn step<'py>(&self, py: Python<'py>, action: Vec<f64>) -> PyResult<StepResult<'py>> {
        let env = &self.env;
        let s = py.detach(|| env.lock().unwrap_or_else(|p| p.into_inner()).step(&action)).map_err(value_error)?;
        let info = info_dict(py, &s.info, false)?;
        Ok((s.observation, s.reward, s.terminated, s.truncated, info))
    }
}

/// The env's configuration from option pairs (`key`, TOML text) and reward weights by term name.
fn env_config(name: &str, options: Vec<(String, String)>, reward: Vec<(String, f64)>) -> PyResult<EnvConfig> {
    let mut pairs = options;
    for (term, weight) in reward {
        let option = reward_weight_option(name, &term).map_err(value_error)?;
        pairs.push((option.to_string(), weight.to_string()));
    }
    EnvConfig::new(name).with_overrides(&pairs).map_err(value_error)
}

/// N copies of one environment stepped together in Rust with automatic reset (Gymnasium's
/// "same-step" mode), split over `threads` threads with the GIL released; the numbers do not
/// depend on the thread count.
#[pyclass(name = "VecEnv", module = "locobench._core")]
struct PyVecEnv {
    // A pyclass must be Sync; the lock is only ever taken by the thread holding the object.
    envs: Mutex<VecEnv>,
}

impl PyVecEnv {
    fn envs(&self) -> std::sync::MutexGuard<'_, VecEnv> {
        self.envs.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// (observations, rewards, terminated, truncated, final observations, infos) of a vector step.
type VecStepResult<'py> =
    (Vec<Vec<f64>>, Vec<f64>, Vec<bool>, Vec<bool>, Vec<Option<Vec<f64>>>, Vec<Bound<'py, PyDict>>);

#[pymethods]
impl PyVecEnv {
    #[new]
    #[pyo3(signature = (name, copies, threads, options = Vec::new(), reward = Vec::new()))]
    fn new(
        name: &str,
        copies: usize,
        threads: usize,
        options: Vec<(String, String)>,
        reward: Vec<(String, f64)>,
    ) -> PyResult<Self> {
        if threads == 0 {
            return Err(value_error("threads must be at least 1"));
        }
        let config = env_config(name, options, reward)?;
        let envs = VecEnv::new(&config, copies, threads).map_err(value_error)?;
        Ok(PyVecEnv { envs: Mutex::new(envs) })
    }

    #[getter]
    fn num_envs(&self) -> usize {
        self.envs().len()
    }

    /// Starts an episode in every copy (copy `i` from `episode_seed(seed, i, 0)`); returns the
    /// first observations.
    fn reset(&self, py: Python<'_>, seed: u64) -> PyResult<Vec<Vec<f64>>> {
        let envs = &self.envs;
        py.detach(|| envs.lock().unwrap_or_else(|p| p.into_inner()).reset(seed)).map_err(value_error)
    }

    /// Steps every copy with its action and resets the copies whose episode ended (their next
    /// episode from `episode_seed(seed, i, k)`). Where a copy's episode ended, its observation is
    /// the new episode's first, its final observation the ended one's last, and its info that of
    /// the ended episode's last step.
    fn step<'py>(&self, py: Python<'py>, actions: Vec<Vec<f64>>) -> PyResult<VecStepResult<'py>> {
        let envs = &self.envs;
        let s = py.detach(|| envs.lock().unwrap_or_else(|p| p.into_inner()).step(&actions)).map_err(value_error)?;
        let infos = s.infos.iter().map(|info| info_dict(py, info, false)).collect::<PyResult<Vec<_>>>()?;
        Ok((s.observations, s.rewards, s.terminated, s.truncated, s.final_observations, infos))
    }
}

/// The reset seed of episode `episode` of copy `copy` after a vector reset with `seed`.
#[pyfunction]
fn episode_seed(seed: u64, copy: usize, episode: u64) -> u64 {
    locobench::envs::episode_seed(seed, copy, episode)
}

/// (observation, reward, terminated, truncated, info), as Gymnasium's `step` returns.
type StepResult<'py> = (Vec<f64>, f64, bool, bool, Bound<'py, PyDict>);

fn toml_text(table: &toml::Table) -> String {
    toml::to_string(table).unwrap_or_default()
}

fn info_dict<'py>(py: Python<'py>, info: &locobench::envs::Info, unstable: bool) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let terms = PyDict::new(py);
    for (name, value) in &info.reward_terms {
        terms.set_item(*name, *value)?;
    }
    d.set_item("reward_terms", terms)?;
    let metrics = PyDict::new(py);
    for (name, value) in &info.metrics {
        metrics.set_item(*name, *value)?;
    }
    d.set_item("metrics", metrics)?;
    d.set_item("clipped_actions", info.clipped_actions)?;
    d.set_item("unstable", unstable || info.unstable)?;
    if !info.warnings.is_empty() {
        d.set_item("warnings", info.warnings.clone())?;
    }
    Ok(d)
}

/// The Raibert/QP controller for one env, commanded to a forward speed. It reads the full
/// simulation state, so it acts on a locobench `Env` (one made in its action mode).
#[pyclass(name = "Controller", module = "locobench._core", unsendable)]
struct PyController {
    policy: Box<dyn Policy>,
    env_name: String,
}

#[pymethods]
impl PyController {
    #[new]
    #[pyo3(signature = (env, speed, yaw_rate = 0.0, gait = None))]
    fn new(env: &str, speed: f64, yaw_rate: f64, gait: Option<&str>) -> PyResult<Self> {
        if !speed.is_finite() || !yaw_rate.is_finite() {
            return Err(PyValueError::new_err(format!("speed and yaw_rate must be finite (got {speed}, {yaw_rate})")));
        }
        let gait = gait.map(parse_gait).transpose().map_err(runtime_error)?;
        let command = Command { speed: SpeedProfile::ramp(speed, RAMP_TIME), yaw_rate };
        let policy = baseline_controller_for(env, command, gait).map_err(runtime_error)?;
        Ok(PyController { policy, env_name: env.to_string() })
    }

    /// The options an env needs for this controller to drive it (Minitaur: torque actions), as
    /// (key, TOML value) pairs.
    #[staticmethod]
    fn env_options(env: &str) -> PyResult<Vec<(String, String)>> {
        let cfg = baseline_env(env).map_err(runtime_error)?;
        Ok(cfg.options.iter().map(|(k, v)| (k.clone(), v.to_string())).collect())
    }

    /// Called at every reset.
    fn begin_episode(&mut self, episode: usize) {
        self.policy.begin_episode(episode);
    }

    /// The action for the env's current state.
    fn act(&mut self, env: &PyEnv, observation: Vec<f64>) -> PyResult<Vec<f64>> {
        let env = env.env();
        if env.spec().name != self.env_name {
            return Err(PyValueError::new_err(format!(
                "this controller drives '{}', not '{}'",
                self.env_name,
                env.spec().name
            )));
        }
        self.policy.act(env.as_ref(), &observation).map_err(runtime_error)
    }
}

/// A trained actor (any policy reference: a run directory, with a step budget or its newest
/// policy; a committed result run; a checkpoint; a budget policy file; an exported policy),
/// acting deterministically.
#[pyclass(name = "TrainedPolicy", module = "locobench._core", unsendable)]
struct PyTrainedPolicy {
    agent: Box<dyn locobench::agents::Agent>,
    env: String,
    env_options: Vec<(String, String)>,
    low: Vec<f64>,
    high: Vec<f64>,
    obs_dim: usize,
}

#[pymethods]
impl PyTrainedPolicy {
    #[new]
    #[pyo3(signature = (path, budget=None))]
    fn new(path: PathBuf, budget: Option<u64>) -> PyResult<Self> {
        if !path.exists() {
            return Err(PyFileNotFoundError::new_err(format!("{}: no such file or directory", path.display())));
        }
        let (run, agent) =
            locobench::train::resolve_policy(&path, budget).and_then(|p| p.load()).map_err(runtime_error)?;
        let env = make(&run.env).map_err(value_error)?;
        let spec = env.spec();
        Ok(PyTrainedPolicy {
            agent,
            env: run.env.name.clone(),
            env_options: run.env.options.iter().map(|(k, v)| (k.clone(), v.to_string())).collect(),
            low: spec.action_space.low.clone(),
            high: spec.action_space.high.clone(),
            obs_dim: spec.observation_space.dim(),
        })
    }

    /// The env the policy was trained on.
    #[getter]
    fn env(&self) -> String {
        self.env.clone()
    }

    /// The options of the env it was trained on, as (key, TOML value) pairs.
    #[getter]
    fn env_options(&self) -> Vec<(String, String)> {
        self.env_options.clone()
    }

    /// The deterministic action for one observation, in the env's action bounds.
    fn act(&self, observation: Vec<f64>) -> PyResult<Vec<f64>> {
        if observation.len() != self.obs_dim {
            return Err(PyValueError::new_err(format!(
                "observation has {} entries, the policy takes {}",
                observation.len(),
                self.obs_dim
            )));
        }
        if let Some(i) = observation.iter().position(|v| !v.is_finite()) {
            return Err(PyValueError::new_err(format!("observation[{i}] is {}", observation[i])));
        }
        let obs: Vec<f32> = observation.iter().map(|&v| v as f32).collect();
        // The settings every network computation runs under, so Python gets the CLI's bits.
        let _runtime = Runtime::enter(1);
        let a = self.agent.act(&obs).map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
        Ok(a.iter()
            .zip(self.low.iter().zip(&self.high))
            .map(|(&a, (&l, &h))| l + (a as f64 + 1.0) * 0.5 * (h - l))
            .collect())
    }
}

/// The registered environment names.
#[pyfunction]
fn env_names_() -> Vec<&'static str> {
    env_names()
}

/// An offscreen renderer of one env's states (MuJoCo's renderer on OSMesa, or EGL with
/// `MUJOCO_GL=egl`). It holds an OpenGL context current on the thread that made it, so Python
/// may only use it from that thread (unsendable).
#[pyclass(name = "Renderer", module = "locobench._core", unsendable)]
struct PyRenderer {
    renderer: locobench::render::Renderer,
}

#[pymethods]
impl PyRenderer {
    #[new]
    #[pyo3(signature = (env, width = 640, height = 480, camera = "follow"))]
    fn new(env: &PyEnv, width: usize, height: usize, camera: &str) -> PyResult<Self> {
        let camera = locobench::render::Camera::parse(camera).map_err(value_error)?;
        let settings = locobench::render::RenderSettings { width, height, camera };
        let model = env.env().data().model().clone();
        let renderer = locobench::render::Renderer::new(&model, settings).map_err(runtime_error)?;
        Ok(PyRenderer { renderer })
    }

    /// The env's current state as RGB bytes, rows from the top: (width, height, bytes).
    fn render<'py>(
        &mut self,
        py: Python<'py>,
        env: &PyEnv,
    ) -> PyResult<(usize, usize, Bound<'py, pyo3::types::PyBytes>)> {
        let frame = self.renderer.render(env.env().data()).map_err(runtime_error)?;
        Ok((frame.width, frame.height, pyo3::types::PyBytes::new(py, &frame.rgb)))
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    locobench::runtime::configure_process();
    m.add_class::<PyEnv>()?;
    m.add_class::<PyVecEnv>()?;
    m.add_function(wrap_pyfunction!(episode_seed, m)?)?;
    m.add_class::<PyController>()?;
    m.add_class::<PyTrainedPolicy>()?;
    m.add_class::<PyRenderer>()?;
    m.add_function(wrap_pyfunction!(env_names_, m)?)?;
    Ok(())
}
