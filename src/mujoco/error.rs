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

/// What can go wrong in the MuJoCo layer.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum MjError {
    /// The MJCF did not compile; MuJoCo's message says where.
    #[error("MuJoCo could not load the model: {0}")]
    Load(String),
    /// MuJoCo raised a fatal error during simulation.
    #[error("MuJoCo error: {0}")]
    Engine(String),
    /// No element of this kind has this name.
    #[error("unknown {kind} name '{name}'")]
    UnknownName {
        /// The element kind (`body`, `site`, ...).
        kind: &'static str,
        /// The name asked for.
        name: String,
    },
    /// An element index past the model's count.
    #[error("{kind} index {index} out of range (model has {count})")]
    BadIndex {
        /// The element kind.
        kind: &'static str,
        /// The index asked for.
        index: usize,
        /// How many the model has.
        count: usize,
    },
    /// An array of the wrong length was passed in.
    #[error("{what}: expected length {expected}, got {got}")]
    BadLength {
        /// Which array.
        what: &'static str,
        /// The length the model needs.
        expected: usize,
        /// The length given.
        got: usize,
    },
}

/// A result whose error is [`MjError`].
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
            // SAFETY: MuJoCo passes a NUL-terminated message, checked non-null above.
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
    // SAFETY: `on_warning` has the signature the shim stores, never unwinds into C, and lives for the whole
    // program; `Once` installs it before any model exists.
    ONCE.call_once(|| unsafe { sys::lb_install_handlers(Some(on_warning)) });
}

/// Returns and clears the warnings MuJoCo raised on this thread since the last call.
pub fn take_warnings() -> Vec<String> {
    WARNINGS.with(|w| std::mem::take(&mut *w.borrow_mut()))
}

pub(crate) fn last_engine_error() -> MjError {
    // SAFETY: the shim returns its thread-local, NUL-terminated buffer, never NULL.
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
