//! Ctrl-C during training: the first SIGINT sets a flag that the loop checks after every
//! step (it then writes `last.bpk` and exits with an error saying how to resume); the
//! handler also restores the default action, so a second Ctrl-C kills at once. Only the
//! `train` command installs it; library callers (tests) are unaffected.

use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn on_sigint(_: libc::c_int) {
    REQUESTED.store(true, Ordering::SeqCst);
    // SAFETY: signal() is async-signal-safe; SIG_DFL makes the next Ctrl-C terminate.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
    }
}

/// Installs the handler (no-op off Unix).
pub fn install() {
    #[cfg(unix)]
    // SAFETY: the handler only stores an atomic and calls signal(), both async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, on_sigint as *const () as libc::sighandler_t);
    }
}

/// Whether Ctrl-C was pressed since the handler was installed.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}
