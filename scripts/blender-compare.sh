#!/usr/bin/env bash
# Blender Cycles against `moirecast render` on the same device.stl, camera
# and light (issue 6's comparison; a benchmark, not a test: it needs
# Debian's blender, a 640 MB install, and the numpy its Python imports:
# apt-get install blender python3-numpy).
#
#   scripts/blender-compare.sh [SPEC [SIZE [TILT [CYCLES_SAMPLES [LIGHTS]]]]]
#
# LIGHTS: `white` (default: one white light from +x) or `default` (the
# amber and sky blue lights of `moirecast render`); colours are compared
# channel by channel.
#
# Both of our integrators: the path tracer (`--integrator path`, 4, 16 and
# 64 spp), whose time at Cycles' noise is fitted; and the default (the
# branching integrator through fixed lens phases), which has no noise, so
# Cycles' time to reach σ = 0.005 (the preview's noise bound: Cycles is
# rendered again at the samples its noise says that takes) is set against
# its time.
#
# Prints JSON: times, noise (σ of two seeds' difference / √2), the equal-noise
# time ratios, and the images' correlation (raw, and over one lens period).
set -euo pipefail
cd "$(dirname "$0")/.."
SPEC=${1:-molds/saddle-horse.toml}
SIZE=${2:-256}
TILT=${3:-0}
SAMPLES=${4:-128}
LIGHTS=${5:-white}
case "$LIGHTS" in
    white) COLOURS=("1,1,1" "0,0,0") ;;
    default) COLOURS=("1,0.6,0.15" "0.15,0.45,1") ;; # moirecast_render::frame::{AMBER, SKY_BLUE}
    *) echo "LIGHTS is white or default, not $LIGHTS" >&2; exit 1 ;;
esac
command -v blender >/dev/null || { echo "blender is not installed (apt-get install blender)" >&2; exit 1; }
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
cargo build --release -q
BIN=target/release/moirecast
"$BIN" device "$SPEC" -o "$OUT/device" -q
INDEX=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['design']['index'])" "$OUT/device/report.json")
for seed in 1 2; do
    for spp in 2 4 8; do
        "$BIN" render "$SPEC" -o "$OUT/ours-$spp-$seed" --size "$SIZE" --samples "$spp" --integrator path \
            --tilts="$TILT" --seed "$seed" --lights "$LIGHTS" -v 2> "$OUT/ours-$spp-$seed.log" >/dev/null
    done
    "$BIN" render "$SPEC" -o "$OUT/default-$seed" --size "$SIZE" \
        --tilts="$TILT" --seed "$seed" --lights "$LIGHTS" -v 2> "$OUT/default-$seed.log" >/dev/null
done
blender -b --factory-startup -noaudio -P scripts/blender/cycles.py -- \
    "$OUT" "$SIZE" "$TILT" "$INDEX" "$SAMPLES" "${COLOURS[@]}" 2>&1 | sed -n 's/^COMPARISON //p'
