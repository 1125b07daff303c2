#!/usr/bin/env bash
# Blender Cycles against `moirecast render` on the same device.stl, camera
# and light (issue 6's comparison; a benchmark, not a test: it needs
# Debian's blender, a 640 MB install: apt-get install blender).
#
#   scripts/blender-compare.sh [SPEC [SIZE [TILT [CYCLES_SAMPLES]]]]
#
# Prints JSON: times, noise (σ of two seeds' difference / √2), our samples
# and time at Cycles' noise, their ratio, and the images' correlation (raw,
# and over one lens period).
set -euo pipefail
cd "$(dirname "$0")/.."
SPEC=${1:-molds/saddle-horse.toml}
SIZE=${2:-256}
TILT=${3:-0}
SAMPLES=${4:-128}
command -v blender >/dev/null || { echo "blender is not installed (apt-get install blender)" >&2; exit 1; }
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
cargo build --release -q
BIN=target/release/moirecast
"$BIN" device "$SPEC" -o "$OUT/device" -q
INDEX=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['design']['index'])" "$OUT/device/report.json")
for spp in 2 4 8; do
    for seed in 1 2; do
        "$BIN" render "$SPEC" -o "$OUT/ours-$spp-$seed" --size "$SIZE" --samples "$spp" \
            --tilts="$TILT" --seed "$seed" --lights white -v 2> "$OUT/ours-$spp-$seed.log" >/dev/null
    done
done
blender -b --factory-startup -noaudio -P scripts/blender/cycles.py -- \
    "$OUT" "$SIZE" "$TILT" "$INDEX" "$SAMPLES" 2>&1 | sed -n 's/^COMPARISON //p'
