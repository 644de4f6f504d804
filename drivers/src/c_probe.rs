//! Test support: compile a tiny C or C++ program against a system header and read back the sizes, offsets and
//! constants it prints, so every FFI struct layout and ioctl number is checked against its real header.

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::Command;

/// A compiler for the probe: the program named by `env_var` (e.g. `CC`, `CXX`), or `default`.
pub struct Compiler {
    /// Environment variable that overrides the compiler.
    pub env_var: &'static str,
    /// Compiler used when the variable is unset.
    pub default: &'static str,
}

/// Compile `source` (saved as `file_name`, whose extension picks C or C++) with `args`, run it, and parse its
/// output lines `NAME VALUE`. The probe must print one line per name with `printf("%s %ld\n", …)`.
///
/// Panics with the compiler's message when the probe does not build: in a layout test that is a failure, never a skip.
pub fn run(compiler: &Compiler, args: &[&str], file_name: &str, source: &str) -> HashMap<String, i64> {
    // One folder per call: tests run as threads of one process, and two probes may share a file name.
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir: PathBuf = std::env::temp_dir().join(format!("supine-probe-{}-{call}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("creating the probe directory");
    let src = dir.join(file_name);
    let exe = dir.join("probe");
    std::fs::write(&src, source).expect("writing the probe source");
    let cc = std::env::var(compiler.env_var).unwrap_or_else(|_| compiler.default.into());
    let built = Command::new(&cc)
        .args(args)
        .arg(&src)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap_or_else(|e| panic!("the layout probe needs a compiler ({cc}): {e}"));
    assert!(
        built.status.success(),
        "probe failed to compile with {cc}: {}",
        String::from_utf8_lossy(&built.stderr)
    );
    let out = Command::new(&exe).output().expect("running the probe");
    let text = String::from_utf8(out.stdout).expect("probe output is ASCII");
    let _ = std::fs::remove_dir_all(&dir);
    text.lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(k, v)| {
            (
                k.to_owned(),
                v.parse().unwrap_or_else(|_| panic!("probe line {k} {v}")),
            )
        })
        .collect()
}

/// Assert that the probe's values equal Rust's, name by name, and that the probe printed nothing else.
pub fn assert_matches(c: &HashMap<String, i64>, rust: &[(&str, i64)]) {
    assert_eq!(
        c.len(),
        rust.len(),
        "probe printed {:?}",
        c.keys().collect::<Vec<_>>()
    );
    for (name, value) in rust {
        assert_eq!(
            c.get(*name),
            Some(value),
            "{name}: the header says {:?}, Rust says {value}",
            c.get(*name)
        );
    }
}
