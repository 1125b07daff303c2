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
