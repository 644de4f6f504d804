//! `supine wire send`.

use super::SendArgs;
use crate::failure::Failure;

/// Run `supine wire send`.
pub fn run(_args: &SendArgs) -> Result<(), Failure> {
    Err(anyhow::anyhow!("`supine wire send` is not built yet").into())
}
