#!/usr/bin/python3
"""Curved high-order rendering, speed against error (run by scripts/bench_curved.sh, which
installs the optional packages and builds the binaries).

Three parts, all at one image size and thread count:
  1. before/after: each scene rendered RUNS times by a baseline binary and by the current
     one, alternately (so that drifts of a shared machine hit both alike); medians of
     timing_s.render and of the process wall time, and their ratio;
  2. speed against error: accuracy.target_residual over 1e-4 .. 1e-12 and the default (no
     target) on nk-quartic and deal.II step-65, accuracy.volume_tolerance over 1e-4 ..
     1e-10 on the nk-sinc volume; render time and the stats' max and RMS error;
  3. VTK's contour of the same nk-quartic mesh (8 order-8 Lagrange hexahedra, written to a
     .vtu here) with vtkContourFilter, timed, and its points' residual on the exact quartic.
Writes a markdown report (--out) and a plot (--png).
"""
import argparse
import json
import math
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# name, config, kind (iso: residual relative to the field's range; volume: the stats'
# absolute RGB error estimate)
SCENES = [
    ("nk-quartic", "configs/nk_quartic.yaml", "iso"),
    ("nk-sinc", "configs/quickstart.yaml", "iso"),
    ("nk-sinc volume", "configs/volume_nk_sinc.yaml", "volume"),
    ("deal.II step-65", "configs/dealii_step65.yaml", "iso"),
    ("MFEM escher", "configs/mfem_escher.yaml", "iso"),
]
DESCRIPTION = {
    "nk-quartic": "8 curved order-8 hexes (builtin), 1 opaque isosurface",
    "nk-sinc": "125 order-8 hexes (builtin), 1 opaque isosurface",
    "nk-sinc volume": "125 order-8 hexes (builtin), volume at volume_tolerance 1e-8",
    "deal.II step-65": "curved Q3 hexes (shared data), 2 isosurfaces, one at opacity 0.4",
    "MFEM escher": "curved P3 tets (shared data), 2 isosurfaces, one at opacity 0.5",
}
TARGETS = [None, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12]       # accuracy.target_residual
VOLUME_TOLERANCES = [1e-4, 1e-6, 1e-8, 1e-10]           # accuracy.volume_tolerance
SWEEPS = [("nk-quartic", "target_residual", TARGETS),
          ("deal.II step-65", "target_residual", TARGETS),
          ("nk-sinc volume", "volume_tolerance", VOLUME_TOLERANCES)]

# Nelson & Kirby's quartic and the isovalue of configs/nk_quartic.yaml.
QUARTIC_ISO = -0.00716511
QUARTIC_RANGE = (-0.02109863099951987, 0.06075)  # its range over the mesh's nodes


def scene_mesh(config):
    """The data.mesh of a config, as a path when it is a file (None for a builtin)."""
    import yaml  # python3-yaml
    with open(os.path.join(ROOT, config)) as f:
        mesh = yaml.safe_load(f)["data"]["mesh"]
    if mesh.startswith("builtin:"):
        return None
    return os.path.normpath(os.path.join(ROOT, os.path.dirname(config), mesh))


def run_hpray(binary, config, sets, size, threads, tmp, rgba=None):
    """One `hpray render`: process wall, timing_s.render and the error figures (and the
    stats as "_stats"), or {"failed": message} when the binary rejects the scene."""
    stats = os.path.join(tmp, "stats.json")
    if os.path.exists(stats):
        os.remove(stats)
    cmd = [binary, "render", os.path.join(ROOT, config), "-q", "--set", f"threads={threads}",
           "--set", f"camera.width={size}", "--set", f"camera.height={size}",
           "--set", "output.exr=null", "--set", "output.png=null",
           "--set", f"output.stats={stats}"]
    if rgba:
        cmd += ["--set", f"output.rgba={rgba}"]
    for kv in sets:
        cmd += ["--set", kv]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if p.returncode != 0:
        return {"failed": (p.stderr.strip().splitlines() or ["exit %d" % p.returncode])[-1]}
    with open(stats) as f:
        s = json.load(f)
    iso, vol = s.get("iso", {}), s.get("volume", {})
    return {"wall": wall, "cpu": cpu, "render": s["timing_s"]["render"],
            "iso_max": iso.get("max_residual_relative"),
            "iso_rms": iso.get("rms_residual_relative"),
            "hits": iso.get("hits"),
            "vol_max": vol.get("max_error_estimate"),
            "vol_rms": vol.get("rms_error_estimate"), "_stats": s}


def summarise(runs):
    """Medians over the runs of one binary and setting (None when any run failed)."""
    failed = [r["failed"] for r in runs if "failed" in r]
    if failed:
        return {"failed": failed[0]}
    out = {}
    for k in runs[0]:
        if k.startswith("_"):
            continue
        vals = [r[k] for r in runs if r[k] is not None]
        out[k] = statistics.median(vals) if vals else None
    return out


def same_view(hpray, config, threads, size, tmp):
    """The config to time both binaries on. A fitted camera (no camera.position) depends
    on the binary's fitting code, so it is resolved once by the current build (its stats
    echo the camera) and written into a copy of the config; the copy also leaves out the
    keys that only annotate the PNG (none is written), which an older revision may not
    know, and makes the mesh path absolute. A config with neither is used as it is."""
    import yaml
    with open(os.path.join(ROOT, config)) as f:
        doc = yaml.safe_load(f)
    png_only = [k for k in ("outline", "legend") if k in doc]
    cam = doc.get("camera")
    fitted = not (isinstance(cam, dict) and "position" in cam)
    if not fitted and not png_only:
        return config
    for k in png_only:
        del doc[k]
    if fitted:
        r = run_hpray(hpray, config, [], size, threads, tmp)
        if "failed" in r:
            sys.exit(f"bench_curved: the current hpray failed on {config}: {r['failed']}")
        got = r["_stats"]["camera"]
        doc["camera"] = {k: got[k] for k in ("position", "look_at", "up", "fov_y",
                                             "ortho_height") if k in got}
    mesh = doc["data"]["mesh"]
    if not mesh.startswith("builtin:"):
        doc["data"]["mesh"] = os.path.normpath(os.path.join(ROOT, os.path.dirname(config), mesh))
    path = os.path.join(tmp, "same_view_" + os.path.basename(config))
    with open(path, "w") as f:
        yaml.safe_dump(doc, f)
    return path


def image_difference(baseline, hpray, config, threads, size, tmp):
    """Max |RGBA| difference between the two binaries' images of `config` (None if the
    baseline fails), so that the timings are known to be of the same picture."""
    a, b = os.path.join(tmp, "base.npy"), os.path.join(tmp, "cur.npy")
    rb = run_hpray(baseline, config, [], size, threads, tmp, rgba=a)
    rc = run_hpray(hpray, config, [], size, threads, tmp, rgba=b)
    if "failed" in rb or "failed" in rc:
        return None
    return float(np.abs(np.load(a) - np.load(b)).max())


def error_of(kind, m):
    if "failed" in m:
        return None, None
    if kind == "iso":
        return m["iso_max"], m["iso_rms"]
    return m["vol_max"], m["vol_rms"]


# ---------------------------------------------------------------------------------------
# VTK's contour of the nk-quartic mesh


def quartic(x):
    d2 = (0.5 - x) ** 2
    return (d2 * (d2 - 0.169)).sum(axis=-1)


def quartic_vertex(a, b, c):
    """Vertex (a, b, c) of the 2x2x2 block, displaced as src/mesh/builtin.cpp does."""
    x = [0.5 * a, 0.5 * b, 0.5 * c]
    idx = (a, b, c)
    for d in range(3):
        if idx[d] == 1:
            x[d] += 0.06 * math.sin(1.7 * (d + 1) + 2.3 * a + 1.1 * b + 0.7 * c)
    return x


def quartic_grid(p=8):
    """builtin:nk-quartic as a vtkUnstructuredGrid of VTK_LAGRANGE_HEXAHEDRON cells: the
    same points (trilinear placement in each cell of its displaced vertices, a shared node
    placed by the first cell that holds it, as the builtin does), VTK's node order (from
    vtkLagrangeHexahedron's own parametric coordinates) and the point field u."""
    import vtk
    from vtk.util import numpy_support as ns
    n = (p + 1) ** 3
    cell = vtk.vtkLagrangeHexahedron()
    cell.GetPointIds().SetNumberOfIds(n)
    cell.GetPoints().SetNumberOfPoints(n)
    cell.SetUniformOrderFromNumPoints(n)
    pc = cell.GetParametricCoords()
    ijk = [tuple(int(round(pc[3 * m + d] * p)) for d in range(3)) for m in range(n)]
    g = 2 * p + 1
    pts = np.zeros((g ** 3, 3))
    placed = np.zeros(g ** 3, bool)
    grid = vtk.vtkUnstructuredGrid()
    cells = []
    for c in range(2):
        for b in range(2):
            for a in range(2):
                v = [quartic_vertex(a + (q & 1), b + ((q >> 1) & 1), c + ((q >> 2) & 1))
                     for q in range(8)]
                ids = []
                for i, j, k in ijk:
                    G = (a * p + i) + g * ((b * p + j) + g * (c * p + k))
                    ids.append(G)
                    if placed[G]:
                        continue
                    placed[G] = True
                    r, s, t = i / p, j / p, k / p
                    for d in range(3):
                        x = 0.0
                        for q in range(8):
                            x += (v[q][d] * (r if q & 1 else 1 - r) *
                                  (s if (q >> 1) & 1 else 1 - s) *
                                  (t if (q >> 2) & 1 else 1 - t))
                        pts[G, d] = x
                cells.append(ids)
    assert placed.all()
    points = vtk.vtkPoints()
    points.SetData(ns.numpy_to_vtk(pts, deep=True))
    grid.SetPoints(points)
    for ids in cells:
        grid.InsertNextCell(vtk.VTK_LAGRANGE_HEXAHEDRON, len(ids), ids)
    u = ns.numpy_to_vtk(quartic(pts), deep=True)
    u.SetName("u")
    grid.GetPointData().SetScalars(u)
    return grid


def vtk_reference(hpray, vtu, tmp, repeats):
    """Writes the quartic mesh to `vtu`, reads it back with VTK's XML reader and contours it
    with vtkContourFilter `repeats` times; returns the timings and the residuals of the
    output points on the exact quartic, and how far hpray's finite element field (hpray
    probe on the builtin) is from the exact quartic at those points."""
    import vtk
    from vtk.util import numpy_support as ns
    os.makedirs(os.path.dirname(vtu), exist_ok=True)
    writer = vtk.vtkXMLUnstructuredGridWriter()
    writer.SetFileName(vtu)
    writer.SetInputData(quartic_grid())
    if not writer.Write():
        raise RuntimeError(f"VTK could not write {vtu}")
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(vtu)
    t0 = time.perf_counter()
    reader.Update()
    read_s = time.perf_counter() - t0
    contour = vtk.vtkContourFilter()
    contour.SetInputConnection(reader.GetOutputPort())
    contour.SetValue(0, QUARTIC_ISO)
    contour.ComputeScalarsOff()
    times = []
    for _ in range(repeats):
        contour.Modified()
        t0 = time.perf_counter()
        contour.Update()
        times.append(time.perf_counter() - t0)
    out = contour.GetOutput()
    x = ns.vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    span = QUARTIC_RANGE[1] - QUARTIC_RANGE[0]
    res = np.abs(quartic(x) - QUARTIC_ISO) / span
    ref = {"vtk": vtk.vtkVersion.GetVTKVersion(), "read_s": read_s,
           "contour_s": statistics.median(times), "contour_min_s": min(times),
           "repeats": repeats, "points": len(x), "triangles": out.GetNumberOfCells(),
           "max": float(res.max()), "rms": float(math.sqrt((res ** 2).mean())),
           "vtu": vtu, "fe_vs_exact": None}
    # hpray's residuals are on its finite element field; say how far that is from the
    # exact quartic at VTK's points (rounding: the interpolant reproduces the quartic).
    csv = os.path.join(tmp, "vtk_points.csv")
    np.savetxt(csv, x, delimiter=",", fmt="%.17g")
    p = subprocess.run([hpray, "probe", "builtin:nk-quartic", "--points", csv,
                        "--fields", "u", "-q"], capture_output=True, text=True)
    if p.returncode == 0:
        rows = np.array([[float(v) for v in line.split()] for line in p.stdout.splitlines()
                         if line.strip() and not line.startswith("#")])
        if len(rows) == len(x):
            ref["fe_vs_exact"] = float(np.abs(rows[:, -1] - quartic(rows[:, :3])).max() / span)
    return ref


# ---------------------------------------------------------------------------------------


def git(*args):
    p = subprocess.run(["git", "-C", ROOT, *args], capture_output=True, text=True)
    return p.stdout.strip() if p.returncode == 0 else ""


def machine():
    model = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    load = "" if not hasattr(os, "getloadavg") else \
        ", load average %.1f at the start (a shared machine)" % os.getloadavg()[0]
    return f"{os.cpu_count()} cores (nproc), {model}{load}"


def fmt_s(v):
    return "n/a" if v is None else f"{v:.3f} s"


def fmt_e(v):
    return "n/a" if v is None else f"{v:.2g}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--baseline-bin", help="hpray binary of the baseline revision")
    ap.add_argument("--baseline-rev", default="", help="the revision as given")
    ap.add_argument("--baseline-sha", default="")
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--vtk-repeats", type=int, default=20)
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "benchmarks_curved.md"))
    ap.add_argument("--png", help="plot (default: --out with .png)")
    ap.add_argument("--vtu", default=os.path.join(ROOT, "build-bench", "nk_quartic_p8.vtu"),
                    help="where the nk-quartic mesh is written for VTK (and ParaView)")
    args = ap.parse_args()
    if args.runs < 1 or args.size < 1 or args.threads < 0:
        ap.error("--runs and --size must be positive, --threads >= 0")
    png = args.png or os.path.splitext(args.out)[0] + ".png"
    hpray = os.path.join(args.build, "bin", "hpray")
    if not os.access(hpray, os.X_OK):
        sys.exit(f"bench_curved: no hpray in {args.build}/bin (build it first)")

    head = git("rev-parse", "--short=12", "HEAD")
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", "src", "partition",
                "compositor", "cmake", "CMakeLists.txt", "configs")
    info = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M"),
            "current": head + (" with uncommitted changes" if dirty else ""),
            "current_subject": git("log", "-1", "--format=%s", "HEAD"),
            "baseline": None}
    if args.baseline_bin:
        info["baseline"] = f"{args.baseline_rev} = {args.baseline_sha[:12]}"
        info["baseline_subject"] = git("log", "-1", "--format=%s", args.baseline_sha)

    skipped = []
    scenes = []
    for name, config, kind in SCENES:
        mesh = scene_mesh(config)
        if mesh is not None and not os.path.exists(mesh):
            note = f"{name} (`{config}`): its mesh {mesh} is missing (../shared/data)"
            print("bench_curved: skipped " + note, file=sys.stderr)
            skipped.append(note)
            continue
        scenes.append((name, config, kind))
    if skipped and len(skipped) == sum(1 for s in SCENES if scene_mesh(s[1])):
        print("bench_curved: ../shared/data is missing: the shared-data scenes "
              "(deal.II step-65, MFEM escher) are left out of the report", file=sys.stderr)

    with tempfile.TemporaryDirectory(prefix="bc_", dir="/tmp") as tmp:
        # 1. before/after
        before_after = []
        check = min(args.size, 128)  # image size of the same-picture check
        for name, config, kind in scenes:
            runs = {"baseline": [], "current": []}
            diff = None
            timed = config
            if args.baseline_bin:
                timed = same_view(hpray, config, args.threads, check, tmp)
                diff = image_difference(args.baseline_bin, hpray, timed, args.threads, check,
                                        tmp)
            else:  # a warm-up: the mesh file into the page cache
                run_hpray(hpray, config, [], check, args.threads, tmp)
            for r in range(args.runs):
                if args.baseline_bin:
                    runs["baseline"].append(run_hpray(args.baseline_bin, timed, [],
                                                      args.size, args.threads, tmp))
                runs["current"].append(run_hpray(hpray, timed, [], args.size,
                                                 args.threads, tmp))
            cur = summarise(runs["current"])
            if "failed" in cur:
                sys.exit(f"bench_curved: the current hpray failed on {config}: {cur['failed']}")
            base = summarise(runs["baseline"]) if args.baseline_bin else None
            before_after.append({"name": name, "config": config, "kind": kind,
                                 "current": cur, "baseline": base, "diff": diff,
                                 "copied": timed != config})
            print(f"{name}: current render {cur['render']:.3f} s" +
                  (f", baseline {base['render']:.3f} s" if base and "failed" not in base
                   else ""), file=sys.stderr)

        # 2. speed against error
        sweeps = []
        present = {s[0]: s for s in scenes}
        for name, key, values in SWEEPS:
            if name not in present:
                continue
            _, config, kind = present[name]
            # Round-robin: each round runs every setting once, so that a drift of the
            # machine's load hits all settings alike.
            sets = [[] if v is None else [f"accuracy.{key}={v:g}"] for v in values]
            runs = [[] for _ in values]
            for r in range(args.runs):
                for i in range(len(values)):
                    runs[i].append(run_hpray(hpray, config, sets[i], args.size,
                                             args.threads, tmp))
            points = []
            for v, rs, kv in zip(values, runs, sets):
                m = summarise(rs)
                if "failed" in m:
                    sys.exit(f"bench_curved: hpray failed on {config} with {kv}: "
                             f"{m['failed']}")
                points.append({"value": v, "m": m})
                print(f"{name}: {key}={label_of(v)}: render {m['render']:.3f} s, "
                      f"error {error_of(kind, m)}", file=sys.stderr)
            sweeps.append({"name": name, "config": config, "kind": kind, "key": key,
                           "points": points})

        # 3. VTK
        try:
            ref = vtk_reference(hpray, args.vtu, tmp, args.vtk_repeats)
            print(f"VTK contour: {ref['contour_s'] * 1e3:.1f} ms, max {ref['max']:.3g}, "
                  f"RMS {ref['rms']:.3g}", file=sys.stderr)
        except ImportError as e:
            print(f"bench_curved: VTK reference skipped: {e}", file=sys.stderr)
            ref = None

    write_report(args, png, info, before_after, sweeps, ref, skipped)
    plot(sweeps, ref, png, args)
    print(f"wrote {args.out} and {png}", file=sys.stderr)


def write_report(args, png, info, before_after, sweeps, ref, skipped):
    L = ["# Curved high-order rendering: speed against error", "",
         "Written by `scripts/bench_curved.sh` (rerun it to refresh this file and the "
         "plot; see docs/benchmarks.md). Not part of the tests.", "",
         f"- machine: {info['machine']}",
         f"- date: {info['date']}",
         f"- current: {info['current']} ({info['current_subject']})"]
    if info["baseline"]:
        L.append(f"- baseline: {info['baseline']} ({info['baseline_subject']})")
    alternating = ", baseline and current alternating" if info["baseline"] else ""
    L += [f"- images {args.size}x{args.size}, `threads: {args.threads}`, medians of "
          f"{args.runs} run{'s' if args.runs > 1 else ''}{alternating}",
          "- render: the stats' `timing_s.render` (rays only); wall: the whole `hpray "
          "render` process (reading, preparing, rendering; no image written); CPU: that "
          "process's user + system time, the figure a busy shared machine disturbs least",
          "- error of an isosurface scene: the stats' `iso.max_residual_relative` and "
          "`iso.rms_residual_relative` (|field - isovalue| at the hits, on the true finite "
          "element field, over the field's range); of a volume: `volume.max_error_estimate` "
          "and `volume.rms_error_estimate` (the per-pixel RGB error estimate)", ""]
    if skipped:
        L += ["Skipped: " + "; ".join(skipped) + ".", ""]

    L += ["## Before and after", ""]
    check = min(args.size, 128)
    if info["baseline"]:
        L += ["Each time cell is baseline → current, then the speedup baseline / current "
              "(above 1: the current code is faster). Before the timed runs both binaries "
              f"render each scene once at {check}^2 and the largest |RGBA| difference of "
              "their images is given, so that the times are known to be of the same picture "
              "(differences far below 1e-6 are rounding). A scene marked * is timed on a "
              "copy of its config: its fitted camera as the current build fits it, written "
              "out explicitly (the fitting itself may differ between revisions), and without "
              "`outline` and `legend`, which only annotate the PNG (none is written here) "
              "and which an older revision may not know.", "",
              "| scene | what | render | wall | CPU | max / RMS error, baseline → current | "
              "image difference |",
              "|---|---|---|---|---|---|---|"]
    else:
        L += ["No baseline (`--baseline none`).", "",
              "| scene | what | render | wall | CPU | max / RMS error |",
              "|---|---|---|---|---|---|"]

    def change(base, cur, key):
        return (f"{base[key]:.3f} → {cur[key]:.3f} s, "
                f"**{base[key] / cur[key]:.2f}**")

    for row in before_after:
        cur, base = row["current"], row["baseline"]
        ce = "%s / %s" % tuple(fmt_e(v) for v in error_of(row["kind"], cur))
        what = f"`{row['config']}`{' *' if row['copied'] else ''}: " \
               f"{DESCRIPTION[row['name']]}"
        if not info["baseline"]:
            L.append(f"| {row['name']} | {what} | {fmt_s(cur['render'])} | "
                     f"{fmt_s(cur['wall'])} | {fmt_s(cur['cpu'])} | {ce} |")
        elif "failed" in base:
            msg = base["failed"].replace("|", "/")
            L.append(f"| {row['name']} | {what} | baseline failed: {msg}; current "
                     f"{fmt_s(cur['render'])} | current {fmt_s(cur['wall'])} | current "
                     f"{fmt_s(cur['cpu'])} | {ce} | |")
        else:
            be = "%s / %s" % tuple(fmt_e(v) for v in error_of(row["kind"], base))
            L.append(f"| {row['name']} | {what} | {change(base, cur, 'render')} | "
                     f"{change(base, cur, 'wall')} | {change(base, cur, 'cpu')} | "
                     f"{be} → {ce} | {fmt_e(row['diff'])} |")
    L.append("")

    L += ["## Speed against error (current)", "",
          "`accuracy.target_residual` (isosurfaces; default: none, every root polished to "
          "the root tolerance) and `accuracy.volume_tolerance` (volume; the config's own is "
          "1e-8), set with `--set`, in rounds that run every setting of a scene once (so "
          "that a drift of the machine's load hits all settings alike). The error columns "
          "are what the stats report as delivered.", "",
          "| scene | setting | render | wall | CPU | max error | RMS error | hits |",
          "|---|---|---|---|---|---|---|---|"]
    for sw in sweeps:
        for pt in sw["points"]:
            m = pt["m"]
            mx, rms = error_of(sw["kind"], m)
            setting = ("default" if pt["value"] is None else
                       f"`{sw['key']}: {label_of(pt['value'])}`")
            hits = "" if sw["kind"] != "iso" or m["hits"] is None else f"{m['hits']:.0f}"
            L.append(f"| {sw['name']} | {setting} | {fmt_s(m['render'])} | "
                     f"{fmt_s(m['wall'])} | {fmt_s(m['cpu'])} | {fmt_e(mx)} | {fmt_e(rms)} | "
                     f"{hits} |")
    L += ["", f"![render time against error]({os.path.relpath(png, os.path.dirname(args.out))})",
          ""]

    L += ["## VTK's contour of the Lagrange cells (nk-quartic)", ""]
    if ref is None:
        L += ["Not measured: /usr/bin/python3 has no VTK (Debian's python3-vtk9).", ""]
    else:
        fe = ("" if ref["fe_vs_exact"] is None else
              f" hpray's finite element field (`hpray probe` on the builtin) differs from the "
              f"exact quartic by at most {ref['fe_vs_exact']:.2g} of the range at VTK's points, "
              "so residuals on either field are the same.")
        L += [f"builtin:nk-quartic written as 8 `VTK_LAGRANGE_HEXAHEDRON` cells of order 8 "
              f"(type 72, VTK's node order; `{os.path.relpath(ref['vtu'], ROOT)}`, "
              "openable in ParaView), read with vtkXMLUnstructuredGridReader and contoured "
              f"at u = {QUARTIC_ISO} with vtkContourFilter, VTK {ref['vtk']} (what "
              "ParaView's Contour filter runs): VTK splits each Lagrange hexahedron into "
              "order^3 linear hexahedra on its nodes and contours those, so the surface is "
              "piecewise linear on the node lattice. Time is the median of "
              f"{ref['repeats']} re-executions of the filter alone (one thread; the output is "
              "geometry that still has to be rendered). Residuals are |u(x) - isovalue| of "
              "the output points on the exact quartic, over the field's range "
              f"[{QUARTIC_RANGE[0]:.8g}, {QUARTIC_RANGE[1]:.8g}]." + fe, "",
              "| method | read .vtu | contour | points | triangles | max residual | RMS "
              "residual |", "|---|---|---|---|---|---|---|",
              f"| VTK vtkContourFilter | {ref['read_s'] * 1e3:.1f} ms | "
              f"{ref['contour_s'] * 1e3:.1f} ms | {ref['points']} | {ref['triangles']} | "
              f"{ref['max']:.2g} | {ref['rms']:.2g} |"]
        quart = next((sw for sw in sweeps if sw["name"] == "nk-quartic"), None)
        if quart:
            for pt in quart["points"]:
                if pt["value"] in (None, 1e-4):
                    m = pt["m"]
                    setting = ("default" if pt["value"] is None else
                               f"target_residual {label_of(pt['value'])}")
                    L.append(f"| hpray render, {setting}, {args.size}^2, {args.threads} "
                             f"threads | | {m['render'] * 1e3:.1f} ms (render) | "
                             f"{m['hits']:.0f} hits | | {fmt_e(m['iso_max'])} | "
                             f"{fmt_e(m['iso_rms'])} |")
        L.append("")
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        f.write("\n".join(L))
    print("\n".join(L))


def label_of(value):
    """1e-08 as 1e-8; None (no setting) as default."""
    if value is None:
        return "default"
    exact = float(f"{value:.0e}") == value and not 1e-3 <= abs(value) < 1e4
    text = f"{value:.0e}" if exact else f"{value:g}"
    return re.sub(r"e([+-])0*(\d)", lambda m: "e" + m.group(1).replace("+", "") + m.group(2),
                  text)


def plot(sweeps, ref, path, args):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    floor = 1e-17  # zero errors drawn here on the log scale
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.4), sharey=True,
                             gridspec_kw={"width_ratios": [3, 2]})
    colors = {"nk-quartic": "tab:orange", "deal.II step-65": "tab:blue",
              "nk-sinc volume": "tab:green"}
    for sw in sweeps:
        ax = axes[0] if sw["kind"] == "iso" else axes[1]
        c = colors.get(sw["name"], "tab:gray")
        t = [pt["m"]["render"] for pt in sw["points"]]
        mx = [max(error_of(sw["kind"], pt["m"])[0] or 0, floor) for pt in sw["points"]]
        rms = [max(error_of(sw["kind"], pt["m"])[1] or 0, floor) for pt in sw["points"]]
        ax.plot(mx, t, "o-", color=c, label=f"{sw['name']}, max")
        ax.plot(rms, t, "o--", color=c, mfc="none", alpha=0.6, label=f"{sw['name']}, RMS")
        # One label for the settings that land on the same spot.
        groups = []
        for pt, x, y in zip(sw["points"], mx, t):
            for g in groups:
                if abs(math.log10(x / g[0])) < 0.15 and abs(math.log10(y / g[1])) < 0.03:
                    g[2].append(label_of(pt["value"]))
                    break
            else:
                groups.append((x, y, [label_of(pt["value"])]))
        for x, y, labels in groups:
            ax.annotate(", ".join(labels), (x, y), textcoords="offset points",
                        xytext=(4, 4), fontsize=7, color=c)
    if ref is not None:
        ax = axes[0]
        ax.plot([ref["max"]], [ref["contour_s"]], "*", color="k", ms=13,
                label="VTK contour (nk-quartic), max")
        ax.plot([ref["rms"]], [ref["contour_s"]], "*", color="k", mfc="none", ms=13,
                label="VTK contour (nk-quartic), RMS")
    axes[0].set_title("isosurfaces: accuracy.target_residual", fontsize=10)
    axes[0].set_xlabel("residual / field range")
    axes[1].set_title("volume: accuracy.volume_tolerance", fontsize=10)
    axes[1].set_xlabel("stats' RGB error estimate")
    axes[0].set_ylabel(f"render time, s ({args.size}^2, {args.threads} threads); "
                       "VTK: contour only")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.margins(x=0.12, y=0.08)
        if ax.lines:
            ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    main()
