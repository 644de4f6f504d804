//! Records the commit this crate is built from (`SUPINE_BUILD_COMMIT`), so that every report and model file names
//! the code that produced it rather than whatever the checkout holds when the binary runs: a binary kept from an
//! earlier commit and run in a newer checkout used to report the newer commit.

use std::path::Path;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let o = Command::new("git").args(args).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

fn main() {
    // Rerun on a new commit (HEAD, the branch's ref, the index) and on an edit of any crate the binaries hold,
    // so that the dirty mark follows the sources too.
    if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
        let dir = Path::new(&dir);
        for f in ["HEAD", "index", "packed-refs"] {
            println!("cargo:rerun-if-changed={}", dir.join(f).display());
        }
        if let Some(r) = git(&["symbolic-ref", "-q", "HEAD"]) {
            println!("cargo:rerun-if-changed={}", dir.join(r).display());
        }
    }
    for src in [
        "src",
        "../core/src",
        "../drivers/src",
        "Cargo.toml",
        "../Cargo.lock",
    ] {
        println!("cargo:rerun-if-changed={src}");
    }
    let commit = match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(h) => {
            let dirty = git(&[
                "--no-optional-locks",
                "status",
                "--porcelain",
                "--untracked-files=no",
            ])
            .is_some_and(|s| !s.is_empty());
            if dirty { format!("{h}+dirty") } else { h }
        }
        None => "unknown".into(),
    };
    println!("cargo:rustc-env=SUPINE_BUILD_COMMIT={commit}");
}
