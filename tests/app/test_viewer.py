#!/usr/bin/env python3
"""Browser test of the viewer that `hpray serve` serves (src/app/viewer/).

Starts `hpray serve tests/data/viewer_scene.yaml --port 0`, opens the page in headless
Chromium with the token and, with real mouse and keyboard input, checks that:

- the first frame arrives, as progressive passes (a coarse one, then the final one);
- a left-drag on the frame orbits the camera: a new final frame arrives whose PNG (fetched
  from the API) differs from the first one's in many pixels;
- moving the isovalue slider renders the new isovalue: the body sent carries it and the
  frame's iso hit count changes;
- the error overlay draws errors.npy of the frame on screen: the overlay canvas is shown
  with opaque pixels exactly where the frame has error data, and the legend's log10
  minimum and maximum are those of the frame (recomputed here from errors.npy);
- a value the service refuses shows its message on the page, and the viewer goes on
  rendering once it is taken back;
- "reset view" brings the scene's camera back;
- another client's request cancels the passes still to come, and the page says so;

then saves a screenshot; opens the page once more through a proxy that drops
`?progressive=1`, as a service without progressive frames would, and checks that frames
still arrive, in one piece, and that orbiting still works; shuts the service down through /api/shutdown and checks that it
exits 0.

Then serves the same data with a volume that names only its field (the renderer's default
transfer functions) and checks that the viewer starts from the renderer's default: its
first frame is pixel for pixel `hpray render` of that scene; its editors show the transfer
functions the frame's stats report as rendered; switching the volume off and on again
sends no transfer function and gives the same picture; an edit sends both, starting from
the reported ones. Every wait has a deadline and the whole test stops after TOTAL_SECONDS.

    /usr/bin/python3 tests/app/test_viewer.py --hpray build/bin/hpray --screenshot shot.png
"""
import argparse
import base64
import http.server
import io
import json
import math
import os
import queue
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request

try:
    import numpy as np
except ImportError as error:
    sys.exit(f"test_viewer: cannot import numpy ({error}); install the Debian package "
             "python3-numpy and run this with /usr/bin/python3")

try:
    from selenium import webdriver
    from selenium.common.exceptions import TimeoutException, WebDriverException
    from selenium.webdriver.chrome.service import Service as ChromeService
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.select import Select
    from selenium.webdriver.support.ui import WebDriverWait
except ImportError as error:
    sys.exit(f"test_viewer: cannot import selenium ({error}); install the Debian packages "
             "chromium chromium-driver python3-selenium (scripts/test.sh does) and run this "
             "with /usr/bin/python3")

SCENE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data",
                     "viewer_scene.yaml")
CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
TOTAL_SECONDS = 120  # the whole test, whatever hangs
START_SECONDS = 30   # hpray serve's start-up line
FRAME_SECONDS = 20   # one interaction's final frame


class Failure(Exception):
    """A check that failed, in words."""


def check(condition, message):
    if not condition:
        raise Failure(message)


def on_alarm(signum, frame):
    raise Failure(f"the test did not finish within {TOTAL_SECONDS} s")


class HprayService:
    """hpray serve on the test scene: its URL and token, its requests, its end."""

    def __init__(self, hpray, log_path, scene=SCENE):
        self.log = open(log_path, "w")
        self.proc = subprocess.Popen([hpray, "serve", scene, "--port", "0"],
                                     stdout=subprocess.PIPE, stderr=self.log, text=True)
        lines = queue.Queue()
        threading.Thread(target=lambda: lines.put(self.proc.stdout.readline()),
                         daemon=True).start()
        try:
            line = lines.get(timeout=START_SECONDS)
        except queue.Empty:
            raise Failure(f"hpray serve printed no start-up line within {START_SECONDS} s "
                          f"(log: {log_path})")
        match = re.fullmatch(r"hpray serve: listening on (http://\S+/) token (\S+)\n?", line)
        check(match, f"unexpected start-up line {line!r} (log: {log_path})")
        self.url, self.token = match.group(1), match.group(2)

    def request(self, method, path, body=None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url.rstrip("/") + path, data=data, method=method)
        req.add_header("Authorization", "Bearer " + self.token)
        with urllib.request.urlopen(req, timeout=10) as answer:
            return answer.read()

    def shutdown(self):
        self.request("POST", "/api/shutdown", {})
        try:
            return self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            raise Failure("hpray serve did not exit within 15 s of /api/shutdown")

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)
        self.log.close()


class PlainProxy:
    """A service without progressive frames, on a port of its own: forwards every request
    to hpray serve without the `progressive` and `passes` query parameters."""

    def __init__(self, upstream):
        upstream = upstream.rstrip("/")

        class Handler(http.server.BaseHTTPRequestHandler):
            def forward(self):
                path, _, query = self.path.partition("?")
                kept = [p for p in query.split("&")
                        if p and not p.startswith(("progressive=", "passes="))]
                url = upstream + path + ("?" + "&".join(kept) if kept else "")
                length = int(self.headers.get("Content-Length") or 0)
                req = urllib.request.Request(url, data=self.rfile.read(length) if length else None,
                                             method=self.command)
                for name in ("Authorization", "Content-Type"):
                    if self.headers.get(name):
                        req.add_header(name, self.headers[name])
                try:
                    with urllib.request.urlopen(req, timeout=FRAME_SECONDS) as answer:
                        status, headers, body = answer.status, answer.headers, answer.read()
                except urllib.error.HTTPError as error:
                    status, headers, body = error.code, error.headers, error.read()
                self.send_response(status)
                self.send_header("Content-Type", headers.get("Content-Type", "text/plain"))
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            do_GET = do_POST = forward

            def log_message(self, *args):
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self):
        self.server.shutdown()
        self.server.server_close()


def start_browser():
    for path in (CHROMIUM, CHROMEDRIVER):
        check(os.path.exists(path), f"{path} is missing; install the Debian packages chromium "
                                    "chromium-driver python3-selenium (scripts/test.sh does)")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1200,800", "--force-device-scale-factor=1"):
        options.add_argument(arg)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=ChromeService(CHROMEDRIVER), options=options)
    # A viewport of 1200 x 800, whatever the window's own decorations take.
    driver.set_window_size(1200, 800)
    inner = driver.execute_script("return [window.innerWidth, window.innerHeight];")
    driver.set_window_size(1200 + 1200 - inner[0], 800 + 800 - inner[1])
    driver.set_page_load_timeout(20)
    driver.set_script_timeout(20)
    return driver


# The newest request's final frame is on screen and nothing is in flight: its frame id.
SETTLED_JS = """
const v = window.hprayViewer, img = document.getElementById('frame');
if (!v || v.busy || !img.complete || img.dataset.final !== 'true') return null;
if (Number(img.dataset.request) !== v.requestsSent || v.requestsSent <= arguments[0]) return null;
return Number(img.dataset.frame);
"""


def wait_settled(driver, after_request, what):
    """Waits for the final frame of a request sent after request number `after_request`."""
    try:
        return WebDriverWait(driver, FRAME_SECONDS, poll_frequency=0.05).until(
            lambda d: d.execute_script(SETTLED_JS, after_request))
    except TimeoutException:
        state = driver.execute_script(
            "const v = window.hprayViewer; return v && {busy: v.busy, frame: v.frame, "
            "final: v.final, requestsSent: v.requestsSent, request: v.request, error: v.error};")
        raise Failure(f"{what}: no final frame within {FRAME_SECONDS} s (viewer: {state})")


def viewer(driver, expression):
    return driver.execute_script(f"return window.hprayViewer.{expression};")


# Pixels of two PNGs (base64) that differ in R, G or B, decoded by the browser.
DIFF_JS = """
const [a, b, done] = arguments;
async function pixels(text) {
  const bytes = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
  const bitmap = await createImageBitmap(new Blob([bytes], {type: 'image/png'}));
  const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
  const ctx = canvas.getContext('2d');
  ctx.drawImage(bitmap, 0, 0);
  return ctx.getImageData(0, 0, bitmap.width, bitmap.height).data;
}
Promise.all([pixels(a), pixels(b)]).then(([p, q]) => {
  if (p.length !== q.length) return done({error: 'the images differ in size'});
  let differing = 0;
  for (let k = 0; k < p.length; k += 4)
    if (p[k] !== q[k] || p[k + 1] !== q[k + 1] || p[k + 2] !== q[k + 2]) ++differing;
  done({differing, total: p.length / 4});
}).catch((e) => done({error: String(e)}));
"""

# The overlay canvas: its size, whether it is shown, and its pixels with alpha > 0.
OVERLAY_JS = """
const c = document.getElementById('overlay');
const data = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
let opaque = 0;
for (let k = 3; k < data.length; k += 4) if (data[k] > 0) ++opaque;
const r = c.getBoundingClientRect();
return {width: c.width, height: c.height, opaque, hidden: c.hidden,
        shownWidth: r.width, shownHeight: r.height, opacity: getComputedStyle(c).opacity};
"""


def png(service, frame):
    return service.request("GET", f"/api/frames/{frame}/image.png")


def scroll_to(driver, element):
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'});", element)


def type_into(driver, box_id, text):
    """Replaces what an input box holds by `text`, as typed, and presses Enter."""
    box = driver.find_element(By.ID, box_id)
    scroll_to(driver, box)
    box.send_keys(Keys.CONTROL, "a")
    box.send_keys(text, Keys.ENTER)


def run(args, service, driver):
    driver.get(f"{service.url}?token={service.token}")

    # The first frame, as progressive passes.
    first = wait_settled(driver, 0, "first frame")
    first_png = png(service, first)
    passes = viewer(driver, "passLog")
    check(viewer(driver, "streaming") is True,
          "the service did not answer /api/render?progressive=1 with an event stream")
    check(any(p["scale"] > 1 for p in passes) and passes[-1]["final"],
          f"expected a coarse pass, then the final one; passes received: {passes}")
    width, height = driver.execute_script(
        "const i = document.getElementById('frame'); return [i.naturalWidth, i.naturalHeight];")
    check((width, height) == (256, 256), f"the final frame is {width}x{height}, not 256x256")
    position = viewer(driver, "camera.position")

    # Orbit: a left-drag on the frame.
    image = driver.find_element(By.ID, "frame")
    sent = viewer(driver, "requestsSent")
    drag = ActionChains(driver, duration=30).move_to_element(image).click_and_hold()
    for _ in range(6):
        drag.move_by_offset(18, 3)
    drag.release().perform()
    orbited = wait_settled(driver, sent, "orbit")
    check(orbited > first, f"orbit: frame {orbited} is not newer than frame {first}")
    moved = viewer(driver, "camera.position")
    check(math.dist(position, moved) > 0.1, f"orbit: the camera stayed at {position} ({moved})")
    diff = driver.execute_async_script(
        DIFF_JS, base64.b64encode(first_png).decode(),
        base64.b64encode(png(service, orbited)).decode())
    check("error" not in diff, f"orbit: comparing the frames' PNGs failed: {diff}")
    check(diff["differing"] > 0.05 * diff["total"],
          f"orbit: frames {first} and {orbited} differ in only {diff['differing']} of "
          f"{diff['total']} pixels")

    # The isovalue slider: a click on it (input events), then the frame of that value.
    hits_before = viewer(driver, "stats.iso.hits")
    slider = driver.find_element(By.ID, "iso-value")
    scroll_to(driver, slider)
    sent = viewer(driver, "requestsSent")
    ActionChains(driver).move_to_element_with_offset(
        slider, int(slider.size["width"] * 0.3), 0).click().perform()
    wait_settled(driver, sent, "isovalue slider")
    value = float(driver.find_element(By.ID, "iso-value-number").get_attribute("value"))
    check(abs(value) > 0.05, f"isovalue slider: the value box still shows {value}")
    body_value = viewer(driver, "lastBody.isosurfaces[0].value")
    check(body_value == value, f"isovalue slider: sent {body_value}, the box shows {value}")
    hits_after = viewer(driver, "stats.iso.hits")
    check(hits_after != hits_before,
          f"isovalue slider: the hit count stayed {hits_before} at isovalue {value}")

    # Error overlay of the frame on screen.
    toggle = driver.find_element(By.ID, "overlay-toggle")
    toggle.click()
    try:
        WebDriverWait(driver, FRAME_SECONDS, poll_frequency=0.05).until(lambda d: d.execute_script(
            "const v = window.hprayViewer; return v.overlay.frame === v.frame && v.overlay.pixels > 0;"))
    except TimeoutException:
        note = driver.find_element(By.ID, "legend-note").text
        raise Failure(f"error overlay: not drawn within {FRAME_SECONDS} s ({note!r})")
    shown = driver.execute_script(OVERLAY_JS)
    check(not shown["hidden"] and driver.find_element(By.ID, "overlay").is_displayed(),
          f"error overlay: the canvas is hidden ({shown})")
    check(shown["shownWidth"] > 300 and float(shown["opacity"]) > 0,
          f"error overlay: not shown over the frame ({shown})")
    frame = viewer(driver, "frame")
    errors = np.load(io.BytesIO(service.request("GET", f"/api/frames/{frame}/errors.npy")))
    check(errors.shape == (shown["height"], shown["width"], 2),
          f"error overlay: canvas {shown['width']}x{shown['height']}, errors.npy {errors.shape}")
    # The default channel: the larger of residual / field range and vol.error, where > 0.
    span = np.subtract(*viewer(driver, "stats.iso.field_range")[::-1])
    with np.errstate(invalid="ignore", divide="ignore"):
        residual = np.where(errors[..., 0] > 0, errors[..., 0] / span, np.nan)
        volume = np.where(errors[..., 1] > 0, errors[..., 1], np.nan)
        combined = np.fmax(residual, volume).astype(np.float64)
    valid = np.isfinite(combined)
    check(shown["opaque"] == int(valid.sum()) > 0,
          f"error overlay: {shown['opaque']} opaque pixels, errors.npy has data in "
          f"{int(valid.sum())}")
    legend = driver.find_element(By.ID, "legend")
    check(legend.is_displayed(), "error overlay: the legend is hidden")
    texts = [driver.find_element(By.ID, i).text for i in ("legend-min", "legend-max")]
    try:
        low, high = (float(t) for t in texts)
    except ValueError:
        raise Failure(f"error overlay: legend min/max are not numbers: {texts}")
    logs = np.log10(combined[valid])
    check(abs(low - logs.min()) < 0.006 and abs(high - logs.max()) < 0.006,
          f"error overlay: legend {low}..{high}, errors.npy gives "
          f"{logs.min():.3f}..{logs.max():.3f}")

    # A value the service refuses: its message on the page; then the viewer goes on.
    extra = driver.find_element(By.ID, "extra-keys")
    scroll_to(driver, extra)
    driver.execute_script("arguments[0].closest('details').open = true;", extra)
    extra.send_keys('{"accuracy": {"volume_tolerance": -1}}')
    sent = viewer(driver, "requestsSent")
    driver.find_element(By.ID, "extra-apply").click()
    message = driver.find_element(By.ID, "message")
    try:
        WebDriverWait(driver, FRAME_SECONDS, poll_frequency=0.05).until(
            lambda d: message.is_displayed() and "volume_tolerance" in message.text)
    except TimeoutException:
        raise Failure(f"refused value: no message naming volume_tolerance on the page "
                      f"(message {message.text!r}, shown {message.is_displayed()})")
    check(viewer(driver, "requestsSent") == sent + 1, "refused value: no request sent")
    driver.find_element(By.ID, "extra-clear").click()
    recovered = wait_settled(driver, sent + 1, "after the refused value")
    check(recovered > frame, f"after the refused value: frame {recovered} is not new")
    check(not message.is_displayed(), "after the refused value: the message is still shown")

    # "reset view" brings the scene's camera back.
    sent = viewer(driver, "requestsSent")
    driver.find_element(By.ID, "reset-view").click()
    wait_settled(driver, sent, "reset view")
    check(math.dist(viewer(driver, "camera.position"), position) < 1e-9,
          f"reset view: the camera is at {viewer(driver, 'camera.position')}, not {position}")

    # Another client's request cancels the passes still to come: a wide frame's coarse pass
    # is on screen when a plain request arrives, and the page says its view was cancelled.
    sent = viewer(driver, "requestsSent")
    type_into(driver, "cam-width", "2048")
    try:
        WebDriverWait(driver, FRAME_SECONDS, poll_frequency=0.02).until(lambda d: d.execute_script(
            "const i = document.getElementById('frame');"
            "return Number(i.dataset.request) > arguments[0] && i.dataset.pass === '0';", sent))
    except TimeoutException:
        raise Failure("cancellation: the coarse pass of the 2048-wide frame was not shown")
    service.request("POST", "/api/render", {})
    try:
        WebDriverWait(driver, FRAME_SECONDS, poll_frequency=0.05).until(
            lambda d: "cancelled" in d.find_element(By.ID, "status").text and
            d.find_element(By.ID, "render-again").is_displayed())
    except TimeoutException:
        raise Failure(f"cancellation: the status line says "
                      f"{driver.find_element(By.ID, 'status').text!r}, not cancelled")
    check(driver.find_element(By.ID, "frame").get_attribute("data-cancelled") == "true" and
          driver.find_element(By.ID, "frame").get_attribute("data-final") == "false",
          "cancellation: the frame's data-cancelled/data-final attributes disagree")

    # The screenshot: the zero isosurface typed in, 480 x 480, the overlay of its residual.
    sent = viewer(driver, "requestsSent")
    for box_id, text in (("iso-value-number", "0"), ("cam-width", "480"), ("cam-height", "480")):
        type_into(driver, box_id, text)
    Select(driver.find_element(By.ID, "overlay-channel")).select_by_value("residual")
    wait_settled(driver, sent, "isovalue and size typed in")
    body = viewer(driver, "lastBody")
    check(body["isosurfaces"][0]["value"] == 0 and body["camera"]["width"] == 480 and
          body["camera"]["height"] == 480, f"typed values not sent: {body}")
    try:
        WebDriverWait(driver, FRAME_SECONDS, poll_frequency=0.05).until(lambda d: d.execute_script(
            "const v = window.hprayViewer; return v.overlay.frame === v.frame && "
            "v.overlay.channel === 'residual' && v.overlay.pixels > 0;"))
    except TimeoutException:
        raise Failure("residual overlay: not drawn for the frame on screen")
    check("iso.residual" in driver.find_element(By.ID, "legend-title").text,
          "residual overlay: the legend does not name iso.residual")
    driver.execute_script("document.getElementById('stats-table').closest('details').scrollIntoView();")
    check(driver.save_screenshot(args.screenshot), f"cannot write {args.screenshot}")

    # A service without progressive frames: the plain answer, one final frame a request.
    proxy = PlainProxy(service.url)
    try:
        driver.get(f"{proxy.url}?token={service.token}")
        plain = wait_settled(driver, 0, "first frame without progressive frames")
        check(viewer(driver, "streaming") is False,
              "without progressive frames: the viewer did not take the plain answer")
        passes = viewer(driver, "passLog")
        check(passes == [{"request": 1, "frame": plain, "pass": 0, "passes": 1, "scale": 1,
                          "final": True}], f"without progressive frames: passes {passes}")
        sent = viewer(driver, "requestsSent")
        ActionChains(driver, duration=30).move_to_element(
            driver.find_element(By.ID, "frame")).click_and_hold().move_by_offset(
            -60, 0).release().perform()
        orbited = wait_settled(driver, sent, "orbit without progressive frames")
        check(orbited > plain, "without progressive frames: orbiting rendered no new frame")
    finally:
        proxy.close()


# The viewer scene's data and camera with a volume that names only its field: viridis over
# the field's range and an extinction ramp up to 10 / the data's diagonal, resolved by the
# renderer (docs/scene.md).
DEFAULT_VOLUME_SCENE = """\
data: {mesh: "builtin:nk-sinc?order=4"}
camera: {position: [2.2, 1.6, 2.6], look_at: [0.5, 0.5, 0.5], up: [0, 1, 0], fov_y: 30,
         width: 160, height: 160}
volume: {color_field: u}
background: [1, 1, 1]
accuracy: {volume_tolerance: 1e-6}
"""


def same_pixels(driver, a, b, what):
    diff = driver.execute_async_script(DIFF_JS, base64.b64encode(a).decode(),
                                       base64.b64encode(b).decode())
    check("error" not in diff, f"{what}: comparing the PNGs failed: {diff}")
    check(diff["differing"] == 0,
          f"{what}: {diff['differing']} of {diff['total']} pixels differ")


def run_default_volume(args, tmp, driver):
    """The viewer on a scene whose volume gives only its field."""
    scene = os.path.join(tmp, "default_volume.yaml")
    with open(scene, "w") as out:
        out.write(DEFAULT_VOLUME_SCENE)
    reference = os.path.join(tmp, "default_volume.png")
    subprocess.run([args.hpray, "-q", "render", scene, "--set", f"output.png={reference}"],
                   check=True, timeout=FRAME_SECONDS)
    with open(reference, "rb") as f:
        reference_png = f.read()
    service = HprayService(args.hpray, os.path.join(tmp, "serve_default_volume.log"), scene)
    try:
        driver.get(f"{service.url}?token={service.token}")
        first = wait_settled(driver, 0, "default volume: first frame")
        same_pixels(driver, png(service, first), reference_png,
                    "default volume: the first frame against hpray render")
        # The volume off and on again: its keys are sent, without transfer functions.
        enabled = driver.find_element(By.ID, "vol-enabled")
        scroll_to(driver, enabled)
        sent = viewer(driver, "requestsSent")
        enabled.click()
        wait_settled(driver, sent, "default volume: switched off")
        check(viewer(driver, "lastBody.volume") is None,
              f"default volume: switched off, the body sends {viewer(driver, 'lastBody.volume')}")
        sent = viewer(driver, "requestsSent")
        enabled.click()
        again = wait_settled(driver, sent, "default volume: switched on again")
        body = viewer(driver, "lastBody.volume")
        check(body == {"color_field": "u", "extinction_field": "u", "glow": "williams-max"},
              f"default volume: switched on again, the body sends {body}")
        same_pixels(driver, png(service, again), reference_png,
                    "default volume: switched on again, against hpray render")
        # The editors show what was rendered: the stats' transfer functions.
        stats = viewer(driver, "stats.volume")
        check(len(stats["color_tf"]) > 8 and len(stats["extinction_tf"]) == 2,
              f"default volume: the stats report {stats}")
        shown = viewer(driver, "volume")
        check(shown is not None, "default volume: the viewer has no volume panel state")
        check(shown["resolved"] == {"color": True, "extinction": True},
              f"default volume: the panel does not keep the renderer's own ({shown['resolved']})")
        check([[p["s"], *p["rgb"]] for p in shown["colorStops"]] == stats["color_tf"] and
              [[p["s"], p["e"]] for p in shown["extinction"]] == stats["extinction_tf"],
              "default volume: the editors do not show the transfer functions rendered")
        # An edit: both transfer functions are sent, the reported ones with the edit.
        sigma = driver.find_element(By.ID, "tf-ext-sigma")
        driver.execute_script("arguments[0].closest('details').open = true;", sigma)
        sent = viewer(driver, "requestsSent")
        type_into(driver, "tf-ext-sigma", "1.5")
        wait_settled(driver, sent, "default volume: an extinction edited")
        body = viewer(driver, "lastBody.volume")
        check(body.get("extinction_tf") == [[stats["extinction_tf"][0][0], 1.5],
                                            stats["extinction_tf"][1]],
              f"default volume: edited, the extinction sent is {body.get('extinction_tf')}")
        sent_colors = body.get("color_tf") or []
        check(len(sent_colors) == len(stats["color_tf"]) and
              all(abs(a - b) <= 1e-5 * max(1, abs(b))
                  for p, q in zip(sent_colors, stats["color_tf"]) for a, b in zip(p, q)),
              f"default volume: edited, the colours sent are not those rendered: {sent_colors}")
        code = service.shutdown()
        check(code == 0, f"hpray serve (default volume) exited {code} after /api/shutdown")
    finally:
        service.kill()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hpray", required=True, help="the hpray executable")
    parser.add_argument("--screenshot", required=True, help="where to save a PNG of the page")
    args = parser.parse_args()
    signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(TOTAL_SECONDS)
    log_path = os.path.join(tempfile.gettempdir(), f"test_viewer_serve_{os.getpid()}.log")
    service = driver = None
    try:
        service = HprayService(args.hpray, log_path)
        try:
            driver = start_browser()
        except WebDriverException as error:
            raise Failure(f"cannot start headless Chromium through {CHROMEDRIVER}: {error.msg}")
        run(args, service, driver)
        code = service.shutdown()
        check(code == 0, f"hpray serve exited {code} after /api/shutdown (log: {log_path})")
        with tempfile.TemporaryDirectory(prefix="test_viewer_") as tmp:
            run_default_volume(args, tmp, driver)
    except (Failure, WebDriverException, urllib.error.URLError) as error:
        print(f"FAILED: {error}", file=sys.stderr)
        if driver is not None:
            try:
                for entry in driver.get_log("browser")[-20:]:
                    print(f"  browser: {entry['level']} {entry['message']}", file=sys.stderr)
            except WebDriverException:
                pass
        if os.path.exists(log_path):
            with open(log_path) as log:
                for line in log.read().splitlines()[-20:]:
                    print(f"  hpray serve: {line}", file=sys.stderr)
        return 1
    finally:
        signal.alarm(0)
        if driver is not None:
            driver.quit()
        if service is not None:
            service.kill()
    print(f"viewer test passed; screenshot {args.screenshot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
