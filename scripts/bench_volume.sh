#!/usr/bin/env bash
# Benchmark of volume rendering: the 1.25M-tet t16 mesh of ../shared/data at 1024^2 (every
# segment in closed form) and nk-sinc (order-8 hexes, adaptive Gauss-Kronrod) at 512^2, each
# on 1 and 2 threads. Prints render/accel seconds, rays and segments per second and the
# volume error estimates from the stats JSON; the machine's load average is printed too,
# since on a shared machine wall-clock times are only as good as the load allows.
# Usage: scripts/bench_volume.sh [BUILD_DIR] [SCRATCH_DIR]
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$(cd "${1:-$ROOT/build}" && pwd)"
SCRATCH="${2:-${TMPDIR:-/tmp}/hpray_bench_volume}"
HPRAY="$BUILD/bin/hpray"
[ -x "$HPRAY" ] || { echo "no $HPRAY: build the hpray target first" >&2; exit 1; }
mkdir -p "$SCRATCH"
cd "$SCRATCH"

echo "host: $(nproc) cores; load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
printf '%-22s %7s %9s %9s %9s %12s %12s %11s %11s %6s\n' scene threads size accel_s \
  render_s rays_per_s segs_per_s rms_error max_error load

# run NAME CONFIG THREADS: one render, one result line.
run() {
  local name="$1" config="$2" threads="$3"
  local stats="$SCRATCH/$name-t$threads.json"
  "$HPRAY" -q render "$config" --set "threads=$threads" --set "output.stats=$stats" \
    --set "output.exr=$SCRATCH/$name-t$threads.exr" \
    --set "output.png=$SCRATCH/$name-t$threads.png"
  /usr/bin/python3 - "$name" "$threads" "$stats" "$(cut -d' ' -f1 /proc/loadavg)" <<'PY'
import json, sys
name, threads, path, load = sys.argv[1:]
s = json.load(open(path))
t = s["timing_s"]
print("%-22s %7s %9s %9.2f %9.2f %12.3g %12.3g %11.3g %11.3g %6s" % (
    name, threads, "%dx%d" % tuple(s["image"]), t["accel"], t["render"],
    s["rays"] / t["render"], s["segments"] / t["render"],
    s["volume"]["rms_error_estimate"], s["volume"]["max_error_estimate"], load))
PY
}

for threads in 1 2; do
  run t16_tets_1M "$ROOT/configs/volume_t16_tets_1M.yaml" "$threads"
done
for threads in 1 2; do
  run nk_sinc "$ROOT/configs/volume_nk_sinc.yaml" "$threads"
done
