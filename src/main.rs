mod cli;

fn main() {
    // End quietly when the reader of our output goes away (`locobench eval ... | head`), as Unix
    // tools do; Rust's default turns that into a panic on the next print.
    // SAFETY: setting a signal's disposition to the default before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    // Before any other thread or candle code runs (see src/runtime.rs); every command then
    // computes under the same settings as training.
    locobench::runtime::configure_process();
    let _runtime = locobench::runtime::Runtime::enter(1);
    if let Err(e) = locobench::numeric::kernel_path::process_path() {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
    if let Err(e) = cli::run() {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
