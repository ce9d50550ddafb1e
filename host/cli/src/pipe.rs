//! What happens when the reader of standard output goes away (`ocm ... | head`).
//!
//! Rust ignores SIGPIPE, so a write to a closed pipe returns an error, and `println!` turns that
//! error into a panic with a backtrace. Unix tools end quietly instead: the default action of
//! SIGPIPE ends the process, and the shell reports it as 128 + 13.

/// Restores the default action of SIGPIPE (Linux with glibc; elsewhere a no-op).
pub fn end_quietly_when_the_reader_leaves() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    #[allow(unsafe_code)]
    // SAFETY: signal only sets the disposition of SIGPIPE; it is called first thing in main,
    // before any other thread exists, and SIG_DFL is a valid disposition for it.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
