# shellcheck shell=bash
# Sourced by the peer scripts (not a peer check itself: tests/run.sh runs tests/peers/*.sh only). Sets
# $supine_cargo, the package/feature selection for the `cargo build` and `cargo test` that give the peers their
# `supine` binary in target/debug/.
#
# Under tests/run.sh (SUPINE_PEERS=1) it is the selection of run.sh's test step, `--workspace --all-features`, so
# cargo finds the binary and the test harnesses that step built fresh. `-p supine` (with or without features)
# resolves the dependencies' features for supine alone, a different set from the whole workspace's, and rebuilt
# supine and part of its dependencies twice more (once per feature set, ~3 min on a clean clone). Run alone, a
# peer builds just `-p supine`.
if [[ -n ${SUPINE_PEERS:-} ]]; then
    supine_cargo=(--workspace --all-features --bin supine)
else
    supine_cargo=(-p supine --bin supine)
fi
