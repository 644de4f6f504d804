//! Heap-allocation counting for the figures `supine replay` and `supine demo` print: the binary's global allocator
//! is the system one behind `stats_alloc`'s counters (two relaxed atomic increments per allocation, nothing per
//! frame when the frame loop allocates nothing, which is what the count shows).

use stats_alloc::{INSTRUMENTED_SYSTEM, StatsAlloc};
use std::alloc::System;

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Heap allocations and reallocations made so far by every thread of the process.
pub fn count() -> u64 {
    let s = GLOBAL.stats();
    (s.allocations + s.reallocations) as u64
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_counter_sees_an_allocation() {
        let before = super::count();
        let v: Vec<u8> = Vec::with_capacity(std::hint::black_box(64));
        assert!(super::count() > before);
        drop(v);
    }
}
