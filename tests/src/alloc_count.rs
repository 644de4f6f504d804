//! A counting global allocator for allocation tests: forwards every call to the system allocator and counts, per
//! thread, the allocations made while a [`count_allocations`] closure runs. A test binary installs it with
//! `#[global_allocator] static A: supine_tests::alloc_count::Counting = supine_tests::alloc_count::Counting;`;
//! the per-frame tests of every stage use it to prove that nothing allocates after start-up.
// A global allocator is an `unsafe impl` by definition; this one only forwards to `System` and counts.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

thread_local! {
    static WATCHING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

/// The counting allocator (install it as the test binary's `#[global_allocator]`).
pub struct Counting;

// SAFETY: every call is forwarded unchanged to the system allocator; the counters are thread-local Cells with const
// initialisers, which need no allocation and no destructor.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

fn count() {
    let _ = WATCHING.try_with(|w| {
        if w.get() {
            let _ = ALLOCATIONS.try_with(|a| a.set(a.get() + 1));
        }
    });
}

/// Run `f` and return its result with the number of heap allocations (and reallocations) it made on this thread.
/// Zero means nothing only if [`Counting`] is the binary's global allocator: check that with
/// [`counter_is_installed`].
pub fn count_allocations<R>(f: impl FnOnce() -> R) -> (R, u64) {
    let before = ALLOCATIONS.with(Cell::get);
    WATCHING.with(|w| w.set(true));
    let r = f();
    WATCHING.with(|w| w.set(false));
    (r, ALLOCATIONS.with(Cell::get) - before)
}

/// Whether the counter sees allocations in this binary (false when [`Counting`] is not the global allocator), so
/// that a zero count cannot pass vacuously.
pub fn counter_is_installed() -> bool {
    // black_box on the vector too: in release builds LLVM may otherwise elide the allocation and its free.
    let (v, n) =
        count_allocations(|| std::hint::black_box(Vec::<u8>::with_capacity(std::hint::black_box(32))));
    drop(std::hint::black_box(v));
    n >= 1
}
