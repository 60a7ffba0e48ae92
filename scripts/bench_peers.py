#!/usr/bin/python3
"""hpray against VTK's unstructured-grid volume mappers on the same data, camera and
transfer functions (run by scripts/bench_peers.sh, which installs the optional peers).

For each scene, RUNS rounds alternate: `hpray render` (process wall from start to the
written image, and its timing_s.render), then each VTK mapper (vtk_peer.py: reading the
file to the first image, then later frames of a turning camera). Errors are the max and
mean absolute difference of premultiplied RGBA against hpray at volume_tolerance 1e-12.
Writes docs/benchmarks.md's peers section and docs/benchmarks_peers.png.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.normpath(os.path.join(ROOT, "..", "shared", "data"))
MAPPERS = ["raycast-linear", "raycast-preint", "projected-tetrahedra"]
LABEL = {"hpray": "hpray (exact, default tolerance)",
         "raycast-linear": "VTK ray cast + linear integrator",
         "raycast-preint": "VTK ray cast + pre-integration",
         "projected-tetrahedra": "VTK projected tetrahedra"}

# The benchmark scenes: an hpray config, its volume only, at a chosen size.
SCENES = [
    {"name": "t16 (1.25M linear tets)", "config": "configs/volume_t16_tets_1M.yaml",
     "size": 1024},
    {"name": "Fichera mixed (tets, hexes, wedges, pyramids)",
     "config": "configs/volume_fichera_mixed.yaml", "size": 512},
]


def load_scene(hpray, config, size):
    """The scene as hpray reads it (the `hpray render` stats echo the camera and volume)."""
    import yaml  # python3-yaml, a dependency of python3-matplotlib's stack on Debian
    with open(os.path.join(ROOT, config)) as f:
        doc = yaml.safe_load(f)
    mesh = os.path.normpath(os.path.join(ROOT, "configs", doc["data"]["mesh"]))
    cam = dict(doc["camera"], width=size, height=size)
    vol = doc["volume"]
    return {"mesh": mesh, "field": vol["color_field"], "color_tf": vol["color_tf"],
            "extinction_tf": vol["extinction_tf"], "camera": cam}


def run_hpray(hpray, config, size, tolerance, out_npy, threads):
    """One `hpray render` writing what a user's run writes (PNG, EXR, stats), plus the
    float64 RGBA array for the errors where out_npy is given (untimed runs only: the
    image is the same on every run)."""
    with tempfile.TemporaryDirectory() as tmp:
        stats = os.path.join(tmp, "s.json")
        cmd = [hpray, "render", os.path.join(ROOT, config), "-q",
               "--set", "isosurfaces=null", "--set", f"threads={threads}",
               "--set", f"camera.width={size}", "--set", f"camera.height={size}",
               "--set", f"output.png={tmp}/f.png", "--set", f"output.exr={tmp}/f.exr",
               "--set", f"output.stats={stats}"]
        if out_npy:
            cmd += ["--set", f"output.rgba={out_npy}"]
        if tolerance:
            cmd += ["--set", f"accuracy.volume_tolerance={tolerance}"]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True)
        wall = time.perf_counter() - t0
        with open(stats) as f:
            s = json.load(f)
    return wall, s["timing_s"]["render"]


def run_vtk(mapper, scene, out_npy, frames):
    cmd = ["/usr/bin/python3", os.path.join(ROOT, "scripts", "vtk_peer.py"), mapper,
           json.dumps(scene), out_npy, "--frames", str(frames)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    return r["load_s"] + r["first_render_s"], statistics.median(r["later_s"])


def errors(a, b):
    d = np.abs(np.load(a) - np.load(b))
    return float(d.max()), float(d.mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--frames", type=int, default=3, help="VTK later frames per run")
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--size", type=int, help="image size for every scene (default: each scene's)")
    ap.add_argument("--docs", default=os.path.join(ROOT, "docs"))
    ap.add_argument("--baseline-bin", help="an hpray of an earlier revision, timed too")
    ap.add_argument("--baseline-rev", default="baseline", help="its revision, for labels")
    args = ap.parse_args()
    hpray = os.path.join(args.build, "bin", "hpray")
    ours = ["hpray"]
    if args.baseline_bin:
        ours.append("baseline")
        LABEL["baseline"] = f"hpray at {args.baseline_rev} (same tolerance)"
    results = []
    load = {}  # per scene: the 1-minute load average before and after its rounds
    with tempfile.TemporaryDirectory() as tmp:
        for sc in SCENES:
            size = args.size or sc["size"]
            scene = load_scene(hpray, sc["config"], size)
            if not os.path.exists(scene["mesh"]):
                print(f"skipped {sc['name']}: {scene['mesh']} is missing", file=sys.stderr)
                continue
            ref = os.path.join(tmp, "ref.npy")
            run_hpray(hpray, sc["config"], size, 1e-12, ref, args.threads)
            times = {k: {"first": [], "later": []} for k in ours + MAPPERS}
            err = {}
            for k in ours:
                out = os.path.join(tmp, k + ".npy")
                binary = args.baseline_bin if k == "baseline" else hpray
                run_hpray(binary, sc["config"], size, None, out, args.threads)
                err[k] = errors(out, ref)
            load[sc["name"]] = [os.getloadavg()[0]]
            for r in range(args.runs):
                for k in ours:
                    binary = args.baseline_bin if k == "baseline" else hpray
                    wall, render = run_hpray(binary, sc["config"], size, None, None,
                                             args.threads)
                    times[k]["first"].append(wall)
                    times[k]["later"].append(render)
                for m in MAPPERS:
                    out = os.path.join(tmp, m + ".npy")
                    first, later = run_vtk(m, scene, out, args.frames)
                    times[m]["first"].append(first)
                    times[m]["later"].append(later)
                    err[m] = errors(out, ref)
                print(f"{sc['name']}: round {r + 1} of {args.runs} done", file=sys.stderr)
            load[sc["name"]].append(os.getloadavg()[0])
            for k in ours + MAPPERS:
                results.append({"scene": sc["name"], "size": size, "renderer": k,
                                "first": statistics.median(times[k]["first"]),
                                "later": statistics.median(times[k]["later"]),
                                "max_error": err[k][0], "mean_error": err[k][1]})
    write_docs(results, load, args)


def write_docs(results, load, args):
    lines = [
        "| scene | renderer | first frame (read to image) | later frames | max abs RGBA error | mean abs RGBA error |",
        "|---|---|---|---|---|---|"]
    for r in results:
        lines.append(f"| {r['scene']}, {r['size']}^2 | {LABEL[r['renderer']]} | "
                     f"{r['first']:.2f} s | {r['later']:.2f} s | {r['max_error']:.2g} | "
                     f"{r['mean_error']:.2g} |")
    table = "\n".join(lines)
    print(table)
    os.makedirs(args.docs, exist_ok=True)
    md = os.path.join(args.docs, "benchmarks.md")
    header = "<!-- peers: written by scripts/bench_peers.sh -->"
    footer = "<!-- /peers -->"
    section = (f"{header}\n## hpray and VTK's unstructured volume mappers\n\n"
               f"Measured by `scripts/bench_peers.sh` on {os.cpu_count()} cores "
               f"({time.strftime('%Y-%m-%d')}), medians of {args.runs} alternating rounds; "
               f"hpray on {args.threads} threads. hpray's first frame is the whole `hpray "
               "render` process (reading, preparing, rendering, writing EXR and PNG), its "
               "later frame the render alone (what a frame of `hpray serve` costs); VTK's "
               "first frame is reading the file to the first image, later frames re-render "
               "a turning camera in the same process (VTK 9.1, under Xvfb with llvmpipe). "
               "Errors are against hpray at volume_tolerance 1e-12; VTK's include its 8-bit "
               "framebuffer (up to 0.002) and, at silhouettes, its own pixel sampling."
               + (f" `hpray at {args.baseline_rev}` is this program at that revision, "
                  "timed in the same rounds." if args.baseline_bin else "")
               + " The timed hpray runs write what a user's run writes (EXR, PNG, stats); "
               "the arrays for the errors come from one more, untimed run of each. "
               "Load average (1 minute) before and after each scene's rounds: "
               + "; ".join(f"{name} {a:.1f} and {b:.1f}" for name, (a, b) in load.items())
               + " (other work on the machine slows hpray and VTK alike; the rounds "
               "alternate them).\n\n"
               f"{table}\n\n![time against error](benchmarks_peers.png)\n{footer}\n")
    text = ""
    if os.path.exists(md):
        with open(md) as f:
            text = f.read()
    if header in text and footer in text:
        start = text.index(header)
        end = text.index(footer) + len(footer) + 1
        text = text[:start] + section + text[end:]
    else:
        text = (text or "# Benchmarks\n\n") + section
    with open(md, "w") as f:
        f.write(text)
    plot(results, os.path.join(args.docs, "benchmarks_peers.png"))


def plot(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 5))
    markers = {"hpray": "*", "baseline": "P", "raycast-linear": "o", "raycast-preint": "s",
               "projected-tetrahedra": "^"}
    scenes = sorted({r["scene"] for r in results})
    colors = dict(zip(scenes, ["tab:blue", "tab:orange", "tab:green"]))
    for r in results:
        ax.scatter(r["first"], max(r["max_error"], 1e-16), marker=markers[r["renderer"]],
                   s=120 if r["renderer"] == "hpray" else 60, color=colors[r["scene"]],
                   label=f"{LABEL[r['renderer']]} — {r['scene']}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("first frame, seconds (read to image)")
    ax.set_ylabel("max abs RGBA error against hpray at 1e-12")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
