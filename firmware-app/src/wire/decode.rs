//! `supine wire decode`.

use super::DecodeArgs;
use crate::failure::Failure;

/// Run `supine wire decode`.
pub fn run(_args: &DecodeArgs) -> Result<(), Failure> {
    Err(anyhow::anyhow!("`supine wire decode` is not built yet").into())
}
