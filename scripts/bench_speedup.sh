#!/usr/bin/env bash
# Rank speedup: the same scene on 1 rank and on P ranks (one thread per rank, so P ranks
# use P cores), alternated REPS times so that drifts of a shared machine hit both alike.
# Usage: scripts/bench_speedup.sh [OUT.csv]   (env: RANKS="2", REPS=5, SIZES="512 1024",
#        SCENES="name=config[;key=value;...] ...", HPRAY_BUILD=build dir).
# Prints per scene, size and P the median total and render times and the speedup of the
# medians, with the stats' wait (time the faster ranks wait for the slowest: imbalance)
# and prepass (the cost-measuring pre-pass of an in-memory split in space).
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

OUT="${1:-$HPRAY_BUILD/bench_speedup.csv}"
RANKS="${RANKS:-2}"
REPS="${REPS:-5}"
SIZES="${SIZES:-512 1024}"
# name=config[;key=value overrides]: an opaque isosurface (early ray termination), the same
# isosurface half transparent (every segment behind it is searched too), and a volume;
# each split between ranks by image tiles (distribute: image, the default for a mesh) and
# in space (distribute: space: k-d boxes and the binary swap, as for a partition).
SCENES="${SCENES:-iso=configs/quickstart.yaml \
iso_space=configs/quickstart.yaml;distribute=space \
iso_transparent=configs/quickstart.yaml;isosurfaces.0.opacity=0.5 \
iso_transparent_space=configs/quickstart.yaml;isosurfaces.0.opacity=0.5;distribute=space \
volume=configs/volume_nk_sinc.yaml \
volume_space=configs/volume_nk_sinc.yaml;distribute=space}"

step "building hpray in $HPRAY_BUILD"
cmake -S "$HPRAY_ROOT" -B "$HPRAY_BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release > /dev/null
cmake --build "$HPRAY_BUILD" --target hpray -j 2
HPRAY="$HPRAY_BUILD/bin/hpray"

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
echo "scene,size,ranks,rep,total_s,render_s,render_min_s,wait_s,prepass_s,composite_s" > "$OUT"
run() {  # run NAME CONFIG SIZE P REP EXTRA...
  local name="$1" config="$2" size="$3" np="$4" rep="$5"
  shift 5
  local stats="$scratch/stats.json"
  rm -f "$stats"
  mpiexec -n "$np" "$HPRAY" render "$HPRAY_ROOT/$config" --set threads=1 \
    --set camera.width="$size" --set camera.height="$size" --set output.exr=null \
    --set output.png=null --set output.stats="$stats" "$@" > /dev/null
  python3 - "$stats" "$name" "$size" "$np" "$rep" >> "$OUT" <<'EOF'
import json, sys
path, name, size, np, rep = sys.argv[1:]
t = json.load(open(path))["timing_s"]
print(f"{name},{size},{np},{rep},{t['total']:.4f},{t['render']:.4f},"
      f"{t.get('render_min', t['render']):.4f},{t.get('wait', 0):.4f},"
      f"{t.get('prepass', 0):.4f},{t['composite']:.4f}")
EOF
}
for entry in $SCENES; do
  name="${entry%%=*}"
  rest="${entry#*=}"
  config="${rest%%;*}"
  extra=()
  if [[ "$rest" == *";"* ]]; then
    IFS=';' read -r -a sets <<< "${rest#*;}"
    for kv in "${sets[@]}"; do extra+=(--set "$kv"); done
  fi
  for size in $SIZES; do
    step "$name at ${size}^2"
    for rep in $(seq "$REPS"); do
      run "$name" "$config" "$size" 1 "$rep" "${extra[@]}"
      for np in $RANKS; do run "$name" "$config" "$size" "$np" "$rep" "${extra[@]}"; done
    done
  done
done
python3 - "$OUT" <<'EOF'
import csv, statistics, sys
rows = list(csv.DictReader(open(sys.argv[1])))
groups = {}
for r in rows:
    groups.setdefault((r["scene"], int(r["size"]), int(r["ranks"])), []).append(r)
med = lambda rs, k: statistics.median(float(r[k]) for r in rs)
print(f"{'scene':16} {'size':>5} {'P':>3} {'total':>8} {'render':>8} {'wait':>7} "
      f"{'prepass':>7} {'speedup':>8} {'(render)':>8}")
for (scene, size, np), rs in sorted(groups.items()):
    one = groups[(scene, size, 1)]
    print(f"{scene:16} {size:5} {np:3} {med(rs, 'total_s'):8.3f} {med(rs, 'render_s'):8.3f} "
          f"{med(rs, 'wait_s'):7.3f} {med(rs, 'prepass_s'):7.3f} "
          f"{med(one, 'total_s') / med(rs, 'total_s'):8.2f} "
          f"{med(one, 'render_s') / med(rs, 'render_s'):8.2f}")
EOF
step "results in $OUT"
