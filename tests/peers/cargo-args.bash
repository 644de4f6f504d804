# shellcheck shell=bash
# Sourced by the peer scripts (not a peer check itself: tests/run.sh runs tests/peers/*.sh only). Sets
# $supine_build, the command that leaves the `supine` binary the peers drive in target/debug/, and $supine_cargo,
# the package/feature selection for a peer's own `cargo test`.
#
# Under tests/run.sh (SUPINE_PEERS=1) the build is the test step's own command with --no-run: cargo finds it fresh
# (about a second) and puts that step's binary in target/debug/. `cargo build -p supine` (with or without features)
# resolves the dependencies' features for supine alone, not for the whole workspace with its dev-dependencies,
# and rebuilt supine and part of its dependencies (twice: once per feature set, ~3 min on a clean clone).
# `--workspace --all-features --bin supine` for a single test still differs from the full test run (another
# harness, rebuilt once, for foxglove.sh). Run alone, a peer builds just `-p supine`.
if [[ -n ${SUPINE_PEERS:-} ]]; then
    supine_build=(cargo test -q --workspace --all-features --no-run)
    supine_cargo=(--workspace --all-features --bin supine)
else
    supine_build=(cargo build -q -p supine --bin supine)
    supine_cargo=(-p supine --bin supine)
fi
