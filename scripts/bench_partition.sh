#!/usr/bin/env bash
# Benchmark of `hpray partition`: cells per second, peak RSS and bytes written, for the
# largest mesh in ../shared/data and for a generated mesh of 11M tets (builtin:cube-tets-130,
# written to an appended .vtu first, since only files can be streamed), the last run at a
# memory limit of a quarter of that file's size.
# Usage: scripts/bench_partition.sh [BUILD_DIR] [SCRATCH_DIR]
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${1:-$ROOT/build}"
SCRATCH="${2:-${TMPDIR:-/tmp}/hpray_bench_partition}"
HPRAY="$BUILD/bin/hpray"
DATA="$ROOT/../shared/data"
[ -x "$HPRAY" ] || { echo "no $HPRAY: build the hpray target first" >&2; exit 1; }
[ -x /usr/bin/time ] || { echo "needs /usr/bin/time (Debian package 'time')" >&2; exit 1; }
mkdir -p "$SCRATCH"

# run NAME INPUT BRICKS LIMIT: one partition, one result line.
run() {
  local name="$1" input="$2" bricks="$3" limit="$4"
  local out="$SCRATCH/$name" log="$SCRATCH/$name.time"
  rm -rf "$out"
  /usr/bin/time -f '%e %M' -o "$log" "$HPRAY" -q partition "$input" --bricks "$bricks" \
    --out "$out" --memory-limit "$limit"
  read -r seconds rss_kib < "$log"
  local summary
  summary="$("$HPRAY" -q info --json "$out")"
  /usr/bin/python3 - "$name" "$bricks" "$limit" "$seconds" "$rss_kib" "$summary" <<'PY'
import json, sys
name, bricks, limit, seconds, rss, summary = sys.argv[1:]
s = json.loads(summary)
owned, seconds = s["owned_cells"], float(seconds)
print(f"{name:28s} bricks {int(bricks):3d}  limit {limit:>5s}  cells {owned:>10,d}  "
      f"{seconds:7.2f} s  {owned / seconds / 1e6:6.2f} Mcells/s  peak RSS "
      f"{int(rss) / 1024:7.1f} MiB  written {s['bytes'] / 2**20:8.1f} MiB  "
      f"ghosts {100 * s['ghost_fraction']:5.2f}%  balance {s['balance']:.4f}")
PY
}

echo "== largest shared mesh (1.25M linear tets, zlib Float32/Int32 input)"
run t16_16 "$DATA/mfem_gmsh_t16_tets_1M.vtu" 16 256M
run t16_64 "$DATA/mfem_gmsh_t16_tets_1M.vtu" 64 64M

echo "== generated: builtin:cube-tets-130 (10,985,000 tets) as an appended raw .vtu"
BIG="$SCRATCH/cube130"
if [ ! -f "$BIG/brick-0000.vtu" ]; then
  # One brick = the whole mesh written by the project's writer (generated in memory).
  "$HPRAY" -q partition builtin:cube-tets-130 --bricks 1 --out "$BIG" --memory-limit 8G
fi
ls -l "$BIG/brick-0000.vtu"
run cube130_16 "$BIG/brick-0000.vtu" 16 1G
run cube130_64 "$BIG/brick-0000.vtu" 64 256M
# A limit of a quarter of the input file (509 MiB) or less: out of core for real.
run cube130_32 "$BIG/brick-0000.vtu" 32 128M
