//! Output files that cannot destroy an input or leave a half-written file behind.
//!
//! Every output path a command takes (`--out`, `--json`, `--sink file:`) goes through [`Output::create`] before any
//! work starts: it is refused when it resolves to the same file as one of the command's inputs or other outputs
//! (through symlinks, `..` or hard links: the device and inode are compared), and a temporary file is created beside
//! it at once, so an unwritable directory fails at start rather than after a whole run. The result is written to
//! the temporary file and renamed over the target by [`Output::commit`], so a failed run leaves the old file intact.
//! A failed run's temporary file is removed when it is empty and kept (and named in the error) when it holds a
//! partial result. Targets that are not regular files (`/dev/stdout`, a FIFO, `/dev/full`) are written directly.
//!
//! Cost: a few syscalls per output at start and at the end; nothing per frame.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use crate::failure::Failure;

/// Whether `a` and `b` name the same existing file (same device and inode, whatever the path spelling).
pub fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(ma), Ok(mb)) => ma.dev() == mb.dev() && ma.ino() == mb.ino(),
        _ => false,
    }
}

/// Refuse an output `path` (given as `flag`) that is one of `inputs` (as `(flag, path)` pairs).
pub fn refuse_overwriting(flag: &str, path: &Path, inputs: &[(&str, &Path)]) -> Result<(), Failure> {
    for (input_flag, input) in inputs {
        if same_file(path, input) {
            return Err(Failure::usage(format!(
                "{flag} {} is the same file as {input_flag} {}; refusing to write over an input",
                path.display(),
                input.display()
            )));
        }
    }
    Ok(())
}

/// An output file being written: a temporary file beside the target, renamed over it on [`Output::commit`].
#[derive(Debug)]
pub struct Output {
    target: PathBuf,
    /// The temporary path, or `None` when the target is written directly (not a regular file).
    temp: Option<PathBuf>,
    file: Option<File>,
}

/// Refuse two outputs named by the same path (`flag` at `path`, `other_flag` at `other` when given): a usage
/// error, before anything is opened.
pub fn refuse_same_output(
    flag: &str,
    path: &Path,
    other_flag: &str,
    other: Option<&Path>,
) -> Result<(), Failure> {
    if other == Some(path) {
        return Err(Failure::usage(format!(
            "{flag} and {other_flag} are both {}; give them different files",
            path.display()
        )));
    }
    Ok(())
}

impl Output {
    /// Check `target` (the value of `flag`) against `inputs` and open a temporary file beside it. Fails now if the
    /// target is a directory or its directory is not writable.
    pub fn create(flag: &str, target: &Path, inputs: &[(&str, &Path)]) -> Result<Self, Failure> {
        refuse_overwriting(flag, target, inputs)?;
        let meta = std::fs::metadata(target).ok();
        if meta.as_ref().is_some_and(|m| m.is_dir()) {
            return Err(anyhow::anyhow!("{flag} {}: is a directory", target.display()).into());
        }
        if meta.as_ref().is_some_and(|m| !m.is_file()) {
            // A device or FIFO: nothing to rename over; write straight to it.
            let file = OpenOptions::new()
                .write(true)
                .open(target)
                .map_err(|e| anyhow::anyhow!("{flag} {}: {e}", target.display()))?;
            return Ok(Output {
                target: target.to_owned(),
                temp: None,
                file: Some(file),
            });
        }
        if meta.as_ref().is_some_and(|m| m.permissions().readonly()) {
            return Err(anyhow::anyhow!("{flag} {}: the file is read-only", target.display()).into());
        }
        // Through a symlink, the file it points to is replaced and the link stays.
        let real = match std::fs::symlink_metadata(target) {
            Ok(m) if m.file_type().is_symlink() => {
                std::fs::canonicalize(target).unwrap_or_else(|_| target.to_owned())
            }
            _ => target.to_owned(),
        };
        let temp = temp_path(&real);
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&temp)
            .map_err(|e| anyhow::anyhow!("{flag} {}: cannot create a file there: {e}", target.display()))?;
        Ok(Output {
            target: real,
            temp: Some(temp),
            file: Some(file),
        })
    }

    /// The file to write the result into.
    pub fn file(&mut self) -> &mut File {
        self.file.as_mut().expect("an output is not used after commit")
    }

    /// Take the file out (for writers that own theirs); [`Output::commit`] then only renames.
    pub fn take_file(&mut self) -> File {
        self.file.take().expect("an output's file is taken once")
    }

    /// The target path.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Flush and sync what was written and rename it over the target.
    pub fn commit(mut self) -> Result<(), Failure> {
        if let Some(mut file) = self.file.take() {
            file.flush()
                .and_then(|()| {
                    if self.temp.is_some() {
                        file.sync_all()
                    } else {
                        Ok(())
                    }
                })
                .map_err(|e| anyhow::anyhow!("writing {}: {e}", self.target.display()))?;
        }
        if let Some(temp) = self.temp.take() {
            std::fs::rename(&temp, &self.target).map_err(|e| {
                let _ = std::fs::remove_file(&temp);
                anyhow::anyhow!("renaming {} to {}: {e}", temp.display(), self.target.display())
            })?;
        }
        Ok(())
    }

    /// Give up after a failure: an empty temporary file is removed; a partial one is kept and its path returned.
    pub fn abandon(mut self) -> Option<PathBuf> {
        self.file = None;
        let temp = self.temp.take()?;
        if std::fs::metadata(&temp).is_ok_and(|m| m.len() > 0) {
            Some(temp)
        } else {
            let _ = std::fs::remove_file(&temp);
            None
        }
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        // An output dropped without commit or abandon (an early `?`): never leave an empty temporary file.
        if let Some(temp) = self.temp.take()
            && std::fs::metadata(&temp).is_ok_and(|m| m.len() == 0)
        {
            let _ = std::fs::remove_file(&temp);
        }
    }
}

/// `dir/.name.PID.partial` beside `target` (`*.partial` is git-ignored).
fn temp_path(target: &Path) -> PathBuf {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".to_owned());
    let file = format!(".{name}.{}.partial", std::process::id());
    match target.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join(file),
        _ => PathBuf::from(file),
    }
}

/// Write `bytes` as the whole content of `out` and commit it.
pub fn write_all(mut out: Output, bytes: &[u8]) -> Result<(), Failure> {
    if let Err(e) = out.file().write_all(bytes) {
        let target = out.target().display().to_string();
        let kept = out.abandon();
        return Err(with_partial(anyhow::anyhow!("writing {target}: {e}"), kept).into());
    }
    out.commit()
}

/// Add "the partial output is in PATH" to an error when a failed run kept one.
pub fn with_partial(err: anyhow::Error, kept: Option<PathBuf>) -> anyhow::Error {
    match kept {
        Some(p) => anyhow::anyhow!("{err:#}; the partial output is kept in {}", p.display()),
        None => err,
    }
}

#[cfg(test)]
mod tests {
    use super::refuse_same_output;
    use std::path::Path;

    #[test]
    fn two_outputs_on_one_path_are_a_usage_error_naming_both() {
        let p = Path::new("out/r.json");
        let e = refuse_same_output("--png", p, "--json", Some(p)).unwrap_err();
        let msg = format!("{e}");
        assert!(msg.contains("--png and --json are both out/r.json"), "{msg}");
        assert!(refuse_same_output("--png", p, "--json", Some(Path::new("other.json"))).is_ok());
        assert!(refuse_same_output("--png", p, "--json", None).is_ok());
    }
}
