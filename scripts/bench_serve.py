#!/usr/bin/env python3
"""Frame latency of `hpray serve` against `hpray render` (a benchmark, not a test).

For each scene and each layout (ranks x threads per rank) it starts the service on this
machine, renders one warm-up frame (the preparation), then FRAMES frames of an orbiting
camera, and reports the median request latency (POST to answer: the frame rendered and
composited; its files are written meanwhile), the median time to the first pass of a
progressive request (scale 8: 1/64 of the pixels) and to its final pass, and, for
comparison, the median process wall of `hpray render` of the same scene (load, prepare,
render, write). The service's frames pay no loading or preparation.

Usage: scripts/bench_serve.py [--build build] [--frames 7] [--runs 3]
                              [--scene configs/quickstart.yaml ...]
                              [--layout 1x2 --layout 2x1 ...]
Scenes under ../shared/data are skipped when the file is missing.
"""
import argparse
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
from hpray_client import Client  # noqa: E402

ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMPI_MCA_rmaps_base_oversubscribe="1")


def launcher(ranks):
    return ["mpirun", "-n", str(ranks), "--bind-to", "none"] if ranks > 1 else []


def start(hpray, scene, ranks, threads):
    cmd = launcher(ranks) + [hpray, "serve", scene, "--port", "0",
                             "--set", f"threads={threads}"]
    service = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               text=True, env=ENV)
    line = service.stdout.readline()
    m = re.match(r"hpray serve: listening on (http://\S+) token (\S+)", line)
    if not m:
        service.kill()
        raise SystemExit(f"{scene}: the service did not start ({line!r})")
    return service, Client(m.group(1), m.group(2))


def orbit(camera, k, frames):
    """The scene's camera turned by k/frames of 60 degrees about its up axis (y)."""
    p, c = camera["position"], camera["look_at"]
    a = math.radians(60.0 * (k + 1) / frames)
    x, z = p[0] - c[0], p[2] - c[2]
    return {"camera": {"position": [c[0] + x * math.cos(a) - z * math.sin(a), p[1],
                                    c[2] + x * math.sin(a) + z * math.cos(a)]}}


def bench_service(hpray, scene, ranks, threads, frames):
    service, client = start(hpray, scene, ranks, threads)
    try:
        camera = client.info()["scene"]["camera"]
        t0 = time.perf_counter()
        client.render_frame({})
        first = time.perf_counter() - t0
        latency, coarse, final = [], [], []
        for k in range(frames):
            t0 = time.perf_counter()
            client.render_frame(orbit(camera, k, frames))
            latency.append(time.perf_counter() - t0)
        for k in range(frames):
            t0 = time.perf_counter()
            for p in client.render_passes(orbit(camera, frames - k, frames), passes=(8, 1)):
                (coarse if p["pass"] == 0 else final).append(time.perf_counter() - t0)
        client.shutdown()
        service.wait(timeout=60)
    finally:
        if service.poll() is None:
            service.kill()
    return first, statistics.median(latency), statistics.median(coarse), \
        statistics.median(final)


def bench_render(hpray, scene, ranks, threads, runs):
    walls = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(runs):
            cmd = launcher(ranks) + [hpray, "render", scene, "-q", "--set", f"threads={threads}",
                                     "--set", f"output.png={tmp}/f.png",
                                     "--set", f"output.exr={tmp}/f.exr",
                                     "--set", f"output.stats={tmp}/f.json"]
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, env=ENV, stdout=subprocess.DEVNULL)
            walls.append(time.perf_counter() - t0)
    return statistics.median(walls)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--frames", type=int, default=7)
    ap.add_argument("--runs", type=int, default=3, help="hpray render runs per layout")
    ap.add_argument("--scene", action="append")
    ap.add_argument("--layout", action="append", help="RANKSxTHREADS, e.g. 2x1")
    args = ap.parse_args()
    hpray = os.path.join(args.build, "bin", "hpray")
    scenes = args.scene or [os.path.join(ROOT, "configs", "quickstart.yaml"),
                            os.path.join(ROOT, "configs", "volume_t16_tets_1M.yaml")]
    layouts = args.layout or ["1x1", "2x1", "1x2"]
    print(f"{os.cpu_count()} cores; medians of {args.frames} frames "
          f"(hpray render: of {args.runs} runs)")
    print("| scene | ranks x threads | hpray render (process) | service: first frame "
          "(with preparation) | later frames | first coarse pass (1/64 px) | final pass |")
    print("|---|---|---|---|---|---|---|")
    for scene in scenes:
        text = open(scene).read()
        m = re.search(r"mesh:\s*(\S+)", text)
        if m and not m.group(1).startswith("builtin:"):
            path = os.path.normpath(os.path.join(os.path.dirname(scene), m.group(1)))
            if not os.path.exists(path):
                print(f"| {os.path.basename(scene)} | skipped: {path} is missing |")
                continue
        for layout in layouts:
            ranks, threads = (int(v) for v in layout.split("x"))
            render = bench_render(hpray, scene, ranks, threads, args.runs)
            first, later, coarse, final = bench_service(hpray, scene, ranks, threads,
                                                        args.frames)
            print(f"| {os.path.basename(scene)} | {ranks} x {threads} | {render:.3f} s | "
                  f"{first:.3f} s | {later:.3f} s | {coarse:.3f} s | {final:.3f} s |",
                  flush=True)


if __name__ == "__main__":
    main()
