//! The FFI calls of the clock: `clock_gettime(CLOCK_MONOTONIC)` and `clock_gettime(CLOCK_THREAD_CPUTIME_ID)`.
//!
//! Layout sources: `struct timespec` is `libc::timespec` (glibc `<time.h>`: `time_t tv_sec; long tv_nsec`, 16 bytes
//! on x86-64 and aarch64); `CLOCK_MONOTONIC` is 1 in `<linux/time.h>` (`libc::CLOCK_MONOTONIC`). Both are checked
//! against the real header by the probe test below.
#![allow(unsafe_code)]

/// `CLOCK_MONOTONIC` in µs.
pub fn monotonic_us() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux, so the call cannot fail
    // (a failure would leave `ts` at zero, which reads as time 0, not as garbage).
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec.max(0) as u64 * 1_000_000 + ts.tv_nsec.max(0) as u64 / 1_000
}

/// `CLOCK_THREAD_CPUTIME_ID` in ns: CPU time the calling thread has used.
pub fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: as above; the calling thread's CPU-time clock always exists on Linux.
    unsafe {
        libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts);
    }
    ts.tv_sec.max(0) as u64 * 1_000_000_000 + ts.tv_nsec.max(0) as u64
}

#[cfg(test)]
mod tests {
    use crate::c_probe::{self, Compiler};

    #[test]
    fn timespec_and_clock_id_match_the_c_header() {
        let probe = c_probe::run(
            &Compiler {
                env_var: "CC",
                default: "cc",
            },
            &[],
            "clock.c",
            "#include <stdio.h>\n#include <time.h>\nint main(void) {\n\
             printf(\"sizeof_timespec %ld\\n\", (long)sizeof(struct timespec));\n\
             printf(\"CLOCK_MONOTONIC %ld\\n\", (long)CLOCK_MONOTONIC);\n return 0; }\n",
        );
        assert_eq!(probe["sizeof_timespec"], size_of::<libc::timespec>() as i64);
        assert_eq!(probe["CLOCK_MONOTONIC"], libc::CLOCK_MONOTONIC as i64);
    }
}
