//! Side-by-side benchmarks against what users would pick instead (issue 14): the supine halves of the ICP
//! comparison with Open3D and small_gicp ([`icp`]) and of the forest comparison with scikit-learn ([`forest`]), and
//! the `.npy` files they exchange with the Python peers ([`npy`]). `tests/bench/run.sh` drives them through the
//! `supine-bench` binary and writes docs/BENCHMARKS.md. Host only; nothing here runs per frame on the robot.

pub mod forest;
pub mod icp;
pub mod npy;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A progress bar on stderr (hidden when `show` is false).
pub fn progress_bar(len: u64, msg: &str, show: bool) -> ProgressBar {
    let b = ProgressBar::with_draw_target(
        Some(len),
        if show {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    b.set_style(
        ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    b.set_message(msg.to_string());
    b
}
