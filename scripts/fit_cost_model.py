#!/usr/bin/env python3
"""Fits the partitioner's cost model (partition/cost_model.h) to the measurements of
benchmarks/calibrate_cost (a CSV, see scripts/calibrate_cost.sh).

Per shape and affine/curved class:
  seconds per segment = a + b * nodes * (line degree + 1)
  setup seconds per cell = c + d * nodes        (single-class data sets only)
by least squares on relative errors, with non-negative coefficients. A class measured at
one size only keeps the tet's constant term of its kind and fits the slope; a class not
measured at all borrows another's coefficients (printed). Prints the predicted/measured
ratio of every row, and with --write replaces the tables in cost_model.h.

Usage: fit_cost_model.py CALIBRATION.csv [--write partition/cost_model.h]
"""
import csv
import re
import sys

import numpy as np

SHAPES = ["tet", "hex", "wedge", "pyramid"]


def nodes(shape, order, family):
    p = order
    if family == "serendipity":
        return {"hex": 20, "wedge": 15, "pyramid": 13, "tet": 10}[shape]
    return {
        "tet": (p + 1) * (p + 2) * (p + 3) // 6,
        "hex": (p + 1) ** 3,
        "wedge": (p + 1) ** 2 * (p + 2) // 2,
        "pyramid": (p + 1) * (p + 2) * (2 * p + 3) // 6,
    }[shape]


def line_degree(shape, order, family):
    if family == "serendipity":
        return 4 if shape == "hex" else 3
    return {"tet": order, "hex": 3 * order, "wedge": 2 * order, "pyramid": 2 * order}[shape]


def fit_line(x, y, fixed_a=None):
    """a + b x ~ y, minimising relative errors, a, b >= 0."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    w = 1.0 / y
    if fixed_a is not None or len(set(x)) < 2:
        a = fixed_a if fixed_a is not None else 0.0
        b = max(0.0, float(np.sum(w * w * x * (y - a)) / np.sum(w * w * x * x)))
        return a, b
    A = np.stack([w, w * x], axis=1)
    (a, b), *_ = np.linalg.lstsq(A, np.ones_like(y), rcond=None)
    if a < 0:
        return fit_line(x, y, fixed_a=0.0)
    if b < 0:
        return float(np.sum(w * w * y) / np.sum(w * w)), 0.0
    return float(a), float(b)


def main():
    rows = list(csv.DictReader(open(sys.argv[1])))
    out = sys.argv[sys.argv.index("--write") + 1] if "--write" in sys.argv else None
    for r in rows:
        r["order"] = int(r["order"])
        r["curved"] = int(r["curved"])
        r["n"] = nodes(r["shape"], r["order"], r["family"])
        r["work"] = r["n"] * (line_degree(r["shape"], r["order"], r["family"]) + 1)
        r["segments"] = float(r["segments"])
        r["seg_s"] = float(r["render_s_per_segment"])
        r["setup_s"] = float(r["setup_s_per_cell"])
    # Enough segments for a stable time per segment.
    seg_rows = [r for r in rows if r["segments"] >= 500 and r["seg_s"] > 0]
    coeffs, notes = {}, {}
    for curved in (0, 1):
        for shape in SHAPES:
            g = [r for r in seg_rows if r["shape"] == shape and r["curved"] == curved]
            if not g:
                continue
            fixed = None
            if len({r["work"] for r in g}) < 2 and (("tet", curved) in coeffs):
                fixed = coeffs[("tet", curved)][0]
            a, b = fit_line([r["work"] for r in g], [r["seg_s"] for r in g], fixed)
            s = [r for r in rows if r["shape"] == shape and r["curved"] == curved
                 and r["classes"] == "1"]
            if s:
                c, d = fit_line([r["n"] for r in s], [r["setup_s"] for r in s])
            else:
                c, d = None, None
            coeffs[(shape, curved)] = [a, b, c, d]
            notes[(shape, curved)] = f"{len(g)} rows"
    # Setup without single-class data: the tet's of the same kind, else the other kind's.
    for key, k in coeffs.items():
        if k[2] is None:
            src = ("tet", key[1]) if coeffs.get(("tet", key[1]), [0, 0, None])[2] is not None \
                else ("tet", 1 - key[1])
            k[2], k[3] = coeffs[src][2], coeffs[src][3]
            notes[key] += f", setup of {src[0]} {'curved' if src[1] else 'affine'}"
    for curved in (0, 1):
        for shape in SHAPES:
            if (shape, curved) not in coeffs:
                src = (shape, 1 - curved) if (shape, 1 - curved) in coeffs else ("hex", curved)
                coeffs[(shape, curved)] = list(coeffs[src])
                notes[(shape, curved)] = f"not measured: {src[0]} " \
                                         f"{'curved' if src[1] else 'affine'}"
    print(f"{'data':22} {'class':22} {'segments':>9} {'measured':>10} {'model':>10} "
          f"{'ratio':>6}")
    worst = 1.0
    for r in rows:
        a, b, c, d = coeffs[(r["shape"], r["curved"])]
        model = a + b * r["work"]
        ratio = model / r["seg_s"] if r["seg_s"] > 0 else float("nan")
        if r["segments"] >= 500:
            worst = max(worst, ratio, 1 / ratio)
        kind = "curved" if r["curved"] else "affine"
        print(f"{r['data']:22} {r['shape'] + str(r['order']) + ' ' + kind:22} "
              f"{int(r['segments']):9d} {r['seg_s']:10.3g} {model:10.3g} {ratio:6.2f}")
    print(f"worst model/measured ratio (rows with >= 500 segments): {worst:.2f}")

    def table(curved):
        lines = []
        for shape in SHAPES:
            a, b, c, d = coeffs[(shape, curved)]
            lines.append(f"    {{{a:.3e}, {b:.3e}, {c:.3e}, {d:.3e}}},  // "
                         f"{shape.capitalize()}: {notes[(shape, curved)]}")
        return "\n".join(lines)

    for curved in (0, 1):
        print(("curved" if curved else "affine") + ":\n" + table(curved))
    if out:
        text = open(out).read()
        for curved, tag in ((0, "AFFINE"), (1, "CURVED")):
            text = re.sub(
                rf"(// FIT-{tag}-BEGIN\n).*?(\n\s*// FIT-{tag}-END)",
                lambda m: m.group(1) + table(curved) + m.group(2), text, flags=re.S)
        open(out, "w").write(text)
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
