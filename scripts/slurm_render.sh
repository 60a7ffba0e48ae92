#!/usr/bin/env bash
# Slurm job: partition a large mesh into bricks, then render a scene on every rank.
# Submit with, for example:
#   sbatch --nodes=4 --ntasks-per-node=8 --cpus-per-task=4 scripts/slurm_render.sh \
#          MESH.vtu SCENE.yaml OUT_DIR [BRICKS]
# BRICKS defaults to the number of ranks times 4 (more bricks than ranks lets the cost
# balance follow the data). Threads per rank follow --cpus-per-task.
#SBATCH --job-name=hpray
#SBATCH --output=hpray-%j.log
set -euo pipefail
MESH="$1"; SCENE="$2"; OUT="$3"
RANKS="${SLURM_NTASKS:?run under sbatch or srun}"
BRICKS="${4:-$((RANKS * 4))}"
THREADS="${SLURM_CPUS_PER_TASK:-1}"
HPRAY="${HPRAY:-$(dirname "$0")/../build/bin/hpray}"
mkdir -p "$OUT"
# One process partitions out of core (memory limit: a quarter of the node by default).
if [ ! -f "$OUT/bricks/manifest.json" ]; then
  srun --ntasks=1 --cpus-per-task="$THREADS" "$HPRAY" partition "$MESH" \
       --bricks "$BRICKS" --out "$OUT/bricks"
fi
export OMP_NUM_THREADS="$THREADS"
srun --cpu-bind=cores "$HPRAY" render "$SCENE" --set data.mesh="$OUT/bricks" \
     --set threads="$THREADS" --set output.exr="$OUT/frame.exr" \
     --set output.png="$OUT/frame.png" --set output.stats="$OUT/frame.json"
