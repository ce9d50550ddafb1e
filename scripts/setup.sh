#!/usr/bin/env bash
# Installs what the ocm build and tests need on a fresh machine:
# the Cortex-M4F Rust target, clippy/rustfmt, QEMU for the emulated MCU, a Python
# virtual environment (.venv) with the packages the interop tests check against, and the
# Python binding of ocm-rl built into it (skipped with --no-binding).
# Idempotent and quiet when everything is already there.
set -euo pipefail
cd "$(dirname "$0")/.."

binding=1
for arg in "$@"; do
    case "$arg" in
    --no-binding) binding=0 ;;
    *)
        echo "setup: unknown argument '$arg' (accepted: --no-binding)" >&2
        exit 2
        ;;
    esac
done

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
# profile into .venv. It shares target/ with the workspace, so after a workspace build it
# compiles only itself (scripts/test.sh builds the workspace first for that reason) and when
# nothing changed it is a reinstall of the same wheel; its output only shows when it fails.
if [ "$binding" = 0 ]; then
    exit 0
fi
rl_log=$(mktemp)
if ! VIRTUAL_ENV="$PWD/.venv" PATH="$PWD/.venv/bin:$PATH" \
    .venv/bin/maturin develop --quiet -m host/rl/py/Cargo.toml >"$rl_log" 2>&1; then
    cat "$rl_log" >&2
    rm -f "$rl_log"
    echo "setup: building the Python binding of ocm-rl (host/rl/py) failed" >&2
    exit 1
fi
rm -f "$rl_log"
