//! The `bsdfit` command line; see [`bsdfit::cli`].

fn main() {
    restore_default_sigpipe();
    std::process::exit(bsdfit::cli::main());
}

/// `bsdfit models | head` closes the pipe early. Rust ignores SIGPIPE, so the next
/// `println!` would panic with "failed printing to stdout"; a command-line tool should
/// end quietly instead, as `ls | head` does. Restoring the default action does that.
#[cfg(unix)]
fn restore_default_sigpipe() {
    const SIGPIPE: i32 = 13; // the same on Linux and macOS
    const SIG_DFL: usize = 0;
    extern "C" {
        fn signal(signum: i32, handler: usize) -> usize;
    }
    // SAFETY: called once at start-up, before any thread exists; installs the default
    // disposition for one signal.
    unsafe {
        signal(SIGPIPE, SIG_DFL);
    }
}

#[cfg(not(unix))]
fn restore_default_sigpipe() {}
