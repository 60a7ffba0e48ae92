#!/usr/bin/env python3
"""scripts/hpray_client.py against a running `hpray serve` (one process, builtin data):
render() returns the premultiplied RGBA `hpray render` writes for the merged scene
(1e-6), render_passes() yields the coarse pass then the final one with their sizes,
errors() the (H, W, 2) float32 error channels matching the frame's residuals, and a bad
key raises ServiceError with status 400 naming it.

Usage: test_client.py --hpray build/bin/hpray
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
from hpray_client import Client, ServiceError  # noqa: E402

SCENE = os.path.join(ROOT, "configs", "ball_p2.yaml")
SIZE = ["--set", "camera.width=48", "--set", "camera.height=40"]


def check(condition, message):
    if not condition:
        raise SystemExit("FAILED: " + message)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--hpray", required=True)
    args = ap.parse_args()
    service = subprocess.Popen([args.hpray, "serve", SCENE, "--port", "0"] + SIZE,
                               stdout=subprocess.PIPE, text=True)
    try:
        line = service.stdout.readline()
        m = re.match(r"hpray serve: listening on (http://\S+) token (\S+)", line)
        check(m is not None, f"no start-up line: {line!r}")
        client = Client(m.group(1), m.group(2), timeout=120)
        overrides = {"camera": {"position": [2.5, 1.0, 1.5]},
                     "isosurfaces": [{"field": "u", "value": 0.6, "opacity": 0.7}]}

        rgba, stats = client.render(overrides)
        check(rgba.shape == (40, 48, 4), f"rgba shape {rgba.shape}")
        check("timing_s" in stats, "stats without timing_s")
        with tempfile.TemporaryDirectory() as tmp:
            ref = os.path.join(tmp, "ref.npy")
            subprocess.run([args.hpray, "render", SCENE, "-q"] + SIZE +
                           ["--set", "camera.position=[2.5, 1.0, 1.5]",
                            "--set", 'isosurfaces=[{field: u, value: 0.6, opacity: 0.7}]',
                            "--set", "output.exr=null", "--set", "output.png=null",
                            "--set", "output.stats=null", "--set", f"output.rgba={ref}"],
                           check=True)
            expected = np.load(ref)
        worst = float(np.max(np.abs(rgba - expected)))
        check(worst <= 1e-6, f"client frame differs from hpray render by {worst}")
        check(float(rgba[..., 3].max()) > 0, "nothing drawn")

        passes = list(client.render_passes(overrides, passes=(4, 1)))
        check([p["pass"] for p in passes] == [0, 1], f"passes {passes}")
        check((passes[0]["width"], passes[0]["height"]) == (12, 10),
              f"coarse size {passes[0]['width']}x{passes[0]['height']}")
        check(passes[1]["final"] and passes[1]["width"] == 48, "final pass")
        errors = client.errors(passes[1]["frame"])
        check(errors.shape == (40, 48, 2) and errors.dtype == np.float32,
              f"errors {errors.shape} {errors.dtype}")
        hit = np.isfinite(errors[..., 0])
        check(hit.any(), "no residual in errors.npy")
        check(float(np.nanmax(errors[..., 0])) <= stats["iso"]["max_residual"] * (1 + 1e-6),
              "residuals in errors.npy above the frame's max residual")

        try:
            client.render({"isosurfaces": [{"field": "u", "valeu": 1}]})
            check(False, "a misspelt key was accepted")
        except ServiceError as e:
            check(e.status == 400 and "valeu" in e.message, f"bad key: {e}")
        client.shutdown()
        check(service.wait(timeout=60) == 0, "the service did not exit 0")
    finally:
        if service.poll() is None:
            service.kill()
    print("client: frames, passes, errors and bad keys as expected")


if __name__ == "__main__":
    main()
