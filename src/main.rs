mod cli;

fn main() {
    // End quietly when the reader of our output goes away (`locobench eval ... | head`), as Unix
    // tools do; Rust's default turns that into a panic on the next print.
    // SAFETY: setting a signal's disposition to the default before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // candle's default thread pools busy-wait; one thread is fastest at these sizes (REFERENCE
    // §6). Set before any candle code runs; users can still choose otherwise.
    for var in ["RAYON_NUM_THREADS", "CANDLE_NUM_THREADS"] {
        if std::env::var_os(var).is_none() {
            std::env::set_var(var, "1");
        }
    }
    // The training hot-path settings (agents::denormals, agents::allocator) for every command,
    // so that `eval` and `record` compute exactly as evaluation during training did.
    locobench::agents::flush_denormals_to_zero();
    locobench::agents::keep_freed_memory();
    if let Err(e) = cli::run() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
