#!/usr/bin/env python3
"""A client for `hpray serve` (standard library and numpy only).

As a module:

    from hpray_client import Client
    c = Client("http://127.0.0.1:8080/", token="...")
    rgba, stats = c.render({"camera": {"position": [4, 0, 0]}})
    # rgba: float64 array (H, W, 4), premultiplied; stats: the frame's stats dict
    for p in c.render_passes({"camera": {"position": [4, 0, 0]}}, passes=(8, 1)):
        print(p["pass"], p["width"], p["stats"]["timing_s"]["total"])  # coarse, then full

From the command line:

    hpray_client.py URL TOKEN [--set key.path=value ...] [--out frame.png] [--npy rgba.npy]

prints the frame's stats as JSON and writes its PNG and/or premultiplied RGBA array.
"""
import argparse
import io
import json
import sys
import urllib.error
import urllib.request

import numpy as np


class ServiceError(RuntimeError):
    """An answer other than 200: its HTTP status and the service's message."""

    def __init__(self, status, message):
        super().__init__(f"HTTP {status}: {message}")
        self.status = status
        self.message = message


class Client:
    def __init__(self, url, token, timeout=600):
        self.url = url.rstrip("/")
        self.token = token
        self.timeout = timeout

    def _request(self, method, path, body=None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, method=method)
        req.add_header("Authorization", "Bearer " + self.token)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        with self._open(req) as answer:
            return answer.read()

    def _open(self, req):
        """urlopen, with an answer other than 200 raised as ServiceError."""
        try:
            return urllib.request.urlopen(req, timeout=self.timeout)
        except urllib.error.HTTPError as e:
            text = e.read().decode(errors="replace")
            try:
                text = json.loads(text).get("error", text)
            except ValueError:
                pass
            raise ServiceError(e.code, text) from None

    def info(self):
        """The loaded data (as `hpray info --json`) and the scene."""
        return json.loads(self._request("GET", "/api/info"))

    def render_frame(self, overrides=None):
        """Renders a frame; returns (frame id, stats)."""
        answer = json.loads(self._request("POST", "/api/render", overrides or {}))
        return answer["frame"], answer["stats"]

    def frame_file(self, frame, name):
        """The bytes of one output of a kept frame: image.png, image.exr, rgba.npy,
        hits.npy or errors.npy."""
        return self._request("GET", f"/api/frames/{frame}/{name}")

    def errors(self, frame):
        """A kept frame's error channels: float32 (H, W, 2), iso.residual (NaN where no
        isosurface is hit) and vol.error."""
        return np.load(io.BytesIO(self.frame_file(frame, "errors.npy")))

    def render_passes(self, overrides=None, passes=(8, 1)):
        """A progressive frame: yields each pass as it arrives, a dict with frame, pass,
        passes, scale, final, width, height and stats (README, "Progressive frames").
        Ends after the final pass, or early when a newer request cancelled the rest
        (then the generator's last value was not final)."""
        data = json.dumps(overrides or {}).encode()
        query = "?progressive=1&passes=" + ",".join(str(int(p)) for p in passes)
        req = urllib.request.Request(self.url + "/api/render" + query, data=data,
                                     method="POST")
        req.add_header("Authorization", "Bearer " + self.token)
        req.add_header("Content-Type", "application/json")
        with self._open(req) as answer:
            event = None
            for raw in answer:
                line = raw.decode().rstrip("\n")
                if line.startswith("event: "):
                    event = line[7:]
                elif line.startswith("data: ") and event:
                    payload = json.loads(line[6:])
                    if event == "pass":
                        yield payload
                    elif event == "error":
                        raise ServiceError(400, payload.get("error", ""))
                    elif event == "end":
                        return
                    event = None

    def render(self, overrides=None):
        """Renders a frame; returns (premultiplied RGBA float64 array (H, W, 4), stats)."""
        frame, stats = self.render_frame(overrides)
        rgba = np.load(io.BytesIO(self.frame_file(frame, "rgba.npy")))
        return rgba, stats

    def shutdown(self):
        self._request("POST", "/api/shutdown", {})


def _set_items_to_overrides(items):
    """`key.path=value` items (values in YAML/JSON flow syntax read as JSON where they
    parse, else as strings) as a nested dict."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"--set {item}: expected key.path=value")
        try:
            parsed = json.loads(value)
        except ValueError:
            parsed = value
        node = out
        parts = key.split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = parsed
    return out


def main(argv):
    ap = argparse.ArgumentParser(description="Render one frame with a running hpray serve.")
    ap.add_argument("url")
    ap.add_argument("token")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", help="write the frame's PNG here")
    ap.add_argument("--npy", help="write the premultiplied RGBA float64 array here")
    args = ap.parse_args(argv)
    client = Client(args.url, args.token)
    try:
        frame, stats = client.render_frame(_set_items_to_overrides(args.set))
        if args.out:
            with open(args.out, "wb") as f:
                f.write(client.frame_file(frame, "image.png"))
        if args.npy:
            with open(args.npy, "wb") as f:
                f.write(client.frame_file(frame, "rgba.npy"))
    except ServiceError as e:
        print(e, file=sys.stderr)
        return 2
    print(json.dumps(stats, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
