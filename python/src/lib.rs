//! Python bindings: the environments, the controller and trained policies. The Python package
//! (`python/locobench/`) wraps these in Gymnasium's API; this module only moves numbers across
//! and turns every Rust error into a Python exception carrying its message.
use std::path::PathBuf;
use std::sync::Mutex;

mod vector_step;

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

    /// On a command task: the velocity command in force, (forward speed m/s, yaw rate rad/s);
    /// None on other envs.
    #[getter]
    fn command(&self) -> Option<(f64, f64)> {
        self.env().command().map(|[v, w]| (v, w))
    }

    /// On a command task: holds this command (forward speed m/s, yaw rate rad/s) from the next
    /// step until the next reset. Other envs raise ValueError.
    fn set_command(&self, speed: f64, yaw_rate: f64) -> PyResult<()> {
        self.env().set_command(speed, yaw_rate).map_err(value_error)
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
    // A pyclass must be Sync; the locks are only ever taken by the thread holding the object.
    envs: Mutex<VecEnv>,
    /// `[copies, action dim]`, the shape of the action arrays `step_gym` takes.
    action_shape: [usize; 2],
    keys: Mutex<Option<vector_step::InfoKeys>>,
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
        let action_shape = [envs.len(), envs.spec().action_space.low.len()];
        Ok(PyVecEnv { envs: Mutex::new(envs), action_shape, keys: Mutex::new(None) })
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

    /// Steps every copy `n` times with the same actions in Rust, without crossing into Python
    /// between steps (what `python/bench_speed.py` compares the Python vector env against).
    fn step_repeat(&self, py: Python<'_>, actions: Vec<Vec<f64>>, n: usize) -> PyResult<()> {
        let envs = &self.envs;
        py.detach(|| {
            let mut envs = envs.lock().unwrap_or_else(|p| p.into_inner());
            (0..n).try_for_each(|_| envs.step(&actions).map(|_| ()))
        })
        .map_err(value_error)
    }

    /// `step` as Gymnasium's vector API returns it (`vector_step`): `actions` a float64 or float32
    /// `[copies, action dim]` array in, NumPy arrays and batched infos out; None, without stepping,
    /// for actions of any other type or shape (the Python side converts or refuses those). What
    /// the Python vector env steps with: little of a step holds the GIL.
    fn step_gym<'py>(
        &self,
        py: Python<'py>,
        actions: &Bound<'py, PyAny>,
    ) -> PyResult<Option<vector_step::GymStep<'py>>> {
        let Some(rows) = vector_step::action_rows(actions, self.action_shape) else { return Ok(None) };
        let envs = &self.envs;
        let s = py.detach(|| envs.lock().unwrap_or_else(|p| p.into_inner()).step(&rows)).map_err(value_error)?;
        let mut keys = self.keys.lock().unwrap_or_else(|p| p.into_inner());
        vector_step::gym_step(py, s, &mut keys, |info| info_dict(py, info, false)).map(Some)
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
    evaluation_options: Vec<(String, String)>,
    low: Vec<f64>,
    high: Vec<f64>,
    obs_dim: usize,
    training: (u64, u64, usize),
    /// The env it was trained on, and the path it was loaded from: what command warnings name.
    trained_env: EnvConfig,
    path: PathBuf,
}

#[pymethods]
impl PyTrainedPolicy {
    #[new]
    #[pyo3(signature = (path, budget=None, device="cpu"))]
    fn new(path: PathBuf, budget: Option<u64>, device: &str) -> PyResult<Self> {
        if !path.exists() {
            return Err(PyFileNotFoundError::new_err(format!("{}: no such file or directory", path.display())));
        }
        let device: locobench::device::ComputeDevice = device.parse().map_err(value_error)?;
        let (run, agent) =
            locobench::train::resolve_policy(&path, budget).and_then(|p| p.load_on(device)).map_err(runtime_error)?;
        let env = make(&run.env).map_err(value_error)?;
        let spec = env.spec();
        let pairs = |cfg: &EnvConfig| cfg.options.iter().map(|(k, v)| (k.clone(), v.to_string())).collect();
        Ok(PyTrainedPolicy {
            agent,
            env: run.env.name.clone(),
            env_options: pairs(&run.env),
            evaluation_options: pairs(&run.env.for_evaluation()),
            low: spec.action_space.low.clone(),
            high: spec.action_space.high.clone(),
            obs_dim: spec.observation_space.dim(),
            training: (run.seed, run.train.total_steps, run.train.eval_episodes),
            trained_env: run.env.clone(),
            path,
        })
    }

    /// One line per command `env` will give (its schedule's, or its ranges' corners) outside the
    /// ranges this policy was trained on, naming the policy and its range: `locobench eval`'s
    /// warnings. Empty for an env that is not a command task.
    fn command_warnings(&self, env: &PyEnv) -> PyResult<Vec<String>> {
        locobench::envs::command::command_warnings(&self.trained_env, &env.config, &self.path.display().to_string())
            .map_err(value_error)
    }

    /// (seed, steps, evaluation episodes) of the run that trained it: what the protocol's
    /// held-out episodes are checked apart from.
    #[getter]
    fn training(&self) -> (u64, u64, usize) {
        self.training
    }

    /// The env the policy was trained on.
    #[getter]
    fn env(&self) -> String {
        self.env.clone()
    }

    /// The options of the env it was trained on, as (key, TOML value) pairs, its training
    /// perturbations included.
    #[getter]
    fn env_options(&self) -> Vec<(String, String)> {
        self.env_options.clone()
    }

    /// The options of the env it is evaluated in, as (key, TOML value) pairs: the training
    /// options with the perturbations switched off (`EnvConfig::for_evaluation`), the world
    /// `locobench eval`, `report` and `record` play it in.
    #[getter]
    fn evaluation_options(&self) -> Vec<(String, String)> {
        self.evaluation_options.clone()
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

/// A Python callable from observation (a list of floats) to action (a list of floats), as a
/// policy the protocol plays. A Python exception raised by the callable is kept and raised again
/// when the evaluation stops.
struct CallablePolicy {
    act: Py<PyAny>,
    act_dim: usize,
    error: Option<PyErr>,
}

impl Policy for CallablePolicy {
    fn name(&self) -> String {
        "python policy".into()
    }

    fn act(&mut self, _env: &dyn locobench::envs::Env, observation: &[f64]) -> anyhow::Result<Vec<f64>> {
        let result = Python::attach(|py| -> PyResult<Vec<f64>> {
            self.act.call1(py, (observation.to_vec(),))?.extract::<Vec<f64>>(py)
        });
        let action = match result {
            Ok(a) => a,
            Err(e) => {
                let message = e.to_string();
                self.error = Some(e);
                anyhow::bail!("the policy raised {message}");
            }
        };
        if action.len() != self.act_dim {
            let e = PyValueError::new_err(format!(
                "the policy returned {} action values, the env takes {}",
                action.len(),
                self.act_dim
            ));
            self.error = Some(e);
            anyhow::bail!("wrong action size");
        }
        if let Some(i) = action.iter().position(|v| !v.is_finite()) {
            self.error = Some(PyValueError::new_err(format!("the policy returned action[{i}] = {}", action[i])));
            anyhow::bail!("non-finite action");
        }
        Ok(action)
    }
}

fn interval_tuple(i: locobench::evaluation::stats::Interval) -> (f64, f64, f64) {
    (i.estimate, i.low, i.high)
}

fn summary_dict<'py>(
    py: Python<'py>,
    s: &locobench::evaluation::summary::HeldOutSummary,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("episodes", s.episodes)?;
    d.set_item("return_mean", interval_tuple(s.mean))?;
    d.set_item("return_iqm", interval_tuple(s.iqm))?;
    d.set_item("return_std", s.std)?;
    d.set_item("falls", s.falls)?;
    d.set_item("fall_rate", interval_tuple(s.fall_rate))?;
    d.set_item("length", s.length)?;
    d.set_item("speed", s.speed)?;
    d.set_item("cost_of_transport", s.cost_of_transport)?;
    let terms = PyDict::new(py);
    for (t, v) in &s.reward_terms {
        terms.set_item(t, *v)?;
    }
    d.set_item("reward_terms", terms)?;
    d.set_item("text", s.lines().join("\n"))?;
    Ok(d)
}

/// Plays `act` on the protocol's held-out episodes of `env`'s configuration (fresh envs, the
/// reset seeds of `locobench eval --seed SEED`) and returns the statistics `locobench eval`
/// prints, optionally with the controller at the policy's speed and survival under pushes.
/// `run`: (seed, steps, evaluation episodes) of the run that trained the policy, when known, to
/// check that no held-out episode is one it trained or was evaluated on.
#[pyfunction]
/// `out` and `meta`: write the episodes and their provenance there (`evaluation::external`);
/// `meta` holds label, library, library_version, policy_file, policy_sha256, author and
/// optionally seed and steps.
#[pyo3(signature = (env, act, episodes, seed, pushes, controller, run=None, out=None, meta=None))]
#[allow(clippy::too_many_arguments)]
fn evaluate<'py>(
    py: Python<'py>,
    env: &PyEnv,
    act: Py<PyAny>,
    episodes: usize,
    seed: u64,
    pushes: Vec<f64>,
    controller: bool,
    run: Option<(u64, u64, usize)>,
    out: Option<PathBuf>,
    meta: Option<Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    use locobench::evaluation::summary::{controller_at_speed, push_survival, HeldOutSummary};
    if episodes == 0 {
        return Err(PyValueError::new_err("episodes must be at least 1"));
    }
    if let Some(dv) = pushes.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return Err(PyValueError::new_err(format!("push level {dv}: a velocity change must be a finite number >= 0")));
    }
    let protocol = locobench::evaluation::Protocol { episodes, seed };
    if let Some((run_seed, steps, eval_episodes)) = run {
        protocol.check_disjoint(run_seed, steps, eval_episodes).map_err(runtime_error)?;
    }
    let cfg = env.config.clone();
    let mut fresh = make(&cfg).map_err(value_error)?;
    let act_dim = fresh.spec().action_space.dim();
    let mut policy = CallablePolicy { act, act_dim, error: None };
    let _runtime = Runtime::enter(1);
    let played = protocol.run(fresh.as_mut(), &mut policy, None, None);
    let eps = match (played, policy.error.take()) {
        (_, Some(e)) => return Err(e),
        (Err(e), None) => return Err(runtime_error(e)),
        (Ok(eps), None) => eps,
    };
    if let Some(dir) = &out {
        let meta = meta.ok_or_else(|| PyValueError::new_err("out needs meta (label, library, ...)"))?;
        let text = |key: &str| -> PyResult<String> {
            Ok(meta.get_item(key)?.map(|v| v.extract::<String>()).transpose()?.unwrap_or_default())
        };
        let number = |key: &str| -> PyResult<Option<u64>> {
            Ok(match meta.get_item(key)? {
                Some(v) if !v.is_none() => Some(v.extract::<u64>()?),
                _ => None,
            })
        };
        let record = locobench::evaluation::external::ExternalMeta {
            label: text("label")?,
            env: cfg.name.clone(),
            options: cfg.resolved_options().map_err(value_error)?,
            episodes,
            protocol_seed: seed,
            library: text("library")?,
            library_version: text("library_version")?,
            policy_file: text("policy_file")?,
            policy_sha256: text("policy_sha256")?,
            machine: locobench::evaluation::external::this_machine(),
            author: text("author")?,
            locobench_version: env!("CARGO_PKG_VERSION").to_string(),
            seed: number("seed")?,
            steps: number("steps")?,
        };
        locobench::evaluation::external::write(dir, &record, &eps).map_err(runtime_error)?;
    }
    let summary = HeldOutSummary::of(&eps);
    let d = summary_dict(py, &summary)?;
    d.set_item("env", cfg.name.clone())?;
    d.set_item("protocol_seed", seed)?;
    d.set_item("episode_returns", eps.iter().map(|e| e.episode_return).collect::<Vec<_>>())?;
    d.set_item("episode_falls", eps.iter().map(|e| e.fell).collect::<Vec<_>>())?;
    if controller {
        if locobench::controller::baseline::baseline_env(&cfg.name).is_err() {
            return Err(PyValueError::new_err(format!("{} has no controller (minitaur and ant do)", cfg.name)));
        }
        match controller_at_speed(&cfg, protocol, (summary.speed * 1000.0).round() / 1000.0, &eps)
            .map_err(runtime_error)?
        {
            Some(m) => {
                let c = summary_dict(py, &m.summary)?;
                c.set_item("commanded", m.commanded)?;
                c.set_item("policy_better", interval_tuple(m.policy_better))?;
                d.set_item("controller", c)?;
            }
            None => d.set_item("controller", py.None())?,
        }
    }
    if !pushes.is_empty() {
        let p = PyDict::new(py);
        for dv in pushes {
            let (survived, n) =
                push_survival(&cfg, protocol, &mut policy, dv).map_err(|e| match policy.error.take() {
                    Some(py_err) => py_err,
                    None => runtime_error(e),
                })?;
            let w = locobench::evaluation::stats::wilson(survived, n);
            p.set_item(dv, (survived, n, (w.estimate, w.low, w.high)))?;
        }
        d.set_item("pushes", p)?;
    }
    Ok(d)
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

/// Writes an exported policy from actor tensors by locobench's names (`locobench.import_sb3`):
/// each tensor as (name, shape, values); checked against the agent `config` builds.
#[pyfunction]
fn import_policy(
    out: PathBuf,
    tensors: Vec<(String, Vec<usize>, Vec<f64>)>,
    config: String,
    source: String,
) -> PyResult<String> {
    let mut map = std::collections::HashMap::new();
    for (name, shape, values) in tensors {
        let t = candle_core::Tensor::from_vec(values, shape, &candle_core::Device::Cpu)
            .map_err(|e| value_error(format!("tensor {name}: {e}")))?;
        map.insert(name, t);
    }
    let path = locobench::train::import_policy(&out, map, &config, &source).map_err(runtime_error)?;
    Ok(path.display().to_string())
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    locobench::runtime::configure_process();
    m.add_class::<PyEnv>()?;
    m.add_class::<PyVecEnv>()?;
    m.add_function(wrap_pyfunction!(episode_seed, m)?)?;
    m.add("CUDA_BUILT", locobench::device::ComputeDevice::CUDA_BUILT)?;
    // "dev" (python/test.sh's build: our crates unoptimised) or "release", so that a speed
    // measurement can refuse a dev build.
    m.add("BUILD_PROFILE", if cfg!(debug_assertions) { "dev" } else { "release" })?;
    m.add_class::<PyController>()?;
    m.add_class::<PyTrainedPolicy>()?;
    m.add_class::<PyRenderer>()?;
    m.add_function(wrap_pyfunction!(env_names_, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(import_policy, m)?)?;
    Ok(())
}
