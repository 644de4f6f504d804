#!/usr/bin/env bash
# supine-core must build with neither std nor alloc. This checks it on a target that has no std at all,
# bpfel-unknown-none: Debian's libstd-rust-web-dev-bpf ships core, alloc and compiler_builtins for it, matched to the
# rustc-web (1.96) that the cross build already uses (rustup cannot add targets here, and Debian's wasm32 and windows
# standard libraries are built for an older rustc). The check builds against a private sysroot holding only core and
# compiler_builtins, so a dependency that pulls in std *or* alloc fails to resolve. It is `cargo check` (type check,
# no code generation): LLVM's BPF backend has no floating point, and the question is the dependency graph.
# A probe crate that asks for `alloc` must fail under the same sysroot, which shows the check can fail.
set -euo pipefail
cd "$(dirname "$0")/.."
target=bpfel-unknown-none
rustc=/usr/bin/rustc
libs=/usr/lib/rustlib/$target/lib
if [[ ! -x $rustc || ! -d $libs ]]; then
    echo "nostd-check: needs Debian's rustc-web and libstd-rust-web-dev-bpf (tests/setup.sh installs them)" >&2
    exit 1
fi
work=$(pwd)/target/nostd
sysroot=$work/sysroot
rm -rf "$sysroot"
mkdir -p "$sysroot/lib/rustlib/$target/lib"
cp "$libs"/libcore-* "$libs"/libcompiler_builtins-* "$sysroot/lib/rustlib/$target/lib/"

probe=$work/probe
mkdir -p "$probe/src"
printf '[package]\nname = "nostd-probe"\nversion = "0.0.0"\nedition = "2024"\n[workspace]\n' >"$probe/Cargo.toml"
printf '#![no_std]\nextern crate alloc;\npub fn f() -> alloc::vec::Vec<u8> { alloc::vec::Vec::new() }\n' >"$probe/src/lib.rs"
if RUSTC=$rustc RUSTFLAGS="--sysroot $sysroot" CARGO_TARGET_DIR=$work/target \
    cargo check -q --manifest-path "$probe/Cargo.toml" --target $target 2>"$work/probe.log"; then
    echo "nostd-check: the probe that uses alloc built: the sysroot does not exclude alloc" >&2
    exit 1
fi
grep -q "can't find crate for \`alloc\`" "$work/probe.log" || {
    echo "nostd-check: the probe failed for another reason:" >&2
    cat "$work/probe.log" >&2
    exit 1
}
# opt-level 0 for the dependencies: a type check generates no code for them, but the root Cargo.toml's
# [profile.dev.package."*"] opt-level = 3 also reaches the proc macros and build scripts this check compiles and runs
# (serde_derive, syn, ...), which took most of the step's CPU time (165 s -> 62 s).
RUSTC=$rustc RUSTFLAGS="--sysroot $sysroot" CARGO_TARGET_DIR=$work/target \
    cargo check -p supine-core --target $target --config 'profile.dev.package."*".opt-level = 0'
echo "nostd-check: supine-core builds for $target with core only (no std, no alloc)"
