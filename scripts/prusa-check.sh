#!/usr/bin/env bash
# Reads each STEP file of a run folder with PrusaSlicer (Debian's
# `prusa-slicer`, which meshes STEP with OpenCascade 7.6: a second reader
# beside the test suite's cadquery-ocp) and prints what it reports:
# manifold, open edges, parts, volume. Not part of the test command
# (PrusaSlicer is a 200 MB install); install it with
#   apt-get install prusa-slicer
#
#   scripts/prusa-check.sh OUT_DIR     (a `moirecast device` or `mold` folder)
set -euo pipefail
dir=${1:?usage: scripts/prusa-check.sh OUT_DIR}
command -v prusa-slicer >/dev/null || { echo "prusa-slicer is not installed: apt-get install prusa-slicer" >&2; exit 2; }
shopt -s nullglob
steps=("$dir"/*.step)
[ ${#steps[@]} -gt 0 ] || { echo "no .step file in $dir" >&2; exit 2; }
status=0
for step in "${steps[@]}"; do
    info=$(prusa-slicer --info "$step" 2>/dev/null | grep -E '^(manifold|open_edges|number_of_parts|volume) =' | tr -s ' ' | paste -sd ';' -)
    echo "$(basename "$step"): $info"
    case $info in *"manifold = yes"*) ;; *) status=1 ;; esac
done
exit $status
