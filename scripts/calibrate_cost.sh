#!/usr/bin/env bash
# Calibrates the partitioner's cost model against the renderer (partition/cost_model.h
# explains the model): builds and runs benchmarks/calibrate_cost on one thread over the
# built-in and shared data sets, writes the measurements to partition/cost_calibration.csv
# and fits the coefficients into partition/cost_model.h (review the diff, rebuild, run the
# tests). Usage: scripts/calibrate_cost.sh [--size N] [--reps R]  (defaults 160, 3; about
# five minutes on an idle 2-core machine). Run it on an otherwise idle machine.
source "$(dirname "${BASH_SOURCE[0]}")/common.sh"

step "building calibrate_cost in $HPRAY_BUILD"
cmake -S "$HPRAY_ROOT" -B "$HPRAY_BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release > /dev/null
cmake --build "$HPRAY_BUILD" --target calibrate_cost -j 2
step "measuring (one thread)"
"$HPRAY_BUILD/benchmarks/calibrate_cost" "$@" > "$HPRAY_ROOT/partition/cost_calibration.csv"
step "fitting"
/usr/bin/python3 "$HPRAY_ROOT/scripts/fit_cost_model.py" \
  "$HPRAY_ROOT/partition/cost_calibration.csv" --write "$HPRAY_ROOT/partition/cost_model.h"
