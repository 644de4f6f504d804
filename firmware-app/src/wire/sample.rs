//! `supine wire sample`.

use super::SampleArgs;
use crate::failure::Failure;

/// Run `supine wire sample`.
pub fn run(_args: &SampleArgs) -> Result<(), Failure> {
    Err(anyhow::anyhow!("`supine wire sample` is not built yet").into())
}
