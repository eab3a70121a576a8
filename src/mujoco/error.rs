//! Routing of MuJoCo's error and warning callbacks into Rust.
//!
//! Errors: the C shim catches them (see `shim.c`) and the safe layer turns the return code into
//! [`MjError::Engine`] carrying MuJoCo's own message. Warnings: collected per thread and drained
//! by whoever called into MuJoCo on that thread (the environments drain them after each step).
//! With both handlers installed MuJoCo never writes `MUJOCO_LOG.TXT` nor reads stdin.
use std::cell::RefCell;
use std::ffi::CStr;
use std::os::raw::c_char;
use std::sync::Once;

use super::sys;

#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum MjError {
    #[error("MuJoCo could not load the model: {0}")]
    Load(String),
    #[error("MuJoCo error: {0}")]
    Engine(String),
    #[error("unknown {kind} name '{name}'")]
    UnknownName { kind: &'static str, name: String },
    #[error("{kind} index {index} out of range (model has {count})")]
    BadIndex { kind: &'static str, index: usize, count: usize },
    #[error("{what}: expected length {expected}, got {got}")]
    BadLength { what: &'static str, expected: usize, got: usize },
}

pub type MjResult<T> = Result<T, MjError>;

const MAX_PENDING_WARNINGS: usize = 64;

thread_local! {
    static WARNINGS: RefCell<Vec<String>> = const { RefCell::new(Vec::new()) };
}

unsafe extern "C" fn on_warning(msg: *const c_char) {
    // Must never unwind into C.
    let _ = std::panic::catch_unwind(|| {
        let text = if msg.is_null() {
            String::from("unknown MuJoCo warning")
        } else {
            unsafe { CStr::from_ptr(msg) }.to_string_lossy().into_owned()
        };
        WARNINGS.with(|w| {
            let mut w = w.borrow_mut();
            if w.len() < MAX_PENDING_WARNINGS {
                w.push(text);
            }
        });
    });
}

/// Installs the handlers once per process. Every safe entry point calls this first.
pub fn install_handlers() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| unsafe { sys::lb_install_handlers(Some(on_warning)) });
}

/// Returns and clears the warnings MuJoCo raised on this thread since the last call.
pub fn take_warnings() -> Vec<String> {
    WARNINGS.with(|w| std::mem::take(&mut *w.borrow_mut()))
}

pub(crate) fn last_engine_error() -> MjError {
    let msg = unsafe { CStr::from_ptr(sys::lb_last_error()) }.to_string_lossy().into_owned();
    MjError::Engine(if msg.is_empty() { "unknown error".into() } else { msg })
}

/// Turns a guarded shim call's return code into a `Result`.
pub(crate) fn check(rc: i32) -> MjResult<()> {
    if rc == 0 {
        Ok(())
    } else {
        Err(last_engine_error())
    }
}
