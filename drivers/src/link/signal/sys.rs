//! The unsafe libc calls behind [`super`]: a SIGINT/SIGTERM handler that only sets an atomic flag.
#![allow(unsafe_code)]

use std::io;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set by the signal handler; read by the command loops.
pub static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_signum: libc::c_int) {
    // Async-signal-safe: a single atomic store.
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Install [`on_signal`] for SIGINT and SIGTERM (`signal.h`), without `SA_RESTART` so that a blocking
/// `poll(2)` returns `EINTR` and the loop sees the flag at once.
pub fn install_interrupt_handler() -> io::Result<()> {
    for signum in [libc::SIGINT, libc::SIGTERM] {
        // SAFETY: sigaction is plain old data; zeroed means no flags and an empty mask before we fill it in.
        let mut action: libc::sigaction = unsafe { std::mem::zeroed() };
        action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
        action.sa_flags = 0;
        // SAFETY: `action.sa_mask` is a valid sigset_t to initialise.
        unsafe { libc::sigemptyset(&mut action.sa_mask) };
        // SAFETY: `action` is fully initialised and outlives the call; the old action is not requested.
        if unsafe { libc::sigaction(signum, &action, std::ptr::null_mut()) } != 0 {
            return Err(io::Error::last_os_error());
        }
    }
    Ok(())
}
