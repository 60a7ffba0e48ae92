#!/usr/bin/env bash
# Speed against error of the isosurface renderer, written as CSV and PNG plots:
#  (a) RMS and max residual versus projection order 2..25 for nk-sinc and nk-quartic
#      (Nelson & Kirby's Fig. 8), with roots taken from the projection (polish: false, as
#      they did) and polished on the true field (hpray's default);
#  (b) render time versus residual over accuracy settings (projection and root tolerances).
# Usage: scripts/bench_iso_accuracy.sh [OUT_DIR] [SIZE_SINC] [SIZE_QUARTIC]
# Defaults: out/bench_iso, 512 and 256 (the curved quartic costs about 16x more per ray).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
OUT="${1:-$HPRAY_ROOT/out/bench_iso}"
SIZE_SINC="${2:-512}"
SIZE_QUARTIC="${3:-256}"
HPRAY="$HPRAY_BUILD/bin/hpray"
[ -x "$HPRAY" ] || { install_packages; configure_and_build; }
mkdir -p "$OUT"

run() {  # run NAME SCENE SIZE extra --set args...
  local name="$1" scene="$2" size="$3"; shift 3
  "$HPRAY" render "$scene" -q --set camera.width="$size" --set camera.height="$size" \
    --set output.exr=null --set output.png=null --set output.stats="$OUT/$name.json" "$@"
}

step "(a) residual versus projection order"
echo "dataset,order,polish,hits,rms_residual_rel,max_residual_rel,render_s,root_failures" > "$OUT/order.csv"
for ds in sinc quartic; do
  if [ "$ds" = sinc ]; then scene="$HPRAY_ROOT/configs/quickstart.yaml"; size=$SIZE_SINC
  else scene="$HPRAY_ROOT/configs/nk_quartic.yaml"; size=$SIZE_QUARTIC; fi
  for order in $(seq 2 25); do
    for polish in false true; do
      run "order_${ds}_${order}_${polish}" "$scene" "$size" \
        --set accuracy.projection_order="$order" --set accuracy.polish="$polish"
      /usr/bin/python3 - "$OUT/order_${ds}_${order}_${polish}.json" "$ds" "$order" "$polish" >> "$OUT/order.csv" <<'PY'
import json, sys
j = json.load(open(sys.argv[1])); i = j["iso"]
print(f"{sys.argv[2]},{sys.argv[3]},{sys.argv[4]},{i['hits']:.0f},{i['rms_residual_relative']:.6e},"
      f"{i['max_residual_relative']:.6e},{j['timing_s']['render']:.4f},{i['root_failures']:.0f}")
PY
    done
    echo "  $ds order $order done"
  done
done

step "(b) render time versus residual over accuracy settings"
echo "dataset,projection_tolerance,root_tolerance,polish,hits,rms_residual_rel,max_residual_rel,render_s" > "$OUT/accuracy.csv"
for ds in sinc quartic; do
  if [ "$ds" = sinc ]; then scene="$HPRAY_ROOT/configs/quickstart.yaml"; size=$SIZE_SINC
  else scene="$HPRAY_ROOT/configs/nk_quartic.yaml"; size=$SIZE_QUARTIC; fi
  for ptol in 1e-4 1e-6 1e-8 1e-10 1e-12 1e-14; do
    for rtol in 1e-6 1e-10 1e-14; do
      for polish in false true; do
        name="acc_${ds}_${ptol}_${rtol}_${polish}"
        run "$name" "$scene" "$size" --set accuracy.projection_tolerance="$ptol" \
          --set accuracy.root_tolerance="$rtol" --set accuracy.polish="$polish"
        /usr/bin/python3 - "$OUT/$name.json" "$ds" "$ptol" "$rtol" "$polish" >> "$OUT/accuracy.csv" <<'PY'
import json, sys
j = json.load(open(sys.argv[1])); i = j["iso"]
print(f"{sys.argv[2]},{sys.argv[3]},{sys.argv[4]},{sys.argv[5]},{i['hits']:.0f},"
      f"{i['rms_residual_relative']:.6e},{i['max_residual_relative']:.6e},{j['timing_s']['render']:.4f}")
PY
      done
    done
  done
done

step "plots"
/usr/bin/python3 "$HPRAY_ROOT/scripts/plot_iso_accuracy.py" "$OUT" || \
  echo "(plots skipped: /usr/bin/python3 needs matplotlib: apt-get install python3-matplotlib)"
step "CSV in $OUT/order.csv and $OUT/accuracy.csv"
