#!/usr/bin/env bash
# Compositor benchmark: composite time and bytes versus image size (512^2..4096^2) and P.
# Usage: scripts/bench_composite.sh [OUT.csv]   (env: RANKS="1 2 3 4 8", REPS=5,
#        HPRAY_BUILD=build dir). Builds bench_composite, runs it under mpiexec for each P
#        (oversubscribed beyond the core count) and writes one CSV with every row.
# A 4096^2 image of 11 double channels is 1.5 GB per rank, plus message buffers of up to
# as much again: 4096^2 runs only where P * 3.2 GB fits in the available memory, and the
# gather reference (3 full images on rank 0) only up to 2048^2 beyond P = 2.
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

OUT="${1:-$HPRAY_BUILD/bench_composite.csv}"
RANKS="${RANKS:-1 2 3 4 8}"
REPS="${REPS:-5}"

step "building bench_composite in $HPRAY_BUILD"
cmake -S "$HPRAY_ROOT" -B "$HPRAY_BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release > /dev/null
cmake --build "$HPRAY_BUILD" --target bench_composite -j 2
BENCH="$HPRAY_BUILD/benchmarks/bench_composite"

available_mb=$(awk '/MemAvailable/ {print int($2 / 1024)}' /proc/meminfo)
rm -f "$OUT"
for np in $RANKS; do
  sizes="512,1024,2048"
  if [ $((np * 3300)) -lt "$available_mb" ]; then sizes="$sizes,4096"; fi
  step "P = $np: sizes $sizes"
  tmp="$(mktemp)"
  mpiexec -n "$np" "$BENCH" --sizes 512,1024,2048 --reps "$REPS" > "$tmp"
  if [[ "$sizes" == *4096 ]]; then
    methods="swap,direct"
    if [ "$np" -le 2 ]; then methods="swap,direct,gather"; fi
    mpiexec -n "$np" "$BENCH" --sizes 4096 --reps "$REPS" --methods "$methods" \
      | tail -n +2 >> "$tmp"
  fi
  if [ ! -s "$OUT" ]; then head -1 "$tmp" > "$OUT"; fi
  tail -n +2 "$tmp" | tee -a "$OUT"
  rm -f "$tmp"
done
step "results in $OUT"
