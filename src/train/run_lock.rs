//! `run.lock` in a run directory while a process trains it: its pid and host, and an exclusive
//! `flock(2)` on the file for as long as the process lives. A second process is refused while the
//! first holds it (two trainers writing one run directory would corrupt it); the kernel lets go
//! of the lock when its holder dies, however it dies, so a lock left by a killed process is
//! simply taken over. `locobench sweep status` reads the pid and host to tell a running job from
//! one that died.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

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
    /// Holds the flock until the guard is dropped (or the process dies).
    _file: std::fs::File,
}

/// Takes the exclusive flock on `file` without waiting; false if another open file holds it.
fn try_flock(file: &std::fs::File) -> bool {
    use std::os::fd::AsRawFd;
    // SAFETY: flock(2) on a descriptor this process owns for the call's duration.
    unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

fn held_by_another(run_dir: &Path) -> anyhow::Error {
    let who = match read_lock(run_dir) {
        Some(info) if info.host == hostname() || info.host.is_empty() => format!("process {} on this host", info.pid),
        Some(info) => format!("process {} on host {}", info.pid, info.host),
        None => "another process".to_string(),
    };
    anyhow::anyhow!("{} is being trained by {who}; stop it first (or wait for it)", run_dir.display())
}

/// An error if another process holds the run directory's lock.
pub(crate) fn refuse_if_running(run_dir: &Path) -> Result<()> {
    let path = run_dir.join(LOCK_FILE);
    if let Ok(file) = std::fs::OpenOptions::new().read(true).write(true).open(&path) {
        if !try_flock(&file) {
            return Err(held_by_another(run_dir));
        }
        // Released when `file` closes here.
    }
    Ok(())
}

impl RunLock {
    pub(crate) fn acquire(run_dir: &Path) -> Result<RunLock> {
        use std::io::Write;
        use std::os::unix::fs::MetadataExt;
        let path = run_dir.join(LOCK_FILE);
        loop {
            let mut file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .with_context(|| format!("opening {}", path.display()))?;
            if !try_flock(&file) {
                return Err(held_by_another(run_dir));
            }
            // A holder that let go between our open and our flock removed the file first; then
            // we hold a lock on a name nobody sees, and must lock the file that is there now.
            let same_file =
                std::fs::metadata(&path).is_ok_and(|m| m.ino() == file.metadata().map(|f| f.ino()).unwrap_or(0));
            if !same_file {
                continue;
            }
            let info = LockInfo { pid: std::process::id(), host: hostname() };
            file.set_len(0)?;
            file.write_all(toml::to_string(&info)?.as_bytes())?;
            return Ok(RunLock { path, _file: file });
        }
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

        // Another open file holds the flock (as another process would): refused, naming the pid
        // the file records.
        {
            let _held = RunLock::acquire(dir.path()).unwrap();
            let other = std::fs::OpenOptions::new().read(true).write(true).open(dir.path().join(LOCK_FILE)).unwrap();
            assert!(!try_flock(&other));
            let err = refuse_if_running(dir.path()).unwrap_err().to_string();
            assert!(err.contains(&format!("process {}", std::process::id())), "{err}");
        }

        // A dead one (no such pid) is replaced; another host's cannot be checked.
        let dead = LockInfo { pid: u32::MAX - 1, host: hostname() };
        assert_eq!(dead.alive(), Some(false));
        std::fs::write(dir.path().join(LOCK_FILE), toml::to_string(&dead).unwrap()).unwrap();
        drop(RunLock::acquire(dir.path()).unwrap());
        assert_eq!(LockInfo { pid: 1, host: "elsewhere".into() }.alive(), None);
    }
}
