#!/usr/bin/env bash
# Installs what the ocm build and tests need on a fresh machine:
# the Cortex-M4F Rust target, clippy/rustfmt, QEMU for the emulated MCU, and a Python
# virtual environment (.venv) with the packages the interop tests check against.
# Idempotent and quiet when everything is already there.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v cargo >/dev/null 2>&1; then
    echo "setup: cargo not found; install Rust (rustup) first" >&2
    exit 1
fi

if command -v rustup >/dev/null 2>&1; then
    if ! rustup target list --installed 2>/dev/null | grep -qx thumbv7em-none-eabihf; then
        echo "setup: adding Rust target thumbv7em-none-eabihf"
        rustup target add thumbv7em-none-eabihf
    fi
    for c in clippy rustfmt; do
        if ! rustup component list --installed 2>/dev/null | grep -q "^$c"; then
            echo "setup: adding Rust component $c"
            rustup component add "$c"
        fi
    done
fi

if ! command -v qemu-system-arm >/dev/null 2>&1; then
    echo "setup: installing qemu-system-arm"
    SUDO=""
    if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1; then SUDO=sudo; fi
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq --no-install-recommends qemu-system-arm >/dev/null
fi

# Python packages of the interop tests (numpy opens our NPY files), in a virtual environment
# so the system's Python stays untouched.
if [ ! -x .venv/bin/python3 ] || ! cmp -s scripts/requirements-test.txt .venv/requirements-installed.txt; then
    if ! python3 -m venv .venv >/dev/null 2>&1; then
        echo "setup: python3 -m venv failed; installing python3-venv"
        SUDO=""
        if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1; then SUDO=sudo; fi
        export DEBIAN_FRONTEND=noninteractive
        $SUDO apt-get update -qq
        $SUDO apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
        python3 -m venv .venv
    fi
    echo "setup: installing Python test packages into .venv"
    .venv/bin/python3 -m pip install -q --disable-pip-version-check -r scripts/requirements-test.txt
    cp scripts/requirements-test.txt .venv/requirements-installed.txt
fi

# The Python binding of ocm-rl (Gymnasium environments, host/rl/py), built by maturin in the dev
# profile into .venv. It shares target/ with the workspace, so when nothing changed this is a
# no-op build and a reinstall of the same wheel; its output only shows when it fails.
rl_log=$(mktemp)
if ! VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" \
    .venv/bin/maturin develop --quiet -m host/rl/py/Cargo.toml >"$rl_log" 2>&1; then
    cat "$rl_log" >&2
    rm -f "$rl_log"
    echo "setup: building the Python binding of ocm-rl (host/rl/py) failed" >&2
    exit 1
fi
rm -f "$rl_log"
