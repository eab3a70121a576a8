//! The evaluation cache: held-out episodes (and the report's clips) kept on disk under a key that
//! holds everything deciding their numbers, so a report regenerated with little new evaluates
//! only what is new. rliable and rl-baselines3-zoo keep scores the same way: computed once, read
//! after.
//!
//! A key is readable text: the code version (a digest of the source files the episodes depend on,
//! `build.rs`), the kernel path class and MuJoCo's version, the env with every option resolved
//! (reward weights included), the protocol's episodes and seed, the policy (a digest of its
//! weights and its run's `config.toml`, or the controller and its command), the speed profile and
//! the push. An entry's file is named by the key's SHA-256 and repeats the key, so a damaged or
//! mismatched entry is noticed, recomputed and rewritten with a warning; entries are written
//! atomically, so a killed report leaves none half-written.
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use anyhow::{bail, Context, Result};

use super::protocol::Protocol;
use super::push::Push;
use super::tracking::TrackingEpisode;
use crate::controller::command::SpeedProfile;
use crate::controller::measure::GaitEpisode;
use crate::envs::EnvConfig;

/// The first line of every entry: its format.
const HEADER: &str = "# locobench evaluation cache entry, format 1";

/// Digest of the code the episodes depend on (`build.rs`).
pub const EVAL_CODE: &str = env!("LOCOBENCH_EVAL_CODE");
/// Digest of that and the code that films and encodes a clip (`build.rs`).
pub const CLIP_CODE: &str = env!("LOCOBENCH_CLIP_CODE");

/// Everything that decides a cached result, as text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Key(String);

impl Key {
    /// The key of `policy`'s episodes under `protocol` in `env` (options resolved, so a default
    /// written out and one left unset are the same key), with the set-point `profile` and `push`.
    /// `policy` names what acts: `"agent <digest>"` for a trained policy
    /// (`train::PolicyRef::digest`), `"controller <speed>"`, `"random <seed>"`.
    pub fn episodes(
        env: &EnvConfig,
        protocol: &Protocol,
        policy: &str,
        profile: Option<&SpeedProfile>,
        push: Option<Push>,
    ) -> Result<Key> {
        Ok(Key(format!(
            "what = episodes\ncode = {EVAL_CODE}\n{}\n{}\nprotocol = {} episodes, seed {}\npolicy = {policy}\n\
             profile = {profile:?}\npush = {push:?}",
            machine_line(),
            env_line(env)?,
            protocol.episodes,
            protocol.seed,
        )))
    }

    /// The key of `policy`'s tracking episodes under `protocol` in `env`, a command task holding
    /// one command (its resolved options name it).
    pub fn tracking(env: &EnvConfig, protocol: &Protocol, policy: &str) -> Result<Key> {
        Ok(Key(format!(
            "what = tracking\ncode = {EVAL_CODE}\n{}\n{}\nprotocol = {} episodes, seed {}\npolicy = {policy}",
            machine_line(),
            env_line(env)?,
            protocol.episodes,
            protocol.seed,
        )))
    }

    /// The key of a clip: `what` describes its env, episode, panels and frame size.
    pub fn clip(what: &str) -> Key {
        Key(format!("what = clip\ncode = {CLIP_CODE}\n{}\n{what}", machine_line()))
    }

    /// The key as text.
    pub fn text(&self) -> &str {
        &self.0
    }

    /// SHA-256 of the text: the entry's file name.
    pub fn digest(&self) -> String {
        crate::io::sha256_hex(self.0.as_bytes())
    }
}

/// The numeric path and physics library: the exact kernels give the same bits on every CPU with
/// AVX2 and FMA, the library's do not.
fn machine_line() -> String {
    let kernels = crate::numeric::kernel_path::active();
    let class = if kernels.is_exact() { "exact" } else { kernels.name() };
    format!("kernels = {class}\nmujoco = {}", crate::mujoco::version())
}

/// The env's name and every option resolved, one line.
pub fn env_line(env: &EnvConfig) -> Result<String> {
    let options = env.resolved_options()?;
    let pairs: Vec<String> = options.iter().map(|(k, v)| format!("{k} = {v}")).collect();
    Ok(format!("env = {}\noptions = {}", env.name, pairs.join(", ")))
}

#[derive(Debug, Default)]
struct Counts {
    read: AtomicUsize,
    computed: AtomicUsize,
    damaged: AtomicUsize,
    /// Nanoseconds spent on keys, lookups and writes, summed over threads.
    overhead_ns: AtomicU64,
}

/// A cache directory, or none (every result computed, nothing kept). Clones share the
/// directory and the counts.
#[derive(Debug, Clone, Default)]
pub struct EvalCache {
    dir: Option<PathBuf>,
    counts: Arc<Counts>,
    used: Arc<Mutex<BTreeSet<PathBuf>>>,
}

impl EvalCache {
    /// No cache: compute everything, keep nothing (`report --no-cache`).
    pub fn off() -> EvalCache {
        EvalCache::default()
    }

    /// The cache in `dir`, created if absent; an error names the directory if it cannot be
    /// written.
    pub fn open(dir: &Path) -> Result<EvalCache> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("evaluation cache {}: cannot create the directory", dir.display()))?;
        tempfile::NamedTempFile::new_in(dir)
            .with_context(|| format!("evaluation cache {}: cannot write there", dir.display()))?;
        crate::io::remove_temporaries(dir)?;
        Ok(EvalCache { dir: Some(dir.to_path_buf()), ..EvalCache::default() })
    }

    /// The directory, if on.
    pub fn dir(&self) -> Option<&Path> {
        self.dir.as_deref()
    }

    fn path(&self, key: &Key) -> Option<PathBuf> {
        self.dir.as_ref().map(|d| d.join(format!("{}.txt", key.digest())))
    }

    /// Runs `f`, counting its time as the cache's overhead (building keys, hashing policies,
    /// reading and writing entries): what a report spends on the cache beyond evaluating.
    pub fn timed<T>(&self, f: impl FnOnce() -> T) -> T {
        let start = std::time::Instant::now();
        let out = f();
        self.counts.overhead_ns.fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        out
    }

    /// Seconds of overhead so far ([`EvalCache::timed`]), summed over threads.
    pub fn overhead_seconds(&self) -> f64 {
        self.counts.overhead_ns.load(Ordering::Relaxed) as f64 * 1e-9
    }

    /// The body kept under `key`, when its entry is there and whole. A damaged entry
    /// (unreadable, cut short, another key) is reported on stderr and counts as absent.
    pub fn lookup(&self, key: &Key) -> Option<String> {
        self.timed(|| self.lookup_untimed(key))
    }

    fn lookup_untimed(&self, key: &Key) -> Option<String> {
        let path = self.path(key)?;
        self.used.lock().unwrap_or_else(|p| p.into_inner()).insert(path.clone());
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return None,
            Err(e) => {
                self.damaged(key, &e.into());
                return None;
            }
        };
        let whole = (|| -> Result<String> {
            let rest = text.strip_prefix(HEADER).and_then(|r| r.strip_prefix('\n')).context("no header line")?;
            let (stored, body) = rest.split_once("\n---\n").context("no end of key")?;
            if stored != key.text() {
                bail!("it holds another key");
            }
            Ok(body.strip_suffix("--- end\n").context("cut short")?.to_string())
        })();
        whole.map_err(|e| self.damaged(key, &e)).ok()
    }

    /// Reports a damaged entry on stderr (it is then recomputed and rewritten).
    fn damaged(&self, key: &Key, why: &anyhow::Error) {
        self.counts.damaged.fetch_add(1, Ordering::Relaxed);
        let path = self.path(key).unwrap_or_default();
        eprintln!("warning: evaluation cache entry {} is damaged ({why:#}); recomputing it", path.display());
    }

    /// Counts a result taken from the cache.
    pub fn count_read(&self) {
        self.counts.read.fetch_add(1, Ordering::Relaxed);
    }

    /// Keeps `body` under `key` (atomically), when the cache is on.
    pub fn store(&self, key: &Key, body: &str) -> Result<()> {
        self.counts.computed.fetch_add(1, Ordering::Relaxed);
        let Some(path) = self.path(key) else { return Ok(()) };
        let text = format!("{HEADER}\n{}\n---\n{body}--- end\n", key.text());
        self.timed(|| {
            crate::io::write_bytes_atomic(&path, text.as_bytes())
                .with_context(|| format!("evaluation cache {}: writing an entry", path.display()))
        })
    }

    /// The episodes under `key`, read from the cache or computed by `compute` and kept.
    pub fn episodes(&self, key: &Key, compute: impl FnOnce() -> Result<Vec<GaitEpisode>>) -> Result<Vec<GaitEpisode>> {
        if let Some(body) = self.lookup(key) {
            match self.timed(|| parse_episodes(&body)) {
                Ok(episodes) => {
                    self.count_read();
                    return Ok(episodes);
                }
                Err(e) => self.damaged(key, &e),
            }
        }
        let episodes = compute()?;
        self.store(key, &self.timed(|| format_episodes(&episodes)))?;
        Ok(episodes)
    }

    /// The tracking episodes under `key`, read from the cache or computed by `compute` and kept.
    pub fn tracking(
        &self,
        key: &Key,
        compute: impl FnOnce() -> Result<Vec<TrackingEpisode>>,
    ) -> Result<Vec<TrackingEpisode>> {
        if let Some(body) = self.lookup(key) {
            match self.timed(|| parse_tracking(&body)) {
                Ok(episodes) => {
                    self.count_read();
                    return Ok(episodes);
                }
                Err(e) => self.damaged(key, &e),
            }
        }
        let episodes = compute()?;
        self.store(key, &self.timed(|| format_tracking(&episodes)))?;
        Ok(episodes)
    }

    /// (read, computed, damaged) so far.
    pub fn counts(&self) -> (usize, usize, usize) {
        let c = &self.counts;
        (c.read.load(Ordering::Relaxed), c.computed.load(Ordering::Relaxed), c.damaged.load(Ordering::Relaxed))
    }

    /// Removes the entries no lookup of this cache asked for (those of older code, options or
    /// policies); returns how many.
    pub fn prune_unused(&self) -> Result<usize> {
        let Some(dir) = &self.dir else { return Ok(0) };
        let used = self.used.lock().unwrap_or_else(|p| p.into_inner());
        let mut removed = 0;
        for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
            let path = entry?.path();
            if path.extension().is_some_and(|e| e == "txt") && !used.contains(&path) {
                std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
                removed += 1;
            }
        }
        Ok(removed)
    }
}

/// Names of reward terms and diagnostics read back from the cache, as the `&'static str` the
/// episodes hold: each distinct name is allocated once per process.
fn intern(name: &str) -> &'static str {
    static NAMES: Mutex<BTreeSet<&'static str>> = Mutex::new(BTreeSet::new());
    let mut names = NAMES.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(n) = names.get(name) {
        return n;
    }
    let leaked: &'static str = Box::leak(name.to_string().into_boxed_str());
    names.insert(leaked);
    leaked
}

/// The scalar fields of an episode, in the order an entry's lines hold them.
const FIELDS: [&str; 14] = [
    "return",
    "length",
    "fell",
    "unstable",
    "mean_speed",
    "speed_error",
    "yaw_rate",
    "sideways",
    "energy",
    "cost_of_transport",
    "weight_times_distance",
    "drift",
    "shake",
    "qp_failures",
];

/// One line per episode: the scalar fields, then `terms` and `diagnostics` as `name=value`, tab
/// separated. Floats are written shortest-round-trip, so they read back to the same bits.
const TRACKING_FIELDS: [&str; 6] = ["speed_rms", "yaw_rate_rms", "fell", "cost_of_transport", "settle_time", "speed"];

fn format_tracking(episodes: &[TrackingEpisode]) -> String {
    let mut out = format!("{}\n", TRACKING_FIELDS.join("\t"));
    for e in episodes {
        let settle = e.settle_time.map_or("none".to_string(), |t| format!("{t:?}"));
        out += &format!(
            "{:?}\t{:?}\t{}\t{:?}\t{settle}\t{:?}\n",
            e.speed_rms, e.yaw_rate_rms, e.fell, e.cost_of_transport, e.speed
        );
    }
    out
}

fn parse_tracking(body: &str) -> Result<Vec<TrackingEpisode>> {
    let mut lines = body.lines();
    if lines.next() != Some(TRACKING_FIELDS.join("\t").as_str()) {
        bail!("other columns");
    }
    let number = |s: &str| s.parse::<f64>().with_context(|| format!("{s:?} is not a number"));
    lines
        .enumerate()
        .map(|(i, line)| {
            let c: Vec<&str> = line.split('\t').collect();
            if c.len() != TRACKING_FIELDS.len() {
                bail!("episode {}: {} columns, not {}", i + 1, c.len(), TRACKING_FIELDS.len());
            }
            Ok(TrackingEpisode {
                speed_rms: number(c[0])?,
                yaw_rate_rms: number(c[1])?,
                fell: c[2].parse::<bool>().with_context(|| format!("{:?} is not true or false", c[2]))?,
                cost_of_transport: number(c[3])?,
                settle_time: if c[4] == "none" { None } else { Some(number(c[4])?) },
                speed: number(c[5])?,
            })
        })
        .collect()
}

fn format_episodes(episodes: &[GaitEpisode]) -> String {
    let mut out = format!("{}\tterms\tdiagnostics\n", FIELDS.join("\t"));
    for e in episodes {
        let scalars = [
            format!("{:?}", e.episode_return),
            e.length.to_string(),
            e.fell.to_string(),
            e.unstable.to_string(),
            format!("{:?}", e.mean_speed),
            format!("{:?}", e.speed_error),
            format!("{:?}", e.yaw_rate),
            format!("{:?}", e.sideways),
            format!("{:?}", e.energy),
            format!("{:?}", e.cost_of_transport),
            format!("{:?}", e.weight_times_distance),
            format!("{:?}", e.drift),
            format!("{:?}", e.shake),
            format!("{:?}", e.qp_failures),
        ];
        let pairs = |v: &[(&str, f64)]| v.iter().map(|(n, x)| format!("{n}={x:?}")).collect::<Vec<_>>().join(" ");
        out.push_str(&format!("{}\t{}\t{}\n", scalars.join("\t"), pairs(&e.reward_terms), pairs(&e.diagnostics)));
    }
    out
}

fn parse_episodes(body: &str) -> Result<Vec<GaitEpisode>> {
    let mut lines = body.lines();
    let header = lines.next().context("no column line")?;
    if header != format!("{}\tterms\tdiagnostics", FIELDS.join("\t")) {
        bail!("other columns");
    }
    let number = |s: &str| s.parse::<f64>().with_context(|| format!("{s:?} is not a number"));
    let pairs = |s: &str| -> Result<Vec<(&'static str, f64)>> {
        s.split(' ')
            .filter(|p| !p.is_empty())
            .map(|p| {
                let (n, v) = p.split_once('=').with_context(|| format!("{p:?} is not name=value"))?;
                Ok((intern(n), number(v)?))
            })
            .collect()
    };
    lines
        .enumerate()
        .map(|(i, line)| {
            let cols: Vec<&str> = line.split('\t').collect();
            if cols.len() != FIELDS.len() + 2 {
                bail!("episode {}: {} columns, not {}", i + 1, cols.len(), FIELDS.len() + 2);
            }
            let flag = |s: &str| s.parse::<bool>().with_context(|| format!("{s:?} is not true or false"));
            Ok(GaitEpisode {
                episode_return: number(cols[0])?,
                length: cols[1].parse().with_context(|| format!("{:?} is not a length", cols[1]))?,
                fell: flag(cols[2])?,
                unstable: flag(cols[3])?,
                mean_speed: number(cols[4])?,
                speed_error: number(cols[5])?,
                yaw_rate: number(cols[6])?,
                sideways: number(cols[7])?,
                energy: number(cols[8])?,
                cost_of_transport: number(cols[9])?,
                weight_times_distance: number(cols[10])?,
                drift: number(cols[11])?,
                shake: number(cols[12])?,
                qp_failures: number(cols[13])?,
                reward_terms: pairs(cols[14])?,
                diagnostics: pairs(cols[15])?,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn episode(x: f64) -> GaitEpisode {
        GaitEpisode {
            episode_return: x,
            length: 7,
            fell: true,
            mean_speed: 0.1 + x,
            cost_of_transport: f64::INFINITY,
            speed_error: -0.0,
            yaw_rate: f64::NAN,
            reward_terms: vec![("forward", 1.0 / 3.0), ("energy", -1e-300)],
            diagnostics: vec![("ticks_at_limit", 5.0)],
            ..GaitEpisode::default()
        }
    }

    fn same(a: &GaitEpisode, b: &GaitEpisode) -> bool {
        format_episodes(std::slice::from_ref(a)) == format_episodes(std::slice::from_ref(b))
            && a.episode_return.to_bits() == b.episode_return.to_bits()
            && a.speed_error.to_bits() == b.speed_error.to_bits()
    }

    #[test]
    fn tracking_episodes_read_back_to_the_same_bits() {
        let episodes = vec![
            TrackingEpisode {
                speed_rms: 0.1 + 0.2,
                yaw_rate_rms: f64::NAN,
                fell: true,
                cost_of_transport: 1.0 / 3.0,
                settle_time: None,
                speed: -0.0,
            },
            TrackingEpisode {
                speed_rms: 1e-300,
                yaw_rate_rms: 0.5,
                fell: false,
                cost_of_transport: f64::NAN,
                settle_time: Some(0.49),
                speed: 2.5,
            },
        ];
        let back = parse_tracking(&format_tracking(&episodes)).unwrap();
        for (a, b) in episodes.iter().zip(&back) {
            assert_eq!(a.speed_rms.to_bits(), b.speed_rms.to_bits());
            assert_eq!(a.yaw_rate_rms.is_nan(), b.yaw_rate_rms.is_nan());
            assert_eq!((a.fell, a.settle_time, a.speed.to_bits()), (b.fell, b.settle_time, b.speed.to_bits()));
            assert_eq!(a.cost_of_transport.is_nan(), b.cost_of_transport.is_nan());
        }
        assert!(parse_tracking("other\tcolumns\n").is_err());
    }

    #[test]
    fn episodes_read_back_to_the_same_bits() {
        let eps = vec![episode(0.1 + 0.2), episode(std::f64::consts::PI * 1e17)];
        let back = parse_episodes(&format_episodes(&eps)).unwrap();
        assert_eq!(back.len(), 2);
        for (a, b) in eps.iter().zip(&back) {
            assert!(same(a, b));
            assert_eq!(a.reward_terms[0].1.to_bits(), b.reward_terms[0].1.to_bits());
            assert_eq!(a.reward_terms[0].0, b.reward_terms[0].0);
            assert!(b.yaw_rate.is_nan() && b.cost_of_transport == f64::INFINITY);
        }
    }

    #[test]
    fn a_hit_reads_a_miss_computes_and_damage_recomputes() {
        let tmp = tempfile::tempdir().unwrap();
        let cache = EvalCache::open(tmp.path()).unwrap();
        let env = EnvConfig::new("hopper");
        let protocol = Protocol { episodes: 2, seed: 0 };
        let key = Key::episodes(&env, &protocol, "random 0", None, None).unwrap();
        let computed = cache.episodes(&key, || Ok(vec![episode(1.0), episode(2.0)])).unwrap();
        let read = cache.episodes(&key, || panic!("a hit must not compute")).unwrap();
        assert!(computed.iter().zip(&read).all(|(a, b)| same(a, b)));
        assert_eq!(cache.counts(), (1, 1, 0));

        // Anything that decides the numbers is another key.
        let other_env = EnvConfig::new("hopper").with_overrides(&[("ctrl_cost_weight".into(), "0.01".into())]).unwrap();
        let others = [
            Key::episodes(&other_env, &protocol, "random 0", None, None).unwrap(),
            Key::episodes(&env, &Protocol { episodes: 2, seed: 1 }, "random 0", None, None).unwrap(),
            Key::episodes(&env, &Protocol { episodes: 3, seed: 0 }, "random 0", None, None).unwrap(),
            Key::episodes(&env, &protocol, "random 1", None, None).unwrap(),
            Key::episodes(&env, &protocol, "random 0", None, Some(Push::lateral(0.5))).unwrap(),
        ];
        for k in &others {
            assert_ne!(k.digest(), key.digest());
        }
        // A default written out is the same key as one left unset.
        let explicit = EnvConfig::new("hopper").with_overrides(&[("ctrl_cost_weight".into(), "0.001".into())]).unwrap();
        assert_eq!(Key::episodes(&explicit, &protocol, "random 0", None, None).unwrap(), key);

        // A damaged entry: a warning, recomputed, rewritten whole.
        let file = tmp.path().join(format!("{}.txt", key.digest()));
        let text = std::fs::read_to_string(&file).unwrap();
        std::fs::write(&file, &text[..text.len() - 20]).unwrap();
        let again = cache.episodes(&key, || Ok(vec![episode(1.0), episode(2.0)])).unwrap();
        assert_eq!(again.len(), 2);
        assert_eq!(cache.counts(), (1, 2, 1));
        assert_eq!(std::fs::read_to_string(&file).unwrap(), text);
        // Unused entries go when asked.
        let unused = Key::episodes(&env, &protocol, "random 9", None, None).unwrap();
        EvalCache::open(tmp.path()).unwrap().store(&unused, "x\n").unwrap();
        assert_eq!(cache.prune_unused().unwrap(), 1);
        assert!(file.is_file());
    }

    #[test]
    fn a_cache_directory_that_cannot_be_written_is_an_error_naming_it() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("a-file");
        std::fs::write(&file, "").unwrap();
        let err = EvalCache::open(&file.join("cache")).unwrap_err();
        assert!(format!("{err:#}").contains("a-file/cache"), "{err:#}");
    }
}
