//! `supine wire listen`.

use super::ListenArgs;
use crate::failure::Failure;

/// Run `supine wire listen`.
pub fn run(_args: &ListenArgs) -> Result<(), Failure> {
    Err(anyhow::anyhow!("`supine wire listen` is not built yet").into())
}
