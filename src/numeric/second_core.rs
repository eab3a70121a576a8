//! One helper thread per training thread, so that independent halves of a dense layer (the twin
//! critics of TD3 and SAC, or the two halves of a batch) run on both cores.
//!
//! Not a pool: a thread enables its own helper with [`enable_on_this_thread`], and [`join`]
//! offers the helper one closure while the caller runs the other (an `OwnedHelper` is the same
//! helper held by a value, for callers that are not a training thread). If the helper has not
//! picked the offered closure up by the time the caller is done with its own, the caller takes it
//! back and runs it too, so a sleeping or descheduled helper (another process on the core) costs at
//! most the speed of one thread, never a wait. The helper spins for a short while after each job
//! (the next one of an update usually follows within microseconds) and then parks, so an idle
//! helper sleeps and a busy machine is not made busier (measured here: candle's default pools
//! busy-wait and collapse under contention). The spin uses plain loads, not `pause`: on this
//! VM a `pause` loop gets the virtual CPU descheduled (pause-loop exiting), which measured as
//! 27 us hand-offs instead of 1 us. After the first 20 us it yields the core between checks,
//! which kept two such processes side by side at 112-123 updates/s each instead of 79-85.
//!
//! Which thread runs which half never changes a result: the halves write disjoint outputs and
//! the helper runs with the caller's floating-point mode (flush-to-zero), so a run is the same
//! bit for bit with or without the helper (tested in `dense.rs`).
use std::cell::{RefCell, UnsafeCell};
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;
use std::thread::{JoinHandle, Thread};
use std::time::{Duration, Instant};

use super::denormals::{float_mode, set_float_mode};

/// How long a waiting side spins before it parks. Long enough to span the gaps between the
/// split layers of one update and between updates of a training loop (an actor step or an
/// environment step); waking a parked thread on this VM took 100-200 us, more than the half
/// layer it was woken for. TD3 400-300 with two threads: 60 us -> 147-163 updates/s,
/// 1 ms -> 180-183.
const SPIN: Duration = Duration::from_millis(1);
/// After this much of SPIN, the waiting side yields its core between checks.
const SPIN_ALONE: Duration = Duration::from_micros(20);

const IDLE: u32 = 0;
const POSTED: u32 = 1;
const RUNNING: u32 = 2;
const DONE: u32 = 3;
const SHUTDOWN: u32 = 4;

type Job = *mut (dyn FnMut() + Send);

struct Shared {
    state: AtomicU32,
    /// Written by the owner before `state` becomes POSTED, read by the helper after it sees it.
    job: UnsafeCell<Option<Job>>,
    /// The owner's MXCSR (flush-to-zero bits) at the time of posting.
    mxcsr: AtomicU32,
    panic: UnsafeCell<Option<Box<dyn std::any::Any + Send>>>,
    owner: Thread,
}

// SAFETY: `job` and `panic` are only touched by one side at a time, handed over through the
// acquire/release transitions of `state` (owner writes job -> POSTED -> helper runs it, writes
// panic -> DONE -> owner reads both).
unsafe impl Sync for Shared {}
// SAFETY: as for `Sync`: the hand-over through `state` orders every access.
unsafe impl Send for Shared {}

struct Helper {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

thread_local! {
    static HELPER: RefCell<Option<Helper>> = const { RefCell::new(None) };
}

/// Starts a helper thread for the calling thread (once; later calls do nothing). From then on
/// the dense layers this thread runs use both cores. Use it on one training thread per machine
/// of two cores; parallel runs (sweeps) should leave it off.
pub(crate) fn enable_on_this_thread() {
    HELPER.with(|h| {
        let mut h = h.borrow_mut();
        if h.is_none() {
            *h = Some(Helper::start());
        }
    });
}

/// Whether this thread has a helper (`join` then runs its second closure on the other core).
pub(crate) fn has_helper() -> bool {
    HELPER.with(|h| h.borrow().is_some())
}

/// Stops this thread's helper, if any.
pub(crate) fn disable_on_this_thread() {
    HELPER.with(|h| h.borrow_mut().take());
}

/// Enables this thread's helper until dropped (stopping it only if it was off before).
pub(crate) struct HelperGuard {
    was_on: bool,
}

impl HelperGuard {
    pub fn start() -> HelperGuard {
        let was_on = HELPER.with(|h| h.borrow().is_some());
        enable_on_this_thread();
        HelperGuard { was_on }
    }
}

impl Drop for HelperGuard {
    fn drop(&mut self) {
        if !self.was_on {
            disable_on_this_thread();
        }
    }
}

/// Runs `a` on this thread and `b` on its helper at the same time, or both here, `a` first, when
/// this thread has no helper. Returns when both are done; a panic in either is passed on.
pub fn join<A: FnOnce(), B: FnOnce() + Send>(a: A, b: B) {
    // taken out while in use, so a nested `join` inside `a` runs sequentially
    let Some(helper) = HELPER.with(|h| h.borrow_mut().take()) else {
        a();
        b();
        return;
    };
    let outcome = run_pair(&helper, a, b);
    HELPER.with(|h| *h.borrow_mut() = Some(helper));
    if let Err(p) = outcome {
        resume_unwind(p);
    }
}

/// A helper thread owned by a value instead of a thread: whichever thread holds it runs `join`'s
/// second closure on it. For work that does not run under a training thread's helper (a vector
/// environment stepped from Python, say), where a thread spawned per call would cost more than
/// the half it runs. A helper wakes the thread that started it, so a holder on another thread
/// starts a new one (rare: the value moved), which keeps the hand-over every training update
/// makes as it is.
pub(crate) struct OwnedHelper {
    helper: Helper,
    holder: std::thread::ThreadId,
}

impl OwnedHelper {
    pub(crate) fn start() -> OwnedHelper {
        OwnedHelper { helper: Helper::start(), holder: std::thread::current().id() }
    }

    /// As [`join`], on this helper.
    pub(crate) fn join<A: FnOnce(), B: FnOnce() + Send>(&mut self, a: A, b: B) {
        if self.holder != std::thread::current().id() {
            *self = OwnedHelper::start();
        }
        if let Err(p) = run_pair(&self.helper, a, b) {
            resume_unwind(p);
        }
    }
}

/// `a` here and `b` on `helper` (or here, after `a`, if the helper has not picked it up); the
/// first panic of either.
fn run_pair<A: FnOnce(), B: FnOnce() + Send>(helper: &Helper, a: A, b: B) -> std::thread::Result<()> {
    let mut b = Some(b);
    let mut b_once = move || {
        if let Some(b) = b.take() {
            b()
        }
    };
    let job: &mut (dyn FnMut() + Send) = &mut b_once;
    // SAFETY: the lifetime is erased so the helper can hold the pointer; below, the job is either
    // taken back or waited for before this frame (and `b_once`) can go away, also when `a`
    // panics (caught).
    let job: Job = unsafe { std::mem::transmute::<&mut (dyn FnMut() + Send), Job>(job) };
    helper.post(job);
    let outcome = catch_unwind(AssertUnwindSafe(a));
    let helper_panic = if helper.take_back() {
        // SAFETY: the helper never saw the job; this frame still owns the closure.
        catch_unwind(AssertUnwindSafe(|| unsafe { (*job)() })).err()
    } else {
        helper.wait_done();
        helper.take_panic()
    };
    outcome?;
    helper_panic.map_or(Ok(()), Err)
}

/// Runs `f(helper)` twice, each time on a new thread: without a helper thread, then with one
/// (`helper` true). A panic in `f` is passed on. For tests of code that splits its work.
#[cfg(test)]
pub(crate) fn with_and_without_helper(f: impl Fn(bool) + Sync) {
    for helper in [false, true] {
        std::thread::scope(|scope| {
            let run = scope.spawn(|| {
                if helper {
                    enable_on_this_thread();
                }
                f(helper)
            });
            if let Err(panic) = run.join() {
                resume_unwind(panic);
            }
        });
    }
}

/// Spins for up to SPIN, then parks, until `state` is one of `wanted`.
fn wait_for(state: &AtomicU32, wanted: &[u32]) -> u32 {
    let started = Instant::now();
    let mut spins = 0u32;
    loop {
        let now = state.load(Ordering::Acquire);
        if wanted.contains(&now) {
            return now;
        }
        spins = spins.wrapping_add(1);
        if spins.is_multiple_of(256) {
            let waited = started.elapsed();
            if waited >= SPIN {
                std::thread::park();
            } else if waited >= SPIN_ALONE {
                // gives the core to another runnable thread, if there is one
                std::thread::yield_now();
            }
        }
    }
}

impl Helper {
    fn start() -> Helper {
        let shared = Arc::new(Shared {
            state: AtomicU32::new(IDLE),
            job: UnsafeCell::new(None),
            mxcsr: AtomicU32::new(float_mode()),
            panic: UnsafeCell::new(None),
            owner: std::thread::current(),
        });
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("locobench-helper".into())
            .spawn(move || Helper::serve(&theirs))
            .expect("could not start the helper thread");
        Helper { shared, thread: Some(thread) }
    }

    fn serve(shared: &Shared) {
        let mut mxcsr = float_mode();
        loop {
            if wait_for(&shared.state, &[POSTED, SHUTDOWN]) == SHUTDOWN {
                return;
            }
            if shared.state.compare_exchange(POSTED, RUNNING, Ordering::Acquire, Ordering::Relaxed).is_err() {
                continue; // the owner took it back
            }
            let wanted = shared.mxcsr.load(Ordering::Relaxed);
            if wanted != mxcsr {
                set_float_mode(wanted);
                mxcsr = wanted;
            }
            // SAFETY: POSTED hands `job` to this thread; the owner keeps the closure alive until
            // it sees DONE.
            let job = unsafe { (*shared.job.get()).take() }.expect("posted without a job");
            // SAFETY: the closure behind `job` stays alive until the owner sees DONE, set below.
            let outcome = catch_unwind(AssertUnwindSafe(|| unsafe { (*job)() }));
            if let Err(p) = outcome {
                // SAFETY: the owner reads `panic` only after DONE.
                unsafe { *shared.panic.get() = Some(p) };
            }
            shared.state.store(DONE, Ordering::Release);
            shared.owner.unpark();
        }
    }

    fn post(&self, job: Job) {
        // SAFETY: the helper is IDLE, so it does not touch `job` until POSTED is stored.
        unsafe { *self.shared.job.get() = Some(job) };
        self.shared.mxcsr.store(float_mode(), Ordering::Relaxed);
        self.shared.state.store(POSTED, Ordering::Release);
        self.thread.as_ref().expect("helper thread").thread().unpark();
    }

    /// Withdraws a posted job the helper has not started; true if it was withdrawn.
    fn take_back(&self) -> bool {
        let withdrawn = self.shared.state.compare_exchange(POSTED, IDLE, Ordering::Acquire, Ordering::Relaxed).is_ok();
        if withdrawn {
            // SAFETY: the helper lost the race for the job and will not read it.
            unsafe { *self.shared.job.get() = None };
        }
        withdrawn
    }

    fn wait_done(&self) {
        wait_for(&self.shared.state, &[DONE]);
        self.shared.state.store(IDLE, Ordering::Relaxed);
    }

    fn take_panic(&self) -> Option<Box<dyn std::any::Any + Send>> {
        // SAFETY: after DONE the helper no longer touches `panic`.
        unsafe { (*self.shared.panic.get()).take() }
    }
}

impl Drop for Helper {
    fn drop(&mut self) {
        self.shared.state.store(SHUTDOWN, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            thread.thread().unpark();
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_halves_run_with_and_without_a_helper() {
        std::thread::spawn(|| {
            for enabled in [false, true] {
                if enabled {
                    enable_on_this_thread();
                }
                let mut out = [0u64; 2];
                let (left, right) = out.split_at_mut(1);
                for _ in 0..1000 {
                    join(|| left[0] += 1, || right[0] += 2);
                }
                assert_eq!(out, [1000, 2000]);
            }
            disable_on_this_thread();
        })
        .join()
        .unwrap();
    }

    #[test]
    fn the_helper_runs_at_the_same_time_with_the_callers_float_mode() {
        std::thread::spawn(|| {
            enable_on_this_thread();
            super::super::denormals::flush_denormals_to_zero();
            let me = std::thread::current().id();
            let helper_ran = std::sync::atomic::AtomicBool::new(false);
            let mut seen = None;
            let mut tiny = 1.0f32;
            join(
                // returns only once the other half has run, so that half cannot be taken back
                || {
                    while !helper_ran.load(Ordering::Acquire) {
                        std::thread::yield_now();
                    }
                },
                || {
                    seen = Some(std::thread::current().id());
                    tiny = std::hint::black_box(f32::MIN_POSITIVE) / 4.0;
                    helper_ran.store(true, Ordering::Release);
                },
            );
            assert_ne!(seen, Some(me));
            #[cfg(target_arch = "x86_64")]
            assert_eq!(tiny, 0.0);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn a_panic_in_the_helper_reaches_the_caller_and_the_helper_survives() {
        std::thread::spawn(|| {
            enable_on_this_thread();
            let caught = catch_unwind(AssertUnwindSafe(|| join(|| {}, || panic!("in the helper"))));
            assert!(caught.is_err());
            let mut ran = false;
            join(|| {}, || ran = true);
            assert!(ran);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn an_owned_helper_serves_whichever_thread_holds_it() {
        let mut helper = OwnedHelper::start();
        for round in 0..2 {
            // each round on a new thread; the helper's half outlasts SPIN, so the holder parks and
            // must be woken by the helper (a helper that woke the thread that started it would
            // leave the holder parked)
            helper = std::thread::spawn(move || {
                super::super::denormals::flush_denormals_to_zero();
                let me = std::thread::current().id();
                let started = std::sync::atomic::AtomicBool::new(false);
                let (mut seen, mut tiny) = (None, 1.0f32);
                helper.join(
                    // returns once the helper has the other half, so that half cannot be taken back
                    || {
                        while !started.load(Ordering::Acquire) {
                            std::thread::yield_now();
                        }
                    },
                    || {
                        started.store(true, Ordering::Release);
                        std::thread::sleep(SPIN * 3);
                        seen = Some(std::thread::current().id());
                        tiny = std::hint::black_box(f32::MIN_POSITIVE) / 4.0;
                    },
                );
                assert!(seen.is_some_and(|t| t != me), "round {round}: the helper ran the second half");
                #[cfg(target_arch = "x86_64")]
                assert_eq!(tiny, 0.0, "round {round}: the helper ran with the holder's float mode");
                let caught = catch_unwind(AssertUnwindSafe(|| helper.join(|| {}, || panic!("in the helper"))));
                assert!(caught.is_err(), "round {round}: the helper's panic reaches the holder");
                helper
            })
            .join()
            .unwrap();
        }
    }
}
