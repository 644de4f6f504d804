# shellcheck shell=bash disable=SC2034
# (SC2034: the variables set here are used by the scripts that source this file.)
# Shared by the cross/ scripts (sourced, not run): repository paths, error helpers and the environment that points
# cargo at Debian's rustc-web, the aarch64 linker, pkg-config for arm64 libraries and qemu as the test runner.

cross_dir=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$cross_dir/.." && pwd)

# The Debian compiler (package rustc-web). Override for experiments, e.g. SUPINE_CROSS_RUSTC=/path/to/rustc.
cross_rustc=${SUPINE_CROSS_RUSTC:-/usr/bin/rustc}
# Separate from target/ (the host's rustup toolchain): two compilers sharing one target dir invalidate each other.
cross_target_dir=${SUPINE_CROSS_TARGET_DIR:-$root/target/cross}
# Built packages land here (gitignored).
cross_out=$root/cross/out

die() {
    echo "cross/${0##*/}: error: $*" >&2
    exit 1
}

usage_error() {
    echo "cross/${0##*/}: $*" >&2
    echo "Try 'cross/${0##*/} --help'." >&2
    exit 2
}

sudo_if_needed() {
    if [[ $(id -u) -eq 0 ]]; then
        "$@"
    elif command -v sudo >/dev/null 2>&1; then
        sudo "$@"
    else
        die "need root for: $* (run as root or install sudo)"
    fi
}

# Prints the usage block: the comment lines at the top of the calling script, without the leading '# '.
print_help() {
    sed -n '2,/^[^#]/{/^#/!q;s/^# \{0,1\}//;p}' "$0"
}

# Seconds since the epoch with centiseconds, for the step times the scripts print.
now() { date +%s.%N | cut -c1-13; }
elapsed() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

# cross_env ARCH: exports everything cargo needs to build (and run) for ARCH (aarch64 or x86_64). Sets
# $triple, $deb_arch, $multiarch, $strip_tool, $objcopy_tool, $runner for the caller.
cross_env() {
    case ${1:-} in
    aarch64 | arm64)
        triple=aarch64-unknown-linux-gnu
        deb_arch=arm64
        multiarch=aarch64-linux-gnu
        strip_tool=aarch64-linux-gnu-strip
        objcopy_tool=aarch64-linux-gnu-objcopy
        linker=aarch64-linux-gnu-gcc
        # The arm64 libc6 (multiarch, pulled in by the arm64 driver libraries) provides /lib/ld-linux-aarch64.so.1
        # and the loader cache knows /usr/lib/aarch64-linux-gnu, so qemu needs no -L prefix; the guest-only
        # LD_LIBRARY_PATH makes the driver libraries' lookup independent of the host's ld.so.cache.
        runner="qemu-aarch64-static -E LD_LIBRARY_PATH=/usr/lib/aarch64-linux-gnu:/lib/aarch64-linux-gnu"
        ;;
    x86_64 | amd64)
        triple=x86_64-unknown-linux-gnu
        deb_arch=amd64
        multiarch=x86_64-linux-gnu
        strip_tool="strip"
        objcopy_tool="objcopy"
        linker=cc
        runner=""
        ;;
    "") usage_error "missing ARCH (aarch64 or x86_64)" ;;
    *) usage_error "unknown ARCH '$1' (expected aarch64 or x86_64)" ;;
    esac
    [[ -x $cross_rustc ]] || die "$cross_rustc not found: run cross/setup first (installs Debian's rustc-web)"
    command -v cargo >/dev/null 2>&1 || die "cargo not found on PATH: install Rust with rustup (https://rustup.rs)"
    command -v "$linker" >/dev/null 2>&1 || die "linker $linker not found: run cross/setup first"
    if [[ -n $runner ]]; then
        command -v "${runner%% *}" >/dev/null 2>&1 || die "${runner%% *} not found: run cross/setup first"
    fi

    local up=${triple^^}
    up=${up//-/_}
    export RUSTC=$cross_rustc
    # rustdoc must match rustc (doctests under `cargo test`).
    export RUSTDOC=${cross_rustc%/*}/rustdoc
    export CARGO_TARGET_DIR=$cross_target_dir
    export "CARGO_TARGET_${up}_LINKER=$linker"
    # The host's linker too, whatever ARCH is: with --target equal to the host triple, cargo links build scripts
    # and proc macros with [target.HOST].linker and keeps it in their fingerprint, so a build for x86_64 (which
    # sets it) and one for aarch64 (which did not) invalidated each other's host artifacts, and with them every
    # crate: cross/package rebuilt the whole aarch64 binary (~200 s) after cross/test's x86_64 build.
    local host_up
    host_up=$("$cross_rustc" -vV | sed -n 's/^host: //p')
    host_up=${host_up^^}
    host_up=${host_up//-/_}
    [[ -n $host_up ]] || die "$cross_rustc -vV names no host triple"
    if [[ $host_up != "$up" ]]; then
        export "CARGO_TARGET_${host_up}_LINKER=cc"
    fi
    if [[ -n $runner ]]; then
        export "CARGO_TARGET_${up}_RUNNER=$runner"
    fi
    # Target-only flags (build scripts and proc macros of the host are untouched): find the driver libraries of
    # the target architecture, and let the linker resolve their own dependencies (libusb, libudev, libstdc++).
    export "CARGO_TARGET_${up}_RUSTFLAGS=-L native=/usr/lib/$multiarch -C link-arg=-Wl,-rpath-link,/usr/lib/$multiarch -C link-arg=-Wl,-rpath-link,/lib/$multiarch"
    # pkg-config (the crate and the tool) for the target's libraries only.
    export PKG_CONFIG_ALLOW_CROSS=1
    export "PKG_CONFIG_LIBDIR_${triple//-/_}=/usr/lib/$multiarch/pkgconfig:/usr/share/pkgconfig"
    export "PKG_CONFIG_SYSROOT_DIR_${triple//-/_}=/"
}
