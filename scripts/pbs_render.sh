#!/usr/bin/env bash
# PBS job: partition a large mesh into bricks, then render a scene on every rank.
# Submit with, for example:
#   qsub -l select=4:ncpus=32:mpiprocs=8 -v MESH=m.vtu,SCENE=s.yaml,OUT=run1 scripts/pbs_render.sh
# Threads per rank = ncpus / mpiprocs of the chunk (set THREADS to override).
#PBS -N hpray
#PBS -j oe
set -euo pipefail
cd "${PBS_O_WORKDIR:-.}"
: "${MESH:?pass -v MESH=...}" "${SCENE:?pass -v SCENE=...}" "${OUT:?pass -v OUT=...}"
RANKS=$(wc -l < "$PBS_NODEFILE")
NODES=$(sort -u "$PBS_NODEFILE" | wc -l)
CORES=$(nproc)
THREADS="${THREADS:-$(( CORES * NODES / RANKS > 0 ? CORES * NODES / RANKS : 1 ))}"
BRICKS="${BRICKS:-$((RANKS * 4))}"
HPRAY="${HPRAY:-$(dirname "$0")/../build/bin/hpray}"
mkdir -p "$OUT"
if [ ! -f "$OUT/bricks/manifest.json" ]; then
  "$HPRAY" partition "$MESH" --bricks "$BRICKS" --out "$OUT/bricks"
fi
mpirun -n "$RANKS" --hostfile "$PBS_NODEFILE" --bind-to none \
  "$HPRAY" render "$SCENE" --set data.mesh="$OUT/bricks" --set threads="$THREADS" \
  --set output.exr="$OUT/frame.exr" --set output.png="$OUT/frame.png" \
  --set output.stats="$OUT/frame.json"
