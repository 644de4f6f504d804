#!/usr/bin/env bash
# Installs what the full test suite needs, idempotently: Debian packages listed in tests/deps/apt.txt, a Python venv
# (.venv) with tests/deps/requirements.txt, and cargo-fuzz. Safe to run again; does nothing when all is present.
set -euo pipefail
cd "$(dirname "$0")/.."

sudo_if_needed() {
    if [[ $(id -u) -eq 0 ]]; then "$@"; else sudo "$@"; fi
}

mapfile -t apt_pkgs < <(grep -hv '^\s*#' tests/deps/apt.txt | tr -s ' \t' '\n' | grep -v '^$' || true)
missing=()
for p in "${apt_pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]} > 0)); then
    echo "setup: installing Debian packages: ${missing[*]}"
    sudo_if_needed env DEBIAN_FRONTEND=noninteractive apt-get update -q
    sudo_if_needed env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

if [[ ! -x .venv/bin/python ]]; then
    echo "setup: creating .venv"
    python3 -m venv .venv
fi
stamp=.venv/.requirements.sha256
want=$(sha256sum tests/deps/requirements.txt | cut -d' ' -f1)
if [[ ! -f $stamp || $(cat "$stamp") != "$want" ]]; then
    echo "setup: installing Python peers into .venv"
    .venv/bin/python -m pip install -q --disable-pip-version-check -r tests/deps/requirements.txt
    echo "$want" >"$stamp"
fi

if ! command -v cargo-fuzz >/dev/null 2>&1 && [[ ! -x $HOME/.cargo/bin/cargo-fuzz ]]; then
    echo "setup: installing cargo-fuzz"
    # Pinned: the version the fuzz targets were written and run with; a newer one may need a newer rustc.
    cargo install --locked --version 0.13.2 cargo-fuzz
fi
echo "setup: ok"
