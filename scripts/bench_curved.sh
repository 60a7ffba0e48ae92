#!/usr/bin/env bash
# Curved high-order rendering, speed against error: the curved scenes (nk-quartic, nk-sinc
# iso and volume, deal.II step-65 and MFEM escher from ../shared/data) rendered by a
# baseline revision and the current build alternately (medians and ratio); render time
# against the delivered error over accuracy.target_residual and accuracy.volume_tolerance;
# and VTK's contour of the nk-quartic Lagrange hexahedra (time, residual on the exact
# quartic) as a reference point. Writes a markdown report and a plot; not part of the tests.
# Installs the optional packages if missing (python3-vtk9, python3-matplotlib,
# python3-yaml), builds hpray in $HPRAY_BUILD if needed, and builds the baseline once in a
# git worktree, build-bench/baseline-<sha>, kept for later runs (remove it with
# `git worktree remove --force build-bench/baseline-<sha>`).
# Usage: scripts/bench_curved.sh [--size 512] [--runs 3] [--threads 2]
#          [--baseline REV|none (default HEAD~1)] [--out docs/benchmarks_curved.md]
#          [--png PATH (default: --out with .png)]
# A shared-data scene whose mesh is missing is skipped with a note in the report.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

baseline="HEAD~1"
args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --baseline) [ $# -ge 2 ] || { echo "bench_curved: --baseline needs a revision" >&2; exit 2; }
                baseline="$2"; shift 2 ;;
    --baseline=*) baseline="${1#*=}"; shift ;;
    -h|--help) sed -n '2,15p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) args+=("$1"); shift ;;
  esac
done
jobs="${JOBS:-$(nproc)}"

install_packages python3-vtk9 python3-matplotlib python3-yaml
if [ ! -d "$HPRAY_ROOT/../shared/data" ]; then
  echo "bench_curved: $(cd "$HPRAY_ROOT/.." && pwd)/shared/data is missing: the deal.II" \
       "and MFEM scenes will be skipped (noted in the report)" >&2
fi

step "building hpray in $HPRAY_BUILD"
if [ ! -f "$HPRAY_BUILD/build.ninja" ]; then
  cmake -S "$HPRAY_ROOT" -B "$HPRAY_BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release > /dev/null
fi
cmake --build "$HPRAY_BUILD" --target hpray -j "$jobs"

if [ "$baseline" != none ]; then
  build_baseline "$baseline"
  args+=(--baseline-bin "$BASELINE_BIN" --baseline-rev "$baseline" --baseline-sha "$BASELINE_SHA")
fi

step "rendering (baseline and current alternating), accuracy sweeps, VTK contour"
/usr/bin/python3 "$HPRAY_ROOT/scripts/bench_curved.py" --build "$HPRAY_BUILD" ${args[@]+"${args[@]}"}
