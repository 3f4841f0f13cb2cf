#!/usr/bin/env bash
# The full benchmark on a machine with many cores: scene groups run side by side, each
# pinned to its own pair of cores (so every timing is a 2-core timing), then merged into one
# report. Usage: benchmarks/run_parallel.sh OUTPUT.md [fourd bench options...]
# FOURD (default: `python3 -m fourd`) runs fourd; needs 2 cores per group (8 groups: 16 cores).
set -uo pipefail
output=${1:?usage: run_parallel.sh OUTPUT.md [bench options]}
shift
fourd=${FOURD:-python3 -m fourd}
work=$(mktemp -d)
groups=(
  "elephant-gallop" "horse-gallop" "crane" "dfaust-hopping" "rigid-turn"
  "splitting-blob" "squash-ball touching-spheres" "bending-arm waving-sheet"
)
cores=$(nproc)
slot=0
for group in "${groups[@]}"; do
  first=$(( (2 * slot) % cores )); second=$(( (2 * slot + 1) % cores ))
  (
    for scene in $group; do
      taskset -c "$first,$second" $fourd bench --quiet --scenes "$scene" -o "$work/$scene/r.md" "$@" \
        >"$work/$scene.log" 2>&1 || echo "bench of $scene failed: see $work/$scene.log" >&2
    done
  ) &
  slot=$((slot + 1))
done
wait
$fourd bench --merge "$work"/*/r.json -o "$output"
echo "logs in $work" >&2
