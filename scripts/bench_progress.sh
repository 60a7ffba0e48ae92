#!/usr/bin/env bash
# What render progress costs. Renders one long scene alternately with progress on, stderr a
# pipe (a line every 5 s) and stderr a terminal (`script`: the one line rewritten twice a
# second), and with -q (no progress printed), RUNS times each, the order rotated every
# round; reports the median `timing_s.render` of each and the relative differences, the
# progress lines each frame printed (counted in its stderr) and the tiles it rendered
# (RenderTiles checks the clock after every tile, whatever the log level), and bounds the
# cost from the microbenchmark build/benchmarks/bench_progress (the per-tile check, and one
# line to a pipe and to a terminal):
#     bound = (tiles x check + lines x line) / (render seconds x threads).
# On a shared machine a difference below the spread of the -q runs is noise: then the
# bound is the answer. The load average is printed before and after.
#
#   scripts/bench_progress.sh [BUILD_DIR] [SCRATCH_DIR]
#   RUNS=5 SCENE=configs/nk_quartic.yaml SIZE=1280 THREADS=1 (defaults): a frame of about
#   9 s on one core, long enough for a line on a pipe and about ten on a terminal (the
#   first is due after 5 s); the whole run about 2.5 minutes.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$(cd "${1:-$ROOT/build}" && pwd)"
SCRATCH="${2:-${TMPDIR:-/tmp}/hpray_bench_progress}"
RUNS="${RUNS:-5}"
SCENE="${SCENE:-$ROOT/configs/nk_quartic.yaml}"
SIZE="${SIZE:-1280}"
THREADS="${THREADS:-1}"
HPRAY="$BUILD/bin/hpray"
BENCH="$BUILD/benchmarks/bench_progress"
for exe in "$HPRAY" "$BENCH"; do
  [ -x "$exe" ] || { echo "no $exe: build hpray and bench_progress first" >&2; exit 1; }
done
command -v script >/dev/null || { echo "needs script(1) (Debian: bsdutils)" >&2; exit 1; }
SCENE="$(cd "$(dirname "$SCENE")" && pwd)/$(basename "$SCENE")"
mkdir -p "$SCRATCH"
rm -f "$SCRATCH"/*.json "$SCRATCH"/*.log
cd "$SCRATCH"

echo "host: $(nproc) cores; load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "scene: $SCENE at ${SIZE}x${SIZE}, $THREADS thread(s), $RUNS runs of each mode"

# render MODE RUN: one frame; its stats in MODE_RUN.json, its stderr in MODE_RUN.log.
render() {
  local mode="$1" run="$2"
  local args=(render "$SCENE" --set "threads=$THREADS" --set "camera.width=$SIZE"
              --set "camera.height=$SIZE" --set "output.stats=$SCRATCH/${mode}_$run.json"
              --set output.exr=null --set output.png=null --set output.hits=null
              --set output.rgba=null)
  case "$mode" in
    pipe) "$HPRAY" "${args[@]}" 2>&1 | cat > "${mode}_$run.log" ;;
    quiet) "$HPRAY" -q "${args[@]}" 2>&1 | cat > "${mode}_$run.log" ;;
    terminal) script -qec "$(printf '%q ' "$HPRAY" "${args[@]}")" "${mode}_$run.log" \
                < /dev/null > /dev/null ;;
  esac
}

modes=(pipe terminal quiet)
for ((run = 0; run < RUNS; ++run)); do
  for ((k = 0; k < 3; ++k)); do
    mode="${modes[$(((run + k) % 3))]}"
    render "$mode" "$run"
    printf '  run %d %-8s render %s s\n' "$run" "$mode" \
      "$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["timing_s"]["render"])' "${mode}_$run.json")"
  done
done

# The microbenchmark, stderr a pipe and a terminal.
"$BENCH" --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
  --benchmark_out="$SCRATCH/micro_pipe.json" --benchmark_out_format=json 2>&1 >/dev/null | cat > /dev/null
script -qec "$(printf '%q ' "$BENCH" --benchmark_filter=BM_ProgressLine \
  --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
  --benchmark_out="$SCRATCH/micro_terminal.json" --benchmark_out_format=json)" /dev/null \
  < /dev/null > /dev/null
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"

/usr/bin/python3 - "$SCRATCH" "$RUNS" "$THREADS" <<'PY'
import json, os, statistics, sys
scratch, runs, threads = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
TILE = 16  # kRenderTile (src/render/brick_renderer.h)

def micro(name, bench):
    for b in json.load(open(os.path.join(scratch, name)))["benchmarks"]:
        if b["run_name"] == bench and b.get("aggregate_name") == "median":
            return b["real_time"] * {"ns": 1e-9, "us": 1e-6, "ms": 1e-3}[b["time_unit"]]
    raise SystemExit(f"no median of {bench} in {name}")

check = micro("micro_pipe.json", "BM_TileReportNoLineDue")
line = {"pipe": micro("micro_pipe.json", "BM_ProgressLine"),
        "terminal": micro("micro_terminal.json", "BM_ProgressLine"), "quiet": 0.0}
render, lines, tiles = {}, {}, None
for mode in ("pipe", "terminal", "quiet"):
    render[mode], lines[mode] = [], []
    for run in range(runs):
        stats = json.load(open(os.path.join(scratch, f"{mode}_{run}.json")))
        render[mode].append(stats["timing_s"]["render"])
        w, h = stats["image"]
        tiles = -(-w // TILE) * -(-h // TILE)
        text = open(os.path.join(scratch, f"{mode}_{run}.log"), "rb").read()
        lines[mode].append(text.count(b"] rendering "))
quiet = statistics.median(render["quiet"])
spread = (max(render["quiet"]) - min(render["quiet"])) / quiet
print()
print(f"per frame: {tiles} tiles (one clock check each, in every mode); "
      f"micro: check {check * 1e9:.1f} ns, line {line['pipe'] * 1e6:.2f} us on a pipe, "
      f"{line['terminal'] * 1e6:.2f} us on a terminal")
print(f"-q runs spread (max - min) / median: {100 * spread:.2f}%")
print(f"{'mode':9} {'median render s':>16} {'vs -q':>8} {'lines/frame':>12} {'bound':>9}")
for mode in ("pipe", "terminal", "quiet"):
    m = statistics.median(render[mode])
    n = statistics.median(lines[mode])
    bound = (tiles * check + n * line[mode]) / (m * threads)
    print(f"{mode:9} {m:16.3f} {100 * (m - quiet) / quiet:+7.2f}% {n:12g} {100 * bound:8.4f}%")
worst = max(abs(statistics.median(render[m]) - quiet) / quiet for m in ("pipe", "terminal"))
print("difference " + ("within" if worst <= spread else "beyond") +
      " the spread of the -q runs")
PY
