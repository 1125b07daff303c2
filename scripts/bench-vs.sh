#!/usr/bin/env bash
# Paired benchmark: this checkout's `moirecast device` and `mold` against a
# baseline commit, built beside it in its own worktree and target dir, run
# alternately (A B A B …) so both see the same machine load; prints each
# side's median wall time and peak RSS (from /usr/bin/time -v) and the
# ratio this/base.
#
#   scripts/bench-vs.sh BASE_COMMIT [SPEC] [RUNS]   (defaults: molds/saddle-horse.toml, 7)
set -euo pipefail
base=${1:?usage: scripts/bench-vs.sh BASE_COMMIT [SPEC] [RUNS]}
spec=$(realpath "${2:-molds/saddle-horse.toml}")
runs=${3:-7}
root=$(git rev-parse --show-toplevel)
work=${BENCH_DIR:-$root/target/bench-vs}
mkdir -p "$work"

# build both (the baseline once per commit)
cargo build --release --quiet --manifest-path "$root/Cargo.toml"
this="$root/target/release/moirecast"
commit=$(git -C "$root" rev-parse --short "$base")
tree="$work/base-$commit"
[ -d "$tree" ] || git -C "$root" worktree add --detach "$tree" "$commit" >/dev/null
cargo build --release --quiet --manifest-path "$tree/Cargo.toml" --target-dir "$work/target-$commit"
that="$work/target-$commit/release/moirecast"

measure() { # BIN COMMAND OUT -> "seconds kilobytes"
    rm -rf "$3"
    /usr/bin/time -v "$1" "$2" "$spec" -o "$3" --quiet 2>"$3.time" >/dev/null
    awk -F': ' '/Elapsed \(wall clock\)/ {n = split($2, t, ":"); s = t[n] + (n > 1 ? 60 * t[n-1] : 0) + (n > 2 ? 3600 * t[n-2] : 0)}
                /Maximum resident set size/ {k = $2} END {print s, k}' "$3.time"
}
median() { sort -g | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}'; }

echo "spec $(basename "$spec"), $runs runs each, alternating; this = $(git -C "$root" rev-parse --short HEAD), base = $commit"
for command in device mold; do
    : >"$work/a.txt"; : >"$work/b.txt"
    measure "$this" "$command" "$work/out-a" >/dev/null  # warm the page cache
    for _ in $(seq "$runs"); do
        measure "$this" "$command" "$work/out-a" >>"$work/a.txt"
        measure "$that" "$command" "$work/out-b" >>"$work/b.txt"
    done
    ta=$(cut -d' ' -f1 "$work/a.txt" | median); tb=$(cut -d' ' -f1 "$work/b.txt" | median)
    ma=$(cut -d' ' -f2 "$work/a.txt" | median); mb=$(cut -d' ' -f2 "$work/b.txt" | median)
    awk -v c="$command" -v ta="$ta" -v tb="$tb" -v ma="$ma" -v mb="$mb" 'BEGIN {
        printf "%-6s this %.3f s %5.0f MB | base %.3f s %5.0f MB | time ratio %.2f, memory ratio %.2f\n",
               c, ta, ma / 1024, tb, mb / 1024, ta / tb, ma / mb }'
done
