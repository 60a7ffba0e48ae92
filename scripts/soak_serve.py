#!/usr/bin/env python3
"""Soak test of `hpray serve` (not a timed test): starts the service on 2 ranks on this
machine's loopback, sends REQUESTS requests (10% malformed; a quarter of the valid ones progressive, whose
passes the other clients' requests may cancel) from CLIENTS concurrent clients, and reports failures of valid requests, answers to malformed ones, latency, and
the resident memory of every rank after the first 100 requests and at the end.

Usage: scripts/soak_serve.py [--build build] [--requests 1000] [--clients 4]
"""
import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
from hpray_client import Client, ServiceError  # noqa: E402

MALFORMED = [
    b"{not json",
    b"[1, 2, 3]",
    b'{"bogus": 1}',
    b'{"camera": {"width": "wide"}}',
    b'{"data": {"mesh": "builtin:cube-tets-1"}}',
    b'{"isosurfaces": [{"field": "nope", "value": 1}]}',
]


def rank_rss_kib(pids):
    out = {}
    for pid in pids:
        try:
            with open(f"/proc/{pid}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        out[pid] = int(line.split()[1])
        except OSError:
            pass
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--requests", type=int, default=1000)
    ap.add_argument("--clients", type=int, default=4)
    ap.add_argument("--scene", default=os.path.join(ROOT, "configs", "quickstart.yaml"))
    ap.add_argument("--size", type=int, default=128, help="image width and height")
    args = ap.parse_args()

    hpray = os.path.join(args.build, "bin", "hpray")
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1", OMPI_MCA_mpi_yield_when_idle="1")
    cmd = ["mpirun", "-n", "2", "--bind-to", "none", hpray, "serve", args.scene, "--port",
           "0", "--set", f"camera.width={args.size}", "--set", f"camera.height={args.size}"]
    service = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env)
    line = service.stdout.readline()
    if not line.startswith("hpray serve: listening on "):
        sys.exit(f"no start-up line: {line!r}")
    url = line.split()[4]
    token = line.split()[-1]
    ranks = subprocess.run(["pgrep", "-P", str(service.pid)], capture_output=True,
                           text=True).stdout.split()
    client = Client(url, token)

    lock = threading.Lock()
    counts = {"valid": 0, "valid_failed": 0, "progressive": 0, "progressive_cancelled": 0,
              "malformed": 0, "malformed_400": 0, "malformed_other": 0}
    latencies = []
    rss = {}
    done = [0]
    rng = random.Random(1)
    plan = [rng.random() < 0.1 for _ in range(args.requests)]
    next_index = [0]

    def worker():
        while True:
            with lock:
                i = next_index[0]
                if i >= len(plan):
                    return
                next_index[0] += 1
            if plan[i]:
                body = MALFORMED[i % len(MALFORMED)]
                req = urllib.request.Request(url.rstrip("/") + "/api/render", data=body,
                                             method="POST")
                req.add_header("Authorization", "Bearer " + token)
                try:
                    urllib.request.urlopen(req, timeout=120).read()
                    status = 200
                except urllib.error.HTTPError as e:
                    status = e.code
                with lock:
                    counts["malformed"] += 1
                    counts["malformed_400" if status == 400 else "malformed_other"] += 1
            else:
                angle = 0.01 * i
                overrides = {"camera": {"position": [2.5 + 0.5 * (i % 3), 1.5, 2.5 + angle]}}
                if i % 5 == 0:
                    overrides["isosurfaces"] = [{"field": "u", "value": 0.05 * (i % 7)}]
                t0 = time.time()
                progressive = i % 4 == 1
                try:
                    if progressive:
                        # Passes that a newer request cancels are a correct answer too:
                        # every delivered pass must be a kept frame with an image.
                        passes = list(client.render_passes(overrides, passes=(4, 1)))
                        ok = bool(passes) and all(
                            client.frame_file(p["frame"], "image.png")[1:4] == b"PNG"
                            for p in passes)
                        cancelled = bool(passes) and not passes[-1]["final"]
                    else:
                        client.render(overrides)
                        ok, cancelled = True, False
                except (ServiceError, OSError):
                    ok, cancelled = False, False
                with lock:
                    counts["valid"] += 1
                    counts["valid_failed"] += 0 if ok else 1
                    counts["progressive"] += progressive
                    counts["progressive_cancelled"] += progressive and cancelled
                    latencies.append(time.time() - t0)
            with lock:
                done[0] += 1
                if done[0] == 100:
                    rss["after_100"] = rank_rss_kib(ranks)

    threads = [threading.Thread(target=worker) for _ in range(args.clients)]
    start = time.time()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.time() - start
    rss["end"] = rank_rss_kib(ranks)
    client.shutdown()
    code = service.wait(timeout=60)

    growth = {pid: (rss["end"].get(pid, 0) - kib) / kib
              for pid, kib in rss.get("after_100", {}).items() if kib}
    report = {
        "requests": args.requests, "clients": args.clients, "wall_s": round(wall, 2),
        **counts,
        "latency_s": {"median": round(statistics.median(latencies), 4),
                      "max": round(max(latencies), 4)} if latencies else {},
        "rss_kib_after_100": rss.get("after_100"), "rss_kib_end": rss["end"],
        "rss_growth_after_100": {pid: round(g, 4) for pid, g in growth.items()},
        "service_exit": code,
    }
    print(json.dumps(report, indent=1))
    ok = (counts["valid_failed"] == 0 and counts["malformed_other"] == 0 and code == 0 and
          all(g < 0.10 for g in growth.values()))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
