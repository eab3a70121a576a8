//! `run.lock` in a run directory while a process trains it: its pid and host. A second
//! process on the same host is refused while the first is alive (two trainers writing one
//! run directory would corrupt it); `locobench sweep status` reads it to tell a running job
//! from one that died. A lock left by a dead process is replaced.
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::io::write_bytes_atomic;

pub(crate) const LOCK_FILE: &str = "run.lock";

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct LockInfo {
    pub(crate) pid: u32,
    pub(crate) host: String,
}

impl LockInfo {
    /// Whether the process that wrote the lock still runs. `None`: it ran on another host,
    /// so this one cannot tell.
    pub(crate) fn alive(&self) -> Option<bool> {
        (self.host == hostname()).then(|| Path::new(&format!("/proc/{}", self.pid)).exists())
    }
}

/// The machine's host name (empty if it cannot be read).
pub(crate) fn hostname() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: the buffer is valid for its length; gethostname NUL-terminates on success.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if rc != 0 {
        return String::new();
    }
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    String::from_utf8_lossy(&buf[..end]).into_owned()
}

/// The lock of a run directory, if there is one.
pub(crate) fn read_lock(run_dir: &Path) -> Option<LockInfo> {
    toml::from_str(&std::fs::read_to_string(run_dir.join(LOCK_FILE)).ok()?).ok()
}

/// Held while training; removed when dropped.
#[derive(Debug)]
pub(crate) struct RunLock {
    path: PathBuf,
}

/// An error if another live process of this host holds the run directory's lock.
pub(crate) fn refuse_if_running(run_dir: &Path) -> Result<()> {
    if let Some(other) = read_lock(run_dir) {
        if other.pid != std::process::id() && other.alive() == Some(true) {
            bail!(
                "{} is being trained by process {} on this host; stop it first (or wait for it)",
                run_dir.display(),
                other.pid
            );
        }
    }
    Ok(())
}

impl RunLock {
    pub(crate) fn acquire(run_dir: &Path) -> Result<RunLock> {
        refuse_if_running(run_dir)?;
        let path = run_dir.join(LOCK_FILE);
        let info = LockInfo { pid: std::process::id(), host: hostname() };
        write_bytes_atomic(&path, toml::to_string(&info)?.as_bytes())?;
        Ok(RunLock { path })
    }
}

impl Drop for RunLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_lock_refuses_a_second_trainer_and_a_dead_one_is_replaced() {
        let dir = tempfile::tempdir().unwrap();
        {
            let _lock = RunLock::acquire(dir.path()).unwrap();
            let info = read_lock(dir.path()).unwrap();
            assert_eq!(info.pid, std::process::id());
            assert_eq!(info.alive(), Some(true));
        }
        // Dropping the guard removed the file.
        assert!(read_lock(dir.path()).is_none());

        // A live process of this host (pid 1 always exists) holds it: refused.
        let other = LockInfo { pid: 1, host: hostname() };
        write_bytes_atomic(&dir.path().join(LOCK_FILE), toml::to_string(&other).unwrap().as_bytes()).unwrap();
        let err = RunLock::acquire(dir.path()).unwrap_err().to_string();
        assert!(err.contains("process 1"), "{err}");

        // A dead one (no such pid) is replaced; another host's cannot be checked.
        let dead = LockInfo { pid: u32::MAX - 1, host: hostname() };
        assert_eq!(dead.alive(), Some(false));
        write_bytes_atomic(&dir.path().join(LOCK_FILE), toml::to_string(&dead).unwrap().as_bytes()).unwrap();
        drop(RunLock::acquire(dir.path()).unwrap());
        assert_eq!(LockInfo { pid: 1, host: "elsewhere".into() }.alive(), None);
    }
}
