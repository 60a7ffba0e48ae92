#!/usr/bin/env bash
# Speed against accuracy of the volume integrator: renders configs/volume_nk_sinc.yaml at
# SIZE^2 on THREADS threads for volume_tolerance 1e-4, 1e-6, 1e-8 and 1e-10 (the median
# render time of RUNS runs each, the runs of the tolerances interleaved) and a reference at
# 1e-12, then tabulates per tolerance: render time, quadrature nodes, the true error (max and
# RMS over the pixels the volume touches, against the reference) and the claimed error
# vol.error (max and median over those pixels), with how often the claim is below the true
# error (it should never be) and how often it is above 100x max(true, 1e-14).
# Usage: scripts/bench_volume_accuracy.sh OUT.md [SIZE] [RUNS] [THREADS]
# Defaults: 512, 3, 2. Work files go to out/bench_volume_accuracy/.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"
[ $# -ge 1 ] || { echo "usage: $0 OUT.md [SIZE] [RUNS] [THREADS]" >&2; exit 2; }
TABLE="$1"
SIZE="${2:-512}"
RUNS="${3:-3}"
THREADS="${4:-2}"
HPRAY="$HPRAY_BUILD/bin/hpray"
[ -x "$HPRAY" ] || { install_packages; configure_and_build; }
SCENE="$HPRAY_ROOT/configs/volume_nk_sinc.yaml"
WORK="$HPRAY_ROOT/out/bench_volume_accuracy"
mkdir -p "$WORK"
TOLERANCES=(1e-4 1e-6 1e-8 1e-10)

run() {  # run NAME TOLERANCE: the pixels (rgba .npy), vol.error (errors .npy) and stats
  "$HPRAY" render "$SCENE" -q --set camera.width="$SIZE" --set camera.height="$SIZE" \
    --set threads="$THREADS" --set accuracy.volume_tolerance="$2" \
    --set output.exr=null --set output.png=null --set output.stats="$WORK/$1.json" \
    --set output.rgba="$WORK/$1.rgba.npy" --set output.errors="$WORK/$1.errors.npy"
}

step "reference: volume_tolerance 1e-12 at ${SIZE}^2"
run reference 1e-12
for r in $(seq "$RUNS"); do
  for tol in "${TOLERANCES[@]}"; do
    step "volume_tolerance $tol, run $r of $RUNS"
    run "tol_${tol}_run${r}" "$tol"
  done
done

step "table"
/usr/bin/python3 - "$WORK" "$TABLE" "$SIZE" "$RUNS" "$THREADS" "${TOLERANCES[@]}" <<'PY'
import json, sys
import numpy as np

work, table, size, runs, threads = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5]
tolerances = sys.argv[6:]
ref = np.load(f"{work}/reference.rgba.npy")
ref_stats = json.load(open(f"{work}/reference.json"))
rows = []
for tol in tolerances:
    times, nodes = [], None
    for r in range(1, runs + 1):
        stats = json.load(open(f"{work}/tol_{tol}_run{r}.json"))
        times.append(stats["timing_s"]["render"])
        nodes = stats["volume"]["quadrature_nodes"]
    # Pixels and claims of the last run (every run computes the same image).
    rgba = np.load(f"{work}/tol_{tol}_run{runs}.rgba.npy")
    claim = np.load(f"{work}/tol_{tol}_run{runs}.errors.npy")[..., 1].astype(np.float64)
    touched = claim > 0
    true = np.abs(rgba[..., :3] - ref[..., :3]).max(axis=-1)[touched]
    claimed = claim[touched]
    ratio = claimed / np.maximum(true, 1e-14)
    rows.append((tol, float(np.median(times)), nodes, true.max(), np.sqrt(np.mean(true**2)),
                 claimed.max(), float(np.median(claimed)), int(np.sum(claimed < true)),
                 float(np.mean(ratio > 100)), int(touched.sum())))

lines = [
    f"configs/volume_nk_sinc.yaml at {size}^2 on {threads} threads: render time the median of "
    f"{runs} runs; errors over the pixels the volume touches, the truth a render at "
    f"volume_tolerance 1e-12 (its own claimed max {ref_stats['volume']['max_error_estimate']:.2g}).",
    "",
    "| volume_tolerance | render s | quadrature nodes | true max | true RMS | claimed max "
    "| claimed median | claim < true | claim > 100x | pixels |",
    "|---|---|---|---|---|---|---|---|---|---|",
]
for (tol, t, nodes, tmax, trms, cmax, cmed, under, over, pixels) in rows:
    lines.append(f"| {tol} | {t:.3f} | {nodes:.3g} | {tmax:.2e} | {trms:.2e} | {cmax:.2e} "
                 f"| {cmed:.2e} | {under} | {100 * over:.2f}% | {pixels} |")
text = "\n".join(lines) + "\n"
open(table, "w").write(text)
print(text)
PY
step "table written to $TABLE"
