#!/usr/bin/env bash
# hpray against VTK's three unstructured-grid volume mappers (ray cast with the exact linear
# integrator, ray cast with pre-integration, projected tetrahedra) on the same data, camera
# and transfer functions: t16 (1.25M tets, 1024^2) and the mixed Fichera mesh (512^2) of
# ../shared/data. Installs the optional peers from Debian's archive if missing
# (python3-vtk9, xvfb, python3-matplotlib; never needed by the build or the tests), builds
# hpray if needed, and rewrites the peers section of docs/benchmarks.md and
# docs/benchmarks_peers.png.
# With --baseline REV, hpray at revision REV (built once in a git worktree under
# build-bench/, see build_baseline in scripts/common.sh) is timed in the same rounds too,
# for the speedup of the current build over it.
# Usage: scripts/bench_peers.sh [--runs 3] [--size N] [--threads T] [--baseline REV]
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --baseline) [ $# -ge 2 ] || { echo "bench_peers: --baseline needs a revision" >&2; exit 2; }
                build_baseline "$2"
                args+=(--baseline-bin "$BASELINE_BIN" --baseline-rev "$2"); shift 2 ;;
    *) args+=("$1"); shift ;;
  esac
done
install_packages python3-vtk9 xvfb xauth python3-matplotlib python3-yaml
[ -x "$HPRAY_BUILD/bin/hpray" ] || configure_and_build
step "rendering with hpray and VTK, alternating"
xvfb-run -a /usr/bin/python3 "$HPRAY_ROOT/scripts/bench_peers.py" --build "$HPRAY_BUILD" \
  ${args[@]+"${args[@]}"}
