//! A clean stop on SIGINT/SIGTERM for link tools and the service loop: the handler only sets a flag that loops
//! poll ([`interrupted`], one atomic load). Blocking waits in the links (`poll(2)` with a timeout) return early on
//! `EINTR`, so a loop sees the flag within one wait slice.

mod sys;

use std::sync::atomic::Ordering;

/// Route SIGINT and SIGTERM to the flag that [`interrupted`] reads (instead of killing the process mid-write).
pub fn catch_interrupts() -> std::io::Result<()> {
    sys::install_interrupt_handler()
}

/// Whether SIGINT or SIGTERM arrived since [`catch_interrupts`].
pub fn interrupted() -> bool {
    sys::INTERRUPTED.load(Ordering::SeqCst)
}
