// The hpray viewer: drives `hpray serve` (README, "The rendering service") from the
// browser. Every change of the view or of a panel asks for one progressive frame; its
// passes are shown as they arrive (coarse ones scaled up in place), with the frame's
// stats and, on request, a heat map of its per-pixel error channels (errors.npy).
// Scene keys and their formats are those of docs/contracts.md.
//
// State for scripts and tests: window.hprayViewer (see `view` below) and the data-*
// attributes of the frame image (#frame).

const $ = (id) => document.getElementById(id);

// ---------------------------------------------------------------------------------------
// Service access

const token = new URLSearchParams(location.search).get('token') || '';
/** The scale divisors of a frame's passes: a coarse one at 1/8 of the size, then the full. */
const PASSES = '8,1';

/** fetch() of an /api/ path, with the token in the Authorization header. */
function api(path, options = {}) {
  const headers = {Authorization: `Bearer ${token}`, ...(options.headers || {})};
  return fetch(path, {...options, headers});
}

/** The message of a failed answer: the service's {"error": ...}, else the status. */
async function failureText(response) {
  const text = await response.text().catch(() => '');
  try {
    const body = JSON.parse(text);
    if (body && typeof body.error === 'string') return body.error;
  } catch (e) {
    // Not JSON: reported as text below.
  }
  return `HTTP ${response.status} ${response.statusText}${text ? ': ' + text : ''}`;
}

/**
 * The events of a Server-Sent Events body, as {event, data} (data lines joined by "\n").
 * Comment lines (":") are skipped; events are separated by a blank line.
 */
async function* serverSentEvents(body) {
  const reader = body.getReader();
  const decoder = new TextDecoder();
  let buffer = '';
  try {
    while (true) {
      const {value, done} = await reader.read();
      if (done) return;
      buffer = (buffer + decoder.decode(value, {stream: true})).replace(/\r\n/g, '\n');
      let end;
      while ((end = buffer.indexOf('\n\n')) >= 0) {
        const block = buffer.slice(0, end);
        buffer = buffer.slice(end + 2);
        let event = 'message';
        const data = [];
        for (const line of block.split('\n')) {
          if (line === '' || line.startsWith(':')) continue;
          const colon = line.indexOf(':');
          const field = colon < 0 ? line : line.slice(0, colon);
          let text = colon < 0 ? '' : line.slice(colon + 1);
          if (text.startsWith(' ')) text = text.slice(1);
          if (field === 'event') event = text;
          else if (field === 'data') data.push(text);
        }
        if (data.length) yield {event, data: data.join('\n')};
      }
    }
  } finally {
    reader.releaseLock();
  }
}

/**
 * A NumPy .npy file (versions 1 to 3, C order, float32 or float64 of either byte order)
 * as {shape, data}, data a Float32Array or Float64Array in C order.
 */
function parseNpy(buffer) {
  const bytes = new Uint8Array(buffer);
  const magic = [0x93, 0x4e, 0x55, 0x4d, 0x50, 0x59];  // "\x93NUMPY"
  if (bytes.length < 10 || magic.some((b, i) => bytes[i] !== b)) throw new Error('not a .npy file');
  const dv = new DataView(buffer);
  const major = bytes[6];
  const headerStart = major === 1 ? 10 : 12;
  const headerLength = major === 1 ? dv.getUint16(8, true) : dv.getUint32(8, true);
  const header = new TextDecoder('latin1').decode(bytes.subarray(headerStart, headerStart + headerLength));
  const descr = /'descr'\s*:\s*'([^']*)'/.exec(header);
  const shapeText = /'shape'\s*:\s*\(([^)]*)\)/.exec(header);
  if (!descr || !shapeText) throw new Error(`.npy header without descr or shape: ${header}`);
  if (/'fortran_order'\s*:\s*True/.test(header)) throw new Error('.npy in Fortran order');
  const shape = shapeText[1].split(',').map((s) => s.trim()).filter((s) => s).map(Number);
  const count = shape.reduce((a, b) => a * b, 1);
  const littleEndian = descr[1][0] !== '>';
  const kind = descr[1].replace(/^[<>=|]/, '');
  const size = {f4: 4, f8: 8}[kind];
  if (!size) throw new Error(`.npy of type ${descr[1]}: expected float32 or float64`);
  const offset = headerStart + headerLength;
  if (buffer.byteLength < offset + count * size) throw new Error('.npy file shorter than its shape');
  const data = size === 4 ? new Float32Array(count) : new Float64Array(count);
  for (let k = 0; k < count; ++k) {
    data[k] = size === 4 ? dv.getFloat32(offset + 4 * k, littleEndian)
                         : dv.getFloat64(offset + 8 * k, littleEndian);
  }
  return {shape, data};
}

// ---------------------------------------------------------------------------------------
// Vectors, colours, numbers

const vec = {
  add: (a, b) => a.map((x, i) => x + b[i]),
  sub: (a, b) => a.map((x, i) => x - b[i]),
  scale: (a, s) => a.map((x) => x * s),
  dot: (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
  cross: (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]],
  length: (a) => Math.hypot(a[0], a[1], a[2]),
  normalize: (a) => vec.scale(a, 1 / (vec.length(a) || 1)),
  /** `v` rotated by `angle` (radians) about the unit vector `axis` (Rodrigues). */
  rotate(v, axis, angle) {
    const c = Math.cos(angle), s = Math.sin(angle);
    const term = vec.scale(axis, vec.dot(axis, v) * (1 - c));
    return vec.add(vec.add(vec.scale(v, c), vec.scale(vec.cross(axis, v), s)), term);
  },
  /** A unit vector perpendicular to the unit vector `a`. */
  perpendicular(a) {
    const other = Math.abs(a[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
    return vec.normalize(vec.cross(a, other));
  },
};

const clamp = (x, lo, hi) => Math.min(hi, Math.max(lo, x));
const isObject = (x) => x !== null && typeof x === 'object' && !Array.isArray(x);
const deepCopy = (x) => (x === undefined ? undefined : JSON.parse(JSON.stringify(x)));
/** `x` rounded to 6 significant digits, for values typed or picked in the panels. */
const tidy = (x) => Number(x.toPrecision(6));

/** `over` merged into `base` as the service merges a request: objects recursively,
 *  anything else (lists, scalars, null) replaces. Returns `base`. */
function mergeKeys(base, over) {
  for (const [key, value] of Object.entries(over)) {
    if (isObject(value) && isObject(base[key])) mergeKeys(base[key], value);
    else base[key] = deepCopy(value);
  }
  return base;
}

/** A number for the stats table and the status line. */
function formatNumber(v, digits = 4) {
  if (typeof v !== 'number') return v === undefined || v === null ? '–' : String(v);
  if (!Number.isFinite(v)) return String(v);
  if (Number.isInteger(v) && Math.abs(v) < 1e15) return v.toLocaleString('en-US');
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-3 || a >= 1e6)) return v.toExponential(digits - 1);
  return String(Number(v.toPrecision(digits)));
}

function formatSeconds(s) {
  if (typeof s !== 'number') return '–';
  return s < 0.1 ? `${(s * 1000).toFixed(1)} ms` : `${s.toFixed(3)} s`;
}

// Scene colours are linear RGB; colour inputs and CSS are sRGB.
const linearToSrgb = (c) => {
  c = clamp(c, 0, 1);
  return c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055;
};
const srgbToLinear = (c) => (c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4));
const linearToHex = (rgb) =>
  '#' + rgb.map((c) => Math.round(linearToSrgb(c) * 255).toString(16).padStart(2, '0')).join('');
const hexToLinear = (hex) =>
  [1, 3, 5].map((i) => tidy(srgbToLinear(parseInt(hex.slice(i, i + 2), 16) / 255)));
const linearToCss = (rgb, alpha = 1) =>
  `rgba(${rgb.map((c) => Math.round(linearToSrgb(c) * 255)).join(',')},${alpha})`;

/** Viridis, sampled at 9 points: the heat map of the error overlay (low dark, high yellow). */
const VIRIDIS = [[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
                 [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]];
function viridis(t) {
  const x = clamp(t, 0, 1) * (VIRIDIS.length - 1);
  const i = Math.min(Math.floor(x), VIRIDIS.length - 2), f = x - i;
  return VIRIDIS[i].map((c, k) => Math.round(c + f * (VIRIDIS[i + 1][k] - c)));
}

/** A piecewise linear transfer function [{s, rgb}] at `s`, clamped at its ends. */
function sampleColor(stops, s) {
  if (s <= stops[0].s) return stops[0].rgb;
  const last = stops[stops.length - 1];
  if (s >= last.s) return last.rgb;
  let i = 1;
  while (stops[i].s < s) ++i;
  const a = stops[i - 1], b = stops[i], f = (s - a.s) / (b.s - a.s);
  return a.rgb.map((c, k) => c + f * (b.rgb[k] - c));
}

/** Maps the scalars of `points` from the range `from` to the range `to`, in place. */
function rescalePoints(points, from, to) {
  const f = (to[1] - to[0]) / (from[1] - from[0] || 1);
  for (const p of points) p.s = tidy(to[0] + (p.s - from[0]) * f);
}

// ---------------------------------------------------------------------------------------
// Viewer state

/** What scripts and tests may read (window.hprayViewer). */
const view = {
  info: null,         // /api/info
  scene: null,        // the service's scene (the file with its --set items)
  camera: null,       // the current camera keys
  stats: null,        // stats of the frame on screen
  frame: null,        // id of the frame on screen
  pass: null,         // its pass index (0-based) and the request's number of passes
  passes: null,
  scale: null,        // its scale divisor (1: full size)
  final: false,       // whether it is the request's last pass
  cancelled: false,   // whether its request was cancelled by a newer one (any client)
  request: 0,         // the viewer's number of the request it belongs to
  requestsSent: 0,    // requests sent so far (the newest one's number)
  busy: false,        // a request in flight or waiting
  streaming: null,    // whether the service answered progressively (null: not asked yet)
  passLog: [],        // the last passes received: {request, frame, pass, passes, scale, final}
  lastBody: null,     // the body of the newest request
  volume: null,       // the volume panel: field, glow, colorStops, extinction, and which
                      // transfer functions are the renderer's own (`resolved`, not sent)
  error: null,        // the message on screen, if any
  overlay: {enabled: false, channel: 'combined', frame: null, min: null, max: null, pixels: 0},
};
window.hprayViewer = view;

let info = null;
let scene = null;
let camera = null;
let homeCamera = null;
let pointFields = [];
let bounds = [[0, 0, 0], [1, 1, 1]];
/** Panels the user has changed: only their keys are sent, the scene's stand otherwise. */
const touched = new Set();
/** The "More scene keys" object, merged over everything else. */
let extraKeys = {};

/** Marks a panel changed and asks for a frame. */
function touch(panel) {
  touched.add(panel);
  requestFrame();
}

// ---------------------------------------------------------------------------------------
// Messages: the service's errors, shown over the view until a newer frame arrives

let messageRequest = 0;

function showMessage(text, request = flight.seq) {
  $('message-text').textContent = text;
  $('message').hidden = false;
  view.error = text;
  messageRequest = request;
}

function clearMessage() {
  $('message').hidden = true;
  view.error = null;
}

// ---------------------------------------------------------------------------------------
// The scene as the service holds it, and the fields

/** `scene` with the service's --set items ("a.b.0.c=VALUE", VALUE in YAML flow syntax,
 *  read here as JSON where it parses, else as a number or a string) applied. */
function applySetItems(sceneIn, items) {
  const out = deepCopy(sceneIn) || {};
  for (const item of items || []) {
    const at = item.indexOf('=');
    if (at < 0) continue;
    const path = item.slice(0, at).split('.');
    const text = item.slice(at + 1).trim();
    let value;
    try {
      value = JSON.parse(text);
    } catch (e) {
      value = text === '~' ? null : text !== '' && Number.isFinite(Number(text)) ? Number(text) : text;
    }
    let node = out;
    for (let k = 0; k + 1 < path.length; ++k) {
      const key = path[k];
      if (!isObject(node[key]) && !Array.isArray(node[key])) node[key] = /^\d+$/.test(path[k + 1]) ? [] : {};
      node = node[key];
    }
    const last = path[path.length - 1];
    if (value === null) delete node[last];
    else node[last] = value;
  }
  return out;
}

/** Names a panel may pick: point fields, vector fields as their components name[i]. */
function listPointFields() {
  const names = [];
  for (const [name, f] of Object.entries(info.data.fields || {})) {
    if (f.association !== 'point') continue;
    const n = f.components || 1;
    if (n === 1) names.push(name);
    else for (let c = 0; c < n; ++c) names.push(`${name}[${c}]`);
  }
  return names;
}

/** The value range of a field or of a component name[i] (`component_ranges` of /api/info,
 *  else the field's range); never empty. */
function fieldRange(name) {
  const match = /^(.*)\[(\d+)\]$/.exec(name);
  const f = (info.data.fields || {})[match ? match[1] : name];
  const r = f && (match && f.component_ranges ? f.component_ranges[Number(match[2])] : f.range);
  if (!r || !Number.isFinite(r[0]) || !Number.isFinite(r[1])) return [0, 1];
  return r[1] > r[0] ? [r[0], r[1]] : [r[0] - 0.5, r[0] + 0.5];
}

/** Fills a <select> with the point fields, `current` selected (added if missing). */
function fillFieldSelect(select, current) {
  select.replaceChildren();
  const names = pointFields.includes(current) || current === undefined ? pointFields : [current, ...pointFields];
  for (const name of names) select.add(new Option(name, name));
  select.value = current;
}

/** Sets a range input and its number box to span `range` and show `value`. */
function setSlider(slider, box, range, value) {
  const lo = Math.min(range[0], value), hi = Math.max(range[1], value);
  slider.min = lo;
  slider.max = hi;
  slider.step = (hi - lo) / 1000;
  slider.value = value;
  if (box) {
    box.value = tidy(value);
    box.step = 'any';
  }
}

// ---------------------------------------------------------------------------------------
// Camera: orbit (turntable about `up`), pan, dolly

const MAX_ELEVATION = (85 * Math.PI) / 180;

/** The scene's camera, or a view of the data's bounds for what it leaves out. */
function initialCamera(sceneCamera) {
  const c = sceneCamera || {};
  const cam = {up: c.up || [0, 1, 0], width: c.width || 512, height: c.height || 512};
  if (c.ortho_height !== undefined) cam.ortho_height = c.ortho_height;
  else cam.fov_y = c.fov_y || 30;
  const centre = vec.scale(vec.add(bounds[0], bounds[1]), 0.5);
  const radius = 0.5 * vec.length(vec.sub(bounds[1], bounds[0])) || 1;
  cam.look_at = c.look_at || centre;
  if (c.position && vec.length(vec.sub(c.position, cam.look_at)) > 0) {
    cam.position = c.position;
  } else {
    // Look from 25 degrees above the horizontal plane, far enough to see the whole box.
    const up = vec.normalize(cam.up);
    const h1 = vec.perpendicular(up), h2 = vec.cross(up, h1);
    const az = Math.PI / 5, el = (25 * Math.PI) / 180;
    const dir = vec.add(vec.scale(vec.add(vec.scale(h1, Math.cos(az)), vec.scale(h2, Math.sin(az))),
                                  Math.cos(el)), vec.scale(up, Math.sin(el)));
    const fov = ((cam.fov_y || 30) * Math.PI) / 180;
    const distance = cam.ortho_height !== undefined ? 3 * radius : (1.1 * radius) / Math.sin(fov / 2);
    cam.position = vec.add(cam.look_at, vec.scale(dir, distance));
  }
  return cam;
}

/** The camera's unit forward, right and true up vectors (docs/contracts.md, Camera). */
function cameraBasis(cam) {
  const forward = vec.normalize(vec.sub(cam.look_at, cam.position));
  const right = vec.normalize(vec.cross(forward, cam.up));
  return {forward, right, trueUp: vec.cross(right, forward)};
}

/** Turns the camera about the look-at point: `azimuth` about `up`, `elevation` towards it,
 *  the elevation kept within MAX_ELEVATION of the horizontal plane. */
function orbit(cam, azimuth, elevation) {
  const up = vec.normalize(cam.up);
  let offset = vec.rotate(vec.sub(cam.position, cam.look_at), up, azimuth);
  const r = vec.length(offset);
  const current = Math.asin(clamp(vec.dot(offset, up) / r, -1, 1));
  const target = clamp(current + elevation, -MAX_ELEVATION, MAX_ELEVATION);
  let horizontal = vec.sub(offset, vec.scale(up, vec.dot(offset, up)));
  horizontal = vec.length(horizontal) > 1e-12 * r ? vec.normalize(horizontal) : vec.perpendicular(up);
  offset = vec.add(vec.scale(horizontal, r * Math.cos(target)), vec.scale(up, r * Math.sin(target)));
  cam.position = vec.add(cam.look_at, offset);
}

/** World size of one screen pixel at the look-at point, for a view `pixels` high. */
function worldPerPixel(cam, pixels) {
  if (cam.ortho_height !== undefined) return cam.ortho_height / pixels;
  const distance = vec.length(vec.sub(cam.look_at, cam.position));
  return (2 * distance * Math.tan((cam.fov_y * Math.PI) / 360)) / pixels;
}

/** Moves camera and look-at point so that the scene follows a drag of (dx, dy) pixels. */
function pan(cam, dx, dy, viewHeight) {
  const {right, trueUp} = cameraBasis(cam);
  const s = worldPerPixel(cam, viewHeight);
  const delta = vec.add(vec.scale(right, -dx * s), vec.scale(trueUp, dy * s));
  cam.position = vec.add(cam.position, delta);
  cam.look_at = vec.add(cam.look_at, delta);
}

/** Multiplies the distance to the look-at point (orthographic: the view height) by `factor`. */
function dolly(cam, factor) {
  if (cam.ortho_height !== undefined) {
    cam.ortho_height = tidy(cam.ortho_height * factor);
    return;
  }
  const offset = vec.sub(cam.position, cam.look_at);
  const minimum = 1e-4 * (vec.length(vec.sub(bounds[1], bounds[0])) || 1);
  const r = Math.max(vec.length(offset) * factor, minimum);
  cam.position = vec.add(cam.look_at, vec.scale(vec.normalize(offset), r));
}

function cameraKeys() {
  const keys = {position: camera.position, look_at: camera.look_at, up: camera.up,
                width: camera.width, height: camera.height};
  if (camera.ortho_height !== undefined) keys.ortho_height = camera.ortho_height;
  else keys.fov_y = camera.fov_y;
  return keys;
}

function showCamera() {
  const lens = camera.ortho_height !== undefined ? 'ortho_height' : 'fov_y';
  $('cam-fov-label').textContent = lens === 'fov_y' ? 'fov y (°)' : 'ortho height';
  $('cam-fov').value = camera[lens];
  $('cam-width').value = camera.width;
  $('cam-height').value = camera.height;
  const p = (v) => `[${v.map((x) => x.toFixed(3)).join(', ')}]`;
  $('cam-readout').textContent = `position ${p(camera.position)}\nlook_at  ${p(camera.look_at)}`;
}

function setupCameraPanel() {
  const lens = () => (camera.ortho_height !== undefined ? 'ortho_height' : 'fov_y');
  // Any number goes to the service, which answers values out of range with a message;
  // an empty box is put back.
  $('cam-fov').addEventListener('change', (e) => {
    if (!Number.isFinite(e.target.valueAsNumber)) return showCamera();
    camera[lens()] = e.target.valueAsNumber;
    requestFrame();
  });
  for (const key of ['width', 'height']) {
    $(`cam-${key}`).addEventListener('change', (e) => {
      if (!Number.isFinite(e.target.valueAsNumber)) return showCamera();
      camera[key] = Math.round(e.target.valueAsNumber);
      layoutStage();
      requestFrame();
    });
  }
  $('reset-view').addEventListener('click', () => {
    Object.assign(camera, deepCopy({...homeCamera, width: camera.width, height: camera.height}));
    requestFrame();
  });
}

// ---------------------------------------------------------------------------------------
// Isosurface panel: the scene's first isosurface (its other keys and the other
// isosurfaces kept as they are)

const iso = {};

function setupIsoPanel() {
  const items = scene.isosurfaces || [];
  const first = items[0] || {};
  const {field, value, color, opacity, ...keep} = first;
  Object.assign(iso, {
    enabled: items.length > 0,
    keep,
    rest: items.slice(1),
    field: field || pointFields[0],
    color: color || [0.9, 0.5, 0.2],
    opacity: opacity === undefined ? 1 : opacity,
  });
  const range = fieldRange(iso.field);
  iso.value = value === undefined ? tidy((range[0] + range[1]) / 2) : value;

  $('iso-enabled').checked = iso.enabled;
  fillFieldSelect($('iso-field'), iso.field);
  setSlider($('iso-value'), $('iso-value-number'), range, iso.value);
  $('iso-color').value = linearToHex(iso.color);
  $('iso-opacity').value = iso.opacity;
  $('iso-opacity-out').value = iso.opacity;
  if (iso.rest.length) {
    $('iso-rest').textContent = `${iso.rest.length} more isosurface(s) of the scene kept as they are`;
  }

  $('iso-enabled').addEventListener('change', (e) => {
    iso.enabled = e.target.checked;
    touch('iso');
  });
  $('iso-field').addEventListener('change', (e) => {
    iso.field = e.target.value;
    const r = fieldRange(iso.field);
    if (iso.value < r[0] || iso.value > r[1]) iso.value = tidy((r[0] + r[1]) / 2);
    setSlider($('iso-value'), $('iso-value-number'), r, iso.value);
    touch('iso');
  });
  $('iso-value').addEventListener('input', (e) => {
    iso.value = tidy(Number(e.target.value));
    $('iso-value-number').value = iso.value;
    touch('iso');
  });
  $('iso-value-number').addEventListener('change', (e) => {
    if (!Number.isFinite(e.target.valueAsNumber)) {
      e.target.value = iso.value;
      return;
    }
    iso.value = e.target.valueAsNumber;
    setSlider($('iso-value'), null, fieldRange(iso.field), iso.value);
    touch('iso');
  });
  $('iso-color').addEventListener('input', (e) => {
    iso.color = hexToLinear(e.target.value);
    touch('iso');
  });
  $('iso-opacity').addEventListener('input', (e) => {
    iso.opacity = Number(e.target.value);
    $('iso-opacity-out').value = iso.opacity;
    touch('iso');
  });
}

function isoKeys() {
  const first = {...iso.keep, field: iso.field, value: iso.value, color: iso.color, opacity: iso.opacity};
  return iso.enabled ? [first, ...iso.rest] : iso.rest;
}

// ---------------------------------------------------------------------------------------
// Volume panel and its transfer-function editors

const volume = {};

function setupVolumePanel() {
  const sv = scene.volume || {};
  const field = sv.color_field || pointFields[0];
  const range = fieldRange(field);
  const diagonal = vec.length(vec.sub(bounds[1], bounds[0])) || 1;
  // A transfer function the scene does not list (absent, or a colour map by name) is the
  // renderer's (ResolveColorMaps: viridis over the field's range, an extinction ramp from 0
  // to 10 / the data's diagonal): it is not sent, so the service resolves it exactly as
  // `hpray render` does, and the editors show the control points that the frames' stats
  // report (adoptResolvedVolume) until one of them is edited. Until a frame reports them,
  // the editors show the same ramps coarsely.
  const resolved = {color: !Array.isArray(sv.color_tf), extinction: !Array.isArray(sv.extinction_tf)};
  const colorTf = !resolved.color ? sv.color_tf
      : [[0, 68, 1, 84], [0.5, 33, 145, 140], [1, 253, 231, 37]].map(
          ([f, ...rgb]) => [range[0] + f * (range[1] - range[0]), ...rgb.map((c) => srgbToLinear(c / 255))]);
  const extinctionTf = !resolved.extinction ? sv.extinction_tf : [[range[0], 0], [range[1], 10 / diagonal]];
  // Glow (wilhelms-van-gelder) may exceed 1: the stops hold colours in [0, 1] and the
  // glow scale multiplies them.
  const brightest = Math.max(1, ...colorTf.map((p) => Math.max(p[1], p[2], p[3])));
  Object.assign(volume, {
    enabled: !!scene.volume,
    field,
    // The scene's own extinction field stays until another field is picked.
    extinctionField: sv.extinction_field || field,
    glow: sv.glow || 'williams-max',
    glowScale: brightest,
    colorStops: colorTf.map(([s, r, g, b]) => ({s, rgb: [r, g, b].map((c) => c / brightest)})),
    extinction: extinctionTf.map(([s, e]) => ({s, e})),
    resolved,
  });
  view.volume = volume;
  fitVolumeAxes();

  $('vol-enabled').checked = volume.enabled;
  fillFieldSelect($('vol-field'), volume.field);
  $('vol-glow').value = volume.glow;
  $('vol-glow-scale').value = tidy(volume.glowScale);
  showGlowScale();

  $('vol-enabled').addEventListener('change', (e) => {
    volume.enabled = e.target.checked;
    touch('volume');
  });
  $('vol-field').addEventListener('change', (e) => {
    volume.field = volume.extinctionField = e.target.value;
    const to = fieldRange(volume.field);
    rescalePoints(volume.colorStops, volume.domain, to);
    rescalePoints(volume.extinction, volume.domain, to);
    volume.domain = to;
    tfEditors.refresh();
    touch('volume');
  });
  $('vol-glow').addEventListener('change', (e) => {
    volume.glow = e.target.value;
    showGlowScale();
    touch('volume');
  });
  $('vol-glow-scale').addEventListener('change', (e) => {
    volume.glowScale = Math.max(0, Number(e.target.value));
    volume.resolved.color = false;  // scales the colour transfer function: sent from now on
    touch('volume');
  });
}

/** The editors' field axis (the field's range and every control point) and extinction axis. */
function fitVolumeAxes() {
  const range = fieldRange(volume.field);
  const scalars = [...volume.colorStops, ...volume.extinction].map((p) => p.s);
  volume.domain = [Math.min(range[0], ...scalars), Math.max(range[1], ...scalars)];
  volume.yMax = niceCeiling(1.15 * Math.max(...volume.extinction.map((p) => p.e)));
}

/** A frame's stats report the volume's transfer functions as rendered: while the panel
 *  shows the renderer's own (`resolved`) for the fields it shows, it takes them over. */
function adoptResolvedVolume(stats) {
  const v = stats && stats.volume;
  if (!volume.resolved || !(volume.resolved.color || volume.resolved.extinction)) return;
  if (!v || !Array.isArray(v.color_tf) || !Array.isArray(v.extinction_tf)) return;
  if (v.color_field !== volume.field || v.extinction_field !== volume.extinctionField) return;
  const scale = volume.glow === 'wilhelms-van-gelder' ? volume.glowScale || 1 : 1;
  const colorStops = v.color_tf.map(([s, r, g, b]) => ({s, rgb: [r, g, b].map((c) => c / scale)}));
  const extinction = v.extinction_tf.map(([s, e]) => ({s, e}));
  let changed = false;
  if (volume.resolved.color && JSON.stringify(colorStops) !== JSON.stringify(volume.colorStops)) {
    volume.colorStops = colorStops;
    changed = true;
  }
  if (volume.resolved.extinction && JSON.stringify(extinction) !== JSON.stringify(volume.extinction)) {
    volume.extinction = extinction;
    changed = true;
  }
  if (!changed) return;
  fitVolumeAxes();
  tfEditors.refresh();
}

function showGlowScale() {
  const glow = volume.glow === 'wilhelms-van-gelder';
  $('vol-glow-scale').hidden = !glow;
  $('vol-glow-scale-label').hidden = !glow;
}

/** The smallest of 1, 2, 5 times a power of ten at or above `x` (1 for x <= 0). */
function niceCeiling(x) {
  if (!(x > 0)) return 1;
  const p = Math.pow(10, Math.floor(Math.log10(x)));
  return [1, 2, 5, 10].map((m) => m * p).find((v) => v >= x * (1 - 1e-12));
}

function volumeKeys() {
  if (!volume.enabled) return null;
  const scale = volume.glow === 'wilhelms-van-gelder' ? volume.glowScale : 1;
  const keys = {color_field: volume.field, extinction_field: volume.extinctionField, glow: volume.glow};
  // The renderer's own transfer functions (see setupVolumePanel) are left to the service.
  if (!volume.resolved.color) keys.color_tf = volume.colorStops.map((p) => [p.s, ...p.rgb.map((c) => tidy(c * scale))]);
  if (!volume.resolved.extinction) keys.extinction_tf = volume.extinction.map((p) => [p.s, p.e]);
  return keys;
}

/** Sets up a canvas for drawing in CSS pixels at the screen's resolution; its context,
 *  width and height, or null while it is not shown. */
function prepareCanvas(canvas) {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (!w || !h) return null;
  const ratio = window.devicePixelRatio || 1;
  if (canvas.width !== Math.round(w * ratio) || canvas.height !== Math.round(h * ratio)) {
    canvas.width = Math.round(w * ratio);
    canvas.height = Math.round(h * ratio);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  ctx.clearRect(0, 0, w, h);
  return {ctx, w, h};
}

/**
 * The two transfer-function editors of the volume panel, over volume.domain:
 * - extinction: control points on a canvas (x the field value, y the extinction); drag to
 *   move, double-click to add, right-click or "remove point" to remove; the area under the
 *   curve is filled with the colour transfer function;
 * - colour: a gradient bar with a marker per stop (drag to move, double-click the bar to
 *   add, right-click a marker to remove) and a row per stop with its value and an
 *   <input type=color>.
 * Scalars stay strictly increasing: a point moves only between its neighbours.
 */
const tfEditors = (() => {
  const ext = $('tf-extinction');
  const bar = $('tf-color');
  const PAD_X = 8, PAD_TOP = 8, PAD_BOTTOM = 16, HIT = 8, BAR_HEIGHT = 20;
  let selected = 0;       // index of the selected extinction point
  let selectedStop = 0;   // index of the selected colour stop
  let dragging = null;    // {target: 'ext' | 'color', index}

  const gap = () => (volume.domain[1] - volume.domain[0]) * 1e-4;
  const xOf = (s, w) => PAD_X + ((s - volume.domain[0]) / (volume.domain[1] - volume.domain[0])) * (w - 2 * PAD_X);
  const sOf = (x, w) => volume.domain[0] + ((x - PAD_X) / (w - 2 * PAD_X)) * (volume.domain[1] - volume.domain[0]);
  const yOf = (e, h) => PAD_TOP + (1 - e / volume.yMax) * (h - PAD_TOP - PAD_BOTTOM);
  const eOf = (y, h) => (1 - (y - PAD_TOP) / (h - PAD_TOP - PAD_BOTTOM)) * volume.yMax;

  /** Where point `i` of `points` may go: between its neighbours, inside the domain. */
  function scalarLimits(points, i) {
    const lo = i > 0 ? points[i - 1].s + gap() : volume.domain[0];
    const hi = i < points.length - 1 ? points[i + 1].s - gap() : volume.domain[1];
    return [lo, Math.max(lo, hi)];
  }

  /** Index of the point of `points` within HIT pixels of x (and of y when given). */
  function hit(points, x, y, w, h) {
    let best = -1, bestDistance = HIT;
    points.forEach((p, i) => {
      const d = y === undefined ? Math.abs(xOf(p.s, w) - x) : Math.hypot(xOf(p.s, w) - x, yOf(p.e, h) - y);
      if (d <= bestDistance) {
        best = i;
        bestDistance = d;
      }
    });
    return best;
  }

  function gradient(ctx, w, alpha) {
    const g = ctx.createLinearGradient(xOf(volume.domain[0], w), 0, xOf(volume.domain[1], w), 0);
    const steps = 48;
    for (let k = 0; k <= steps; ++k) {
      const s = volume.domain[0] + (k / steps) * (volume.domain[1] - volume.domain[0]);
      g.addColorStop(k / steps, linearToCss(sampleColor(volume.colorStops, s), alpha));
    }
    return g;
  }

  function drawExtinction() {
    const c = prepareCanvas(ext);
    if (!c) return;
    const {ctx, w, h} = c;
    const points = volume.extinction;
    const x0 = xOf(volume.domain[0], w), x1 = xOf(volume.domain[1], w), yBase = yOf(0, h);
    // Grid: the zero line and half the axis.
    ctx.strokeStyle = '#30343b';
    ctx.beginPath();
    ctx.moveTo(x0, yOf(volume.yMax / 2, h));
    ctx.lineTo(x1, yOf(volume.yMax / 2, h));
    ctx.moveTo(x0, yBase);
    ctx.lineTo(x1, yBase);
    ctx.stroke();
    // The curve, clamped at its ends like the renderer's, and the colour beneath it.
    const line = [[x0, yOf(points[0].e, h)], ...points.map((p) => [xOf(p.s, w), yOf(p.e, h)]),
                  [x1, yOf(points[points.length - 1].e, h)]];
    ctx.beginPath();
    ctx.moveTo(x0, yBase);
    for (const [x, y] of line) ctx.lineTo(x, y);
    ctx.lineTo(x1, yBase);
    ctx.closePath();
    ctx.fillStyle = gradient(ctx, w, 0.55);
    ctx.fill();
    ctx.beginPath();
    line.forEach(([x, y], k) => (k ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    ctx.strokeStyle = '#f0f0f0';
    ctx.lineWidth = 1.5;
    ctx.stroke();
    points.forEach((p, i) => {
      ctx.beginPath();
      ctx.arc(xOf(p.s, w), yOf(p.e, h), i === selected ? 6 : 4.5, 0, 2 * Math.PI);
      ctx.fillStyle = i === selected ? '#5aa9ff' : '#f0f0f0';
      ctx.fill();
      ctx.strokeStyle = '#15171a';
      ctx.lineWidth = 1.5;
      ctx.stroke();
    });
    ctx.fillStyle = '#9aa1ad';
    ctx.font = '11px system-ui, sans-serif';
    ctx.textBaseline = 'bottom';
    ctx.textAlign = 'left';
    ctx.fillText(formatNumber(volume.domain[0], 3), x0, h);
    ctx.textAlign = 'right';
    ctx.fillText(formatNumber(volume.domain[1], 3), x1, h);
    ctx.textBaseline = 'top';
    ctx.textAlign = 'left';
    ctx.fillText(formatNumber(volume.yMax, 3), x0 + 2, 1);
  }

  function drawColorBar() {
    const c = prepareCanvas(bar);
    if (!c) return;
    const {ctx, w, h} = c;
    ctx.fillStyle = gradient(ctx, w, 1);
    ctx.fillRect(xOf(volume.domain[0], w), 1, xOf(volume.domain[1], w) - xOf(volume.domain[0], w), BAR_HEIGHT);
    volume.colorStops.forEach((p, i) => {
      const x = xOf(p.s, w);
      ctx.beginPath();
      ctx.moveTo(x, BAR_HEIGHT + 2);
      ctx.lineTo(x - 6, h - 1);
      ctx.lineTo(x + 6, h - 1);
      ctx.closePath();
      ctx.fillStyle = linearToCss(p.rgb);
      ctx.fill();
      ctx.strokeStyle = i === selectedStop ? '#5aa9ff' : '#f0f0f0';
      ctx.lineWidth = i === selectedStop ? 2.5 : 1;
      ctx.stroke();
    });
  }

  /** The selected extinction point in the number boxes. */
  function showSelected() {
    const p = volume.extinction[selected];
    $('tf-ext-value').value = tidy(p.s);
    $('tf-ext-sigma').value = tidy(p.e);
    $('tf-ext-ymax').value = volume.yMax;
    $('tf-ext-remove').disabled = volume.extinction.length < 2;
  }

  /** One row per colour stop: its value, its colour, a remove button. */
  function buildStopRows() {
    const rows = volume.colorStops.map((p, i) => {
      const row = document.createElement('div');
      row.className = 'stop-row' + (i === selectedStop ? ' selected' : '');
      const value = document.createElement('input');
      value.type = 'number';
      value.step = 'any';
      value.value = tidy(p.s);
      value.id = `tf-stop-${i}-value`;
      value.addEventListener('focus', () => selectStop(i));
      value.addEventListener('change', () => {
        const [lo, hi] = scalarLimits(volume.colorStops, i);
        p.s = clamp(Number(value.value), lo, hi);
        value.value = tidy(p.s);
        changed(false);
      });
      const color = document.createElement('input');
      color.type = 'color';
      color.value = linearToHex(p.rgb);
      color.id = `tf-stop-${i}-color`;
      color.addEventListener('input', () => {
        p.rgb = hexToLinear(color.value);
        changed(false);
      });
      const remove = document.createElement('button');
      remove.type = 'button';
      remove.textContent = '×';
      remove.title = 'remove this stop';
      remove.id = `tf-stop-${i}-remove`;
      remove.disabled = volume.colorStops.length < 2;
      remove.addEventListener('click', () => removeStop(i));
      row.append(value, color, remove);
      return row;
    });
    $('tf-color-stops').replaceChildren(...rows);
  }

  function selectStop(i) {
    if (selectedStop === i) return;
    selectedStop = i;
    [...$('tf-color-stops').children].forEach((row, k) => row.classList.toggle('selected', k === i));
    drawColorBar();
  }

  function removeStop(i) {
    if (volume.colorStops.length < 2) return;
    volume.colorStops.splice(i, 1);
    selectedStop = Math.min(selectedStop, volume.colorStops.length - 1);
    changed(true);
  }

  /** Redraws after an edit, rebuilds the stop rows when `structure` changed, and renders.
   *  Both transfer functions are sent from now on, as shown (the renderer's own, as the
   *  frames reported them, with the edit). */
  function changed(structure) {
    volume.resolved.color = volume.resolved.extinction = false;
    if (structure) buildStopRows();
    refreshDrawing();
    touch('volume');
  }

  function refreshDrawing() {
    if (!volume.extinction) return;  // before the panel is set up
    drawExtinction();
    drawColorBar();
    showSelected();
  }

  /** Everything again, e.g. after the domain changed. */
  function refresh() {
    selected = Math.min(selected, volume.extinction.length - 1);
    selectedStop = Math.min(selectedStop, volume.colorStops.length - 1);
    buildStopRows();
    refreshDrawing();
  }

  // Extinction canvas
  ext.addEventListener('pointerdown', (e) => {
    if (e.button !== 0) return;
    const i = hit(volume.extinction, e.offsetX, e.offsetY, ext.clientWidth, ext.clientHeight);
    if (i < 0) return;
    selected = i;
    dragging = {target: 'ext', index: i};
    ext.setPointerCapture(e.pointerId);
    refreshDrawing();
  });
  ext.addEventListener('pointermove', (e) => {
    if (!dragging || dragging.target !== 'ext') return;
    const p = volume.extinction[dragging.index];
    const [lo, hi] = scalarLimits(volume.extinction, dragging.index);
    p.s = tidy(clamp(sOf(e.offsetX, ext.clientWidth), lo, hi));
    p.e = tidy(clamp(eOf(e.offsetY, ext.clientHeight), 0, volume.yMax));
    changed(false);
  });
  const endDrag = () => {
    dragging = null;
  };
  ext.addEventListener('pointerup', endDrag);
  ext.addEventListener('pointercancel', endDrag);
  ext.addEventListener('dblclick', (e) => {
    const w = ext.clientWidth, h = ext.clientHeight;
    if (hit(volume.extinction, e.offsetX, e.offsetY, w, h) >= 0) return;
    const s = tidy(clamp(sOf(e.offsetX, w), volume.domain[0], volume.domain[1]));
    if (volume.extinction.some((p) => Math.abs(p.s - s) < gap())) return;
    const point = {s, e: tidy(clamp(eOf(e.offsetY, h), 0, volume.yMax))};
    volume.extinction.push(point);
    volume.extinction.sort((a, b) => a.s - b.s);
    selected = volume.extinction.indexOf(point);
    changed(false);
  });
  ext.addEventListener('contextmenu', (e) => {
    e.preventDefault();
    const i = hit(volume.extinction, e.offsetX, e.offsetY, ext.clientWidth, ext.clientHeight);
    if (i < 0 || volume.extinction.length < 2) return;
    volume.extinction.splice(i, 1);
    selected = Math.min(selected, volume.extinction.length - 1);
    changed(false);
  });
  $('tf-ext-remove').addEventListener('click', () => {
    if (volume.extinction.length < 2) return;
    volume.extinction.splice(selected, 1);
    selected = Math.min(selected, volume.extinction.length - 1);
    changed(false);
  });
  $('tf-ext-value').addEventListener('change', (e) => {
    const [lo, hi] = scalarLimits(volume.extinction, selected);
    volume.extinction[selected].s = clamp(Number(e.target.value), lo, hi);
    changed(false);
  });
  $('tf-ext-sigma').addEventListener('change', (e) => {
    const sigma = Math.max(0, Number(e.target.value) || 0);
    volume.extinction[selected].e = sigma;
    volume.yMax = Math.max(volume.yMax, niceCeiling(sigma));
    changed(false);
  });
  $('tf-ext-ymax').addEventListener('change', (e) => {
    // The axis shows every point: it cannot go below the largest extinction.
    const top = Math.max(...volume.extinction.map((p) => p.e));
    volume.yMax = Math.max(Number(e.target.value) || 0, top) || 1;
    refreshDrawing();
  });

  // Colour bar
  bar.addEventListener('pointerdown', (e) => {
    if (e.button !== 0) return;
    const i = hit(volume.colorStops, e.offsetX, undefined, bar.clientWidth);
    if (i < 0) return;
    selectStop(i);
    dragging = {target: 'color', index: i};
    bar.setPointerCapture(e.pointerId);
  });
  bar.addEventListener('pointermove', (e) => {
    if (!dragging || dragging.target !== 'color') return;
    const p = volume.colorStops[dragging.index];
    const [lo, hi] = scalarLimits(volume.colorStops, dragging.index);
    p.s = tidy(clamp(sOf(e.offsetX, bar.clientWidth), lo, hi));
    const input = $(`tf-stop-${dragging.index}-value`);
    if (input) input.value = p.s;
    changed(false);
  });
  bar.addEventListener('pointerup', endDrag);
  bar.addEventListener('pointercancel', endDrag);
  const addStop = (s) => {
    if (volume.colorStops.some((p) => Math.abs(p.s - s) < gap())) return;
    const stop = {s, rgb: sampleColor(volume.colorStops, s).map(tidy)};
    volume.colorStops.push(stop);
    volume.colorStops.sort((a, b) => a.s - b.s);
    selectedStop = volume.colorStops.indexOf(stop);
    changed(true);
  };
  bar.addEventListener('dblclick', (e) => {
    const w = bar.clientWidth;
    if (hit(volume.colorStops, e.offsetX, undefined, w) >= 0) return;
    addStop(tidy(clamp(sOf(e.offsetX, w), volume.domain[0], volume.domain[1])));
  });
  bar.addEventListener('contextmenu', (e) => {
    e.preventDefault();
    const i = hit(volume.colorStops, e.offsetX, undefined, bar.clientWidth);
    if (i >= 0) removeStop(i);
  });
  // "add stop": halfway into the widest gap between stops (or the domain's ends).
  $('tf-color-add').addEventListener('click', () => {
    const edges = [volume.domain[0], ...volume.colorStops.map((p) => p.s), volume.domain[1]];
    let best = 0;
    for (let k = 1; k < edges.length - 1; ++k) if (edges[k + 1] - edges[k] > edges[best + 1] - edges[best]) best = k;
    addStop(tidy((edges[best] + edges[best + 1]) / 2));
  });

  // Canvases in a closed <details> have no size: drawn when opened and when resized.
  new ResizeObserver(refreshDrawing).observe(ext);
  return {refresh};
})();

// ---------------------------------------------------------------------------------------
// Slice panel: the scene's first slice (the others kept as they are), its plane moved
// along its normal

const slice = {};
const AXES = {x: [1, 0, 0], y: [0, 1, 0], z: [0, 0, 1]};

function setupSlicePanel() {
  const items = scene.slices || [];
  const first = items[0] || {};
  const {field, normal, point, color_tf: colorTf, opacity, ...keep} = first;
  const centre = vec.scale(vec.add(bounds[0], bounds[1]), 0.5);
  Object.assign(slice, {
    enabled: items.length > 0,
    keep,
    rest: items.slice(1),
    field: field || pointFields[0],
    normal: normal || [0, 0, 1],
    point: point || centre,
    opacity: opacity === undefined ? 1 : opacity,
  });
  const range = fieldRange(slice.field);
  slice.colorTf = colorTf ||
      [[range[0], 0.23, 0.3, 0.75], [(range[0] + range[1]) / 2, 0.87, 0.87, 0.87], [range[1], 0.7, 0.02, 0.15]]
          .map(([s, ...rgb]) => [tidy(s), ...rgb.map((c) => tidy(srgbToLinear(c)))]);

  const normalSelect = $('slice-normal');
  for (const name of Object.keys(AXES)) normalSelect.add(new Option(name, name));
  const axis = Object.keys(AXES).find((k) => vec.length(vec.sub(vec.normalize(slice.normal), AXES[k])) < 1e-12);
  if (axis) {
    normalSelect.value = axis;
  } else {
    normalSelect.add(new Option(`scene [${slice.normal.join(', ')}]`, 'scene'));
    normalSelect.value = 'scene';
  }
  const sceneNormal = slice.normal;

  $('slice-enabled').checked = slice.enabled;
  fillFieldSelect($('slice-field'), slice.field);
  $('slice-opacity').value = slice.opacity;
  $('slice-opacity-out').value = slice.opacity;
  showSlicePosition();
  if (slice.rest.length) {
    $('slice-rest').textContent = `${slice.rest.length} more slice(s) of the scene kept as they are`;
  }

  $('slice-enabled').addEventListener('change', (e) => {
    slice.enabled = e.target.checked;
    touch('slice');
  });
  $('slice-field').addEventListener('change', (e) => {
    const from = fieldRange(slice.field);
    slice.field = e.target.value;
    const points = slice.colorTf.map(([s]) => ({s}));
    rescalePoints(points, from, fieldRange(slice.field));
    slice.colorTf = slice.colorTf.map(([, ...rgb], k) => [points[k].s, ...rgb]);
    touch('slice');
  });
  normalSelect.addEventListener('change', (e) => {
    slice.normal = e.target.value === 'scene' ? sceneNormal : AXES[e.target.value];
    showSlicePosition();
    touch('slice');
  });
  $('slice-position').addEventListener('input', (e) => {
    moveSlice(Number(e.target.value));
    $('slice-position-number').value = tidy(Number(e.target.value));
    touch('slice');
  });
  $('slice-position-number').addEventListener('change', (e) => {
    if (Number.isFinite(e.target.valueAsNumber)) moveSlice(e.target.valueAsNumber);
    showSlicePosition();
    touch('slice');
  });
  $('slice-opacity').addEventListener('input', (e) => {
    slice.opacity = Number(e.target.value);
    $('slice-opacity-out').value = slice.opacity;
    touch('slice');
  });
}

/** The plane's offset along its unit normal and that offset's range over the data's box. */
function slicePosition() {
  const n = vec.normalize(slice.normal);
  const corners = [0, 1, 2, 3, 4, 5, 6, 7].map((k) => [0, 1, 2].map((a) => bounds[(k >> a) & 1][a]));
  const offsets = corners.map((c) => vec.dot(n, c));
  return {n, value: vec.dot(n, slice.point), range: [Math.min(...offsets), Math.max(...offsets)]};
}

function showSlicePosition() {
  const {value, range} = slicePosition();
  setSlider($('slice-position'), $('slice-position-number'), range, value);
}

/** Moves the plane along its normal to the offset `s`. */
function moveSlice(s) {
  const {n, value} = slicePosition();
  slice.point = vec.add(slice.point, vec.scale(n, s - value)).map(tidy);
}

function sliceKeys() {
  const first = {...slice.keep, point: slice.point, normal: slice.normal, field: slice.field,
                 color_tf: slice.colorTf, opacity: slice.opacity};
  return slice.enabled ? [first, ...slice.rest] : slice.rest;
}

// ---------------------------------------------------------------------------------------
// Clip box panel: per axis a low and a high slider over the data's bounds

const clip = {};

function setupClipPanel() {
  const box = scene.clip && scene.clip.box;
  clip.enabled = !!box;
  clip.box = deepCopy(box || bounds);
  $('clip-enabled').checked = clip.enabled;
  $('clip-enabled').addEventListener('change', (e) => {
    clip.enabled = e.target.checked;
    touch('clip');
  });
  const rows = ['x', 'y', 'z'].map((name, a) => {
    const lo = Math.min(bounds[0][a], clip.box[0][a]), hi = Math.max(bounds[1][a], clip.box[1][a]);
    const step = (hi - lo) / 200 || 1e-3;
    const row = document.createElement('div');
    row.className = 'clip-axis';
    const label = document.createElement('span');
    label.textContent = name;
    const sliders = [0, 1].map((side) => {
      const cell = document.createElement('div');
      const slider = document.createElement('input');
      slider.type = 'range';
      slider.id = `clip-${name}-${side ? 'hi' : 'lo'}`;
      slider.min = lo;
      slider.max = hi;
      slider.step = step;
      slider.value = clip.box[side][a];
      slider.title = `${side ? 'high' : 'low'} ${name}`;
      const out = document.createElement('output');
      out.id = `${slider.id}-out`;
      out.value = tidy(clip.box[side][a]);
      slider.addEventListener('input', () => {
        // The box stays non-empty: each side stops a step short of the other.
        let v = Number(slider.value);
        v = side ? Math.max(v, clip.box[0][a] + step) : Math.min(v, clip.box[1][a] - step);
        slider.value = v;
        clip.box[side][a] = tidy(v);
        out.value = clip.box[side][a];
        if (!clip.enabled) {
          clip.enabled = true;
          $('clip-enabled').checked = true;
        }
        touch('clip');
      });
      cell.append(slider, out);
      return cell;
    });
    row.append(label, ...sliders);
    return row;
  });
  $('clip-axes').replaceChildren(...rows);
}

function clipKeys() {
  return {box: clip.enabled ? clip.box : null};
}

// ---------------------------------------------------------------------------------------
// "More scene keys": a JSON object merged over the panels' keys

function setupExtraKeys() {
  $('extra-apply').addEventListener('click', () => {
    const text = $('extra-keys').value.trim();
    let keys = {};
    if (text) {
      try {
        keys = JSON.parse(text);
      } catch (e) {
        showMessage(`More scene keys: not JSON (${e.message}); not applied`);
        return;
      }
      if (!isObject(keys)) {
        showMessage('More scene keys: expected a JSON object of scene keys; not applied');
        return;
      }
    }
    extraKeys = keys;
    requestFrame();
  });
  $('extra-clear').addEventListener('click', () => {
    $('extra-keys').value = '';
    extraKeys = {};
    requestFrame();
  });
}

/** The body of a render request: the camera always, the keys of changed panels, then the
 *  extra keys. */
function requestBody() {
  const body = {camera: cameraKeys()};
  if (touched.has('iso')) body.isosurfaces = isoKeys();
  if (touched.has('volume')) body.volume = volumeKeys();
  if (touched.has('slice')) body.slices = sliceKeys();
  if (touched.has('clip')) body.clip = clipKeys();
  return mergeKeys(deepCopy(body), extraKeys);
}

// ---------------------------------------------------------------------------------------
// Requests: at most one in flight and the newest wish pending

/**
 * `pending` says the view changed since the request in flight was sent. A progressive
 * request that has already delivered a pass is superseded as soon as something newer is
 * wanted: its connection is closed (the service cancels its remaining passes) and the
 * newest state is sent. A request that has delivered nothing yet, or a plain
 * (non-progressive) one, is waited for, so that every interaction shows something.
 */
const flight = {current: null, pending: false, seq: 0};

function requestFrame() {
  flight.pending = true;
  pump();
  showBusy();
}

function pump() {
  if (!flight.pending || !camera) return;
  const current = flight.current;
  if (current) {
    if (!current.streaming || current.passesReceived === 0) return;
    current.superseded = true;
    current.controller.abort();
  }
  flight.pending = false;
  send(requestBody());
}

function showBusy() {
  view.busy = !!flight.current || flight.pending;
  $('busy').hidden = !view.busy;
  $('render-again').hidden = !view.cancelled || view.busy;
}

async function send(body) {
  const request = {seq: ++flight.seq, body, width: body.camera.width, height: body.camera.height,
                   streaming: false, passesReceived: 0, superseded: false, cancelled: false,
                   controller: new AbortController()};
  flight.current = request;
  view.requestsSent = request.seq;
  view.lastBody = body;
  showBusy();
  try {
    const response = await api(`/api/render?progressive=1&passes=${PASSES}`, {
      method: 'POST',
      headers: {'Content-Type': 'application/json'},
      body: JSON.stringify(body),
      signal: request.controller.signal,
    });
    if (!response.ok) {
      showMessage(await failureText(response), request.seq);
      return;
    }
    if ((response.headers.get('Content-Type') || '').startsWith('text/event-stream')) {
      request.streaming = view.streaming = true;
      let ended = false;
      for await (const event of serverSentEvents(response.body)) {
        const data = JSON.parse(event.data);
        if (event.event === 'pass') {
          received(request, data);
        } else if (event.event === 'error') {
          showMessage(data.error, request.seq);
        } else if (event.event === 'end') {
          ended = true;
          if (data.cancelled) markCancelled(request);
        }
      }
      if (!ended && !request.superseded) showMessage('the render stream ended early', request.seq);
    } else {
      // A service without progressive frames answers the plain way: one final frame.
      view.streaming = false;
      const answer = await response.json();
      const [width, height] = (answer.stats && answer.stats.image) || [request.width, request.height];
      received(request, {frame: answer.frame, pass: 0, passes: 1, scale: 1, final: true, width, height,
                         stats: answer.stats});
    }
  } catch (e) {
    if (!request.superseded) showMessage(`no answer from the service: ${e.message}`, request.seq);
  } finally {
    if (flight.current === request) flight.current = null;
    pump();
    showBusy();
  }
}

/** Marks a request whose remaining passes the service cancelled for a newer request (of
 *  another client: this page closes the streams it supersedes). */
function markCancelled(request) {
  request.cancelled = true;
  if (view.request === request.seq && !view.final) {
    view.cancelled = true;
    showStatus();
  }
}

/** A finished pass: shown once its image is loaded (unless something newer is shown by then). */
function received(request, pass) {
  request.passesReceived += 1;
  view.passLog.push({request: request.seq, frame: pass.frame, pass: pass.pass, passes: pass.passes,
                     scale: pass.scale, final: pass.final});
  if (view.passLog.length > 32) view.passLog.shift();
  display(request, pass);
  pump();
}

// ---------------------------------------------------------------------------------------
// The frame on screen

const frameImage = $('frame');
let shown = {request: 0, pass: -1, url: null};

const newer = (request, pass) => request > shown.request || (request === shown.request && pass > shown.pass);

async function display(request, pass) {
  try {
    const response = await api(`/api/frames/${pass.frame}/image.png`);
    if (!response.ok) throw new Error(await failureText(response));
    const url = URL.createObjectURL(await response.blob());
    const probe = new Image();
    probe.src = url;
    await probe.decode();
    if (!newer(request.seq, pass.pass)) {
      URL.revokeObjectURL(url);
      return;
    }
    // The decoded image is reused: the swap shows no blank in between.
    frameImage.src = url;
    if (shown.url) URL.revokeObjectURL(shown.url);
    shown = {request: request.seq, pass: pass.pass, url, width: request.width, height: request.height};
    Object.assign(view, {frame: pass.frame, pass: pass.pass, passes: pass.passes, final: pass.final, scale: pass.scale,
                         request: request.seq, stats: pass.stats, cancelled: request.cancelled && !pass.final});
    Object.assign(frameImage.dataset, {frame: pass.frame, pass: pass.pass, passes: pass.passes,
                                       final: pass.final, scale: pass.scale, request: request.seq});
    if (view.error && request.seq > messageRequest) clearMessage();
    layoutStage();
    showStatus();
    showStats(pass.stats);
    adoptResolvedVolume(pass.stats);
    showCamera();
    refreshOverlay();
  } catch (e) {
    if (newer(request.seq, pass.pass)) showMessage(`frame ${pass.frame}: ${e.message}`, request.seq);
  }
}

/** The status line: pass, frame, render time, size, and whether the request was cancelled. */
function showStatus() {
  const s = view.stats || {};
  const parts = [`pass ${view.pass + 1}/${view.passes}`, `frame ${view.frame}`,
                 formatSeconds(s.timing_s && s.timing_s.total)];
  if (s.image) parts.push(`${s.image[0]}×${s.image[1]}${view.scale > 1 ? ` (1/${view.scale} scale)` : ''}`);
  const status = $('status');
  status.replaceChildren(parts.join(' · '));
  if (view.cancelled) {
    const tag = document.createElement('span');
    tag.className = 'cancelled';
    tag.textContent = ' · cancelled';
    status.append(tag);
  }
  const warnings = (s.warnings || []).length;
  if (warnings) {
    const tag = document.createElement('span');
    tag.className = 'warnings';
    tag.textContent = ` · ⚠ ${warnings} warning${warnings > 1 ? 's' : ''}`;
    status.append(tag);
  }
  frameImage.dataset.cancelled = view.cancelled;
  showBusy();
}

/** Sizes the stage (image and overlay) to the largest box of the frame's aspect that fits
 *  above the legend. */
function layoutStage() {
  const area = $('view');
  const width = shown.width || (camera && camera.width) || 1;
  const height = shown.height || (camera && camera.height) || 1;
  const legend = $('legend').hidden ? 0 : $('legend').offsetHeight + 8;
  const aw = area.clientWidth - 24, ah = area.clientHeight - 24 - legend;
  if (aw <= 0 || ah <= 0) return;
  const scale = Math.min(aw / width, ah / height);
  $('stage').style.width = `${Math.floor(width * scale)}px`;
  $('stage').style.height = `${Math.floor(height * scale)}px`;
}

// ---------------------------------------------------------------------------------------
// Stats panel

function showStats(stats) {
  if (!stats) return;
  const iso = stats.iso || {}, vol = stats.volume || {}, t = stats.timing_s || {};
  const range = iso.field_range;
  const span = range ? range[1] - range[0] : NaN;
  const relative = (key, absolute) =>
      iso[key] !== undefined ? iso[key] : span > 0 && absolute !== undefined ? absolute / span : undefined;
  const sections = [
    ['timing', [['load', formatSeconds(t.load)], ['accel', formatSeconds(t.accel)],
                ['render', formatSeconds(t.render)], ['composite', formatSeconds(t.composite)],
                ['write', formatSeconds(t.write)], ['total', formatSeconds(t.total)]]],
    ['work', [['image', stats.image ? `${stats.image[0]} × ${stats.image[1]}` : '–'],
              ['rays', formatNumber(stats.rays)],
              ['segments', formatNumber(stats.segments)],
              ['segments culled', formatNumber(stats.segments_culled)],
              ['bricks', `${formatNumber(stats.bricks_loaded)} / ${formatNumber(stats.bricks_total)}`],
              ['ranks', formatNumber(stats.ranks)], ['threads', formatNumber(stats.threads)]]],
    ['isosurfaces', [['hits', formatNumber(iso.hits)],
                     ['max residual', formatNumber(iso.max_residual, 3)],
                     ['max residual / range', formatNumber(relative('max_residual_relative', iso.max_residual), 3)],
                     ['RMS residual', formatNumber(iso.rms_residual, 3)],
                     ['RMS residual / range', formatNumber(relative('rms_residual_relative', iso.rms_residual), 3)],
                     ['field range', range ? `${formatNumber(range[0])} … ${formatNumber(range[1])}` : '–'],
                     ['projection order', `${formatNumber(iso.mean_projection_order, 3)} (max ${formatNumber(iso.max_projection_order)})`],
                     ['root failures', formatNumber(iso.root_failures)]]],
    ['volume', [['max error estimate', formatNumber(vol.max_error_estimate, 3)],
                ['RMS error estimate', formatNumber(vol.rms_error_estimate, 3)]]],
  ];
  if (info.ranks) {
    sections.push(['ranks', info.ranks.map((r) => [`rank ${r.rank}`, `pid ${r.pid} on ${r.host}`])]);
  }
  const rows = [];
  for (const [title, entries] of sections) {
    const head = document.createElement('tr');
    const th = document.createElement('th');
    th.colSpan = 2;
    th.textContent = title;
    head.append(th);
    rows.push(head);
    for (const [name, value] of entries) {
      const tr = document.createElement('tr');
      const a = document.createElement('td'), b = document.createElement('td');
      a.textContent = name;
      b.textContent = value;
      tr.append(a, b);
      rows.push(tr);
    }
  }
  $('stats-table').replaceChildren(...rows);
  const warnings = stats.warnings || [];
  $('stats-warnings').replaceChildren(...warnings.map((w) => {
    const li = document.createElement('li');
    li.textContent = w;
    return li;
  }));
  $('stats-warnings').hidden = warnings.length === 0;
  $('stats-json').textContent = JSON.stringify(stats, null, 1);
}

// ---------------------------------------------------------------------------------------
// Error overlay: log10 of the frame's errors.npy as a heat map over the image

const overlayCanvas = $('overlay');
const overlay = view.overlay;
/** Parsed errors.npy of the last frames shown, by frame id. */
const errorArrays = new Map();
const CHANNELS = {
  combined: 'log10 max(|residual| / field range, vol.error)',
  residual: 'log10 iso.residual (absolute)',
  volume: 'log10 vol.error (absolute)',
};

async function refreshOverlay() {
  const frame = view.frame;
  if (!overlay.enabled || frame === null) {
    overlayCanvas.hidden = true;
    $('legend').hidden = true;
    layoutStage();
    return;
  }
  if ($('legend').hidden) {
    $('legend').hidden = false;
    layoutStage();
  }
  let array = errorArrays.get(frame);
  if (!array) {
    try {
      const response = await api(`/api/frames/${frame}/errors.npy`);
      if (!response.ok) {
        throw new Error(response.status === 404
            ? 'no errors.npy for this frame (a service without it, or the frame is no longer kept)'
            : await failureText(response));
      }
      array = parseNpy(await response.arrayBuffer());
      if (array.shape.length !== 3 || array.shape[2] < 2) throw new Error(`errors.npy of shape (${array.shape})`);
    } catch (e) {
      if (view.frame === frame) showLegendProblem(e.message);
      return;
    }
    errorArrays.set(frame, array);
    while (errorArrays.size > 4) errorArrays.delete(errorArrays.keys().next().value);
  }
  // Drawn only for the frame still on screen (a newer one has its own refresh under way).
  if (view.frame === frame && overlay.enabled) drawOverlay(frame, array, view.stats || {});
}

function showLegendProblem(text) {
  overlayCanvas.hidden = true;
  Object.assign(overlay, {frame: null, min: null, max: null, pixels: 0});
  $('legend-title').textContent = CHANNELS[overlay.channel];
  for (const id of ['legend-min', 'legend-mid', 'legend-max']) $(id).textContent = '';
  $('legend-note').textContent = text;
}

/** The error of pixel k in the chosen channel; NaN where there is none. */
function pixelError(data, k, channels, channel, span) {
  const residual = data[channels * k], volumeError = data[channels * k + 1];
  const r = residual > 0 ? residual : NaN;        // NaN (no hit) and 0 stay NaN
  const v = volumeError > 0 ? volumeError : NaN;  // 0: no volume there
  if (channel === 'residual') return r;
  if (channel === 'volume') return v;
  const relative = span > 0 ? r / span : NaN;
  if (Number.isNaN(relative)) return v;
  return Number.isNaN(v) ? relative : Math.max(relative, v);
}

function drawOverlay(frame, array, stats) {
  const [height, width, channels] = array.shape;
  const range = (stats.iso && stats.iso.field_range) || fieldRange(iso.field);
  const span = range[1] - range[0];
  const logs = new Float64Array(width * height);
  let min = Infinity, max = -Infinity, pixels = 0;
  for (let k = 0; k < width * height; ++k) {
    const e = pixelError(array.data, k, channels, overlay.channel, span);
    const l = Number.isFinite(e) ? Math.log10(e) : NaN;
    logs[k] = l;
    if (!Number.isNaN(l)) {
      min = Math.min(min, l);
      max = Math.max(max, l);
      pixels += 1;
    }
  }
  overlayCanvas.width = width;
  overlayCanvas.height = height;
  const ctx = overlayCanvas.getContext('2d');
  const image = ctx.createImageData(width, height);
  const spread = max - min;
  for (let k = 0; k < width * height; ++k) {
    if (Number.isNaN(logs[k])) continue;  // transparent: no data
    const [r, g, b] = viridis(spread > 0 ? (logs[k] - min) / spread : 0.5);
    image.data.set([r, g, b, 255], 4 * k);
  }
  ctx.putImageData(image, 0, 0);
  overlayCanvas.style.opacity = $('overlay-opacity').value;
  overlayCanvas.hidden = false;

  Object.assign(overlay, {frame, min: pixels ? min : null, max: pixels ? max : null, pixels});
  $('legend-title').textContent = CHANNELS[overlay.channel];
  if (pixels) {
    $('legend-min').textContent = min.toFixed(2);
    $('legend-mid').textContent = ((min + max) / 2).toFixed(2);
    $('legend-max').textContent = max.toFixed(2);
    $('legend-note').textContent = `frame ${frame}: ${pixels.toLocaleString('en-US')} of ` +
        `${(width * height).toLocaleString('en-US')} pixels with an error above 0; ` +
        `largest ${formatNumber(Math.pow(10, max), 3)}`;
  } else {
    for (const id of ['legend-min', 'legend-mid', 'legend-max']) $(id).textContent = '–';
    $('legend-note').textContent = `frame ${frame}: no error data (no isosurface hit, no volume)`;
  }
}

function drawLegendBar() {
  const canvas = $('legend-bar');
  const ctx = canvas.getContext('2d');
  for (let x = 0; x < canvas.width; ++x) {
    const [r, g, b] = viridis(x / (canvas.width - 1));
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(x, 0, 1, canvas.height);
  }
}

/** The errors of the pixel under the pointer, while the overlay is on. */
function showReadout(event) {
  const array = overlay.enabled && errorArrays.get(view.frame);
  if (!array) {
    $('readout').hidden = true;
    return;
  }
  const [height, width, channels] = array.shape;
  const rect = $('stage').getBoundingClientRect();
  const i = Math.floor(((event.clientX - rect.left) / rect.width) * width);
  const j = Math.floor(((event.clientY - rect.top) / rect.height) * height);
  if (i < 0 || j < 0 || i >= width || j >= height) {
    $('readout').hidden = true;
    return;
  }
  const k = (j * width + i) * channels;
  const value = (x) => (Number.isNaN(x) ? 'none' : x.toExponential(2));
  $('readout').textContent = `pixel (${i}, ${j})\niso.residual ${value(array.data[k])}\n` +
      `vol.error    ${value(array.data[k + 1])}`;
  $('readout').hidden = false;
}

function setupOverlayControls() {
  drawLegendBar();
  $('overlay-toggle').addEventListener('change', (e) => {
    overlay.enabled = e.target.checked;
    if (!overlay.enabled) $('readout').hidden = true;
    refreshOverlay();
  });
  $('overlay-channel').addEventListener('change', (e) => {
    overlay.channel = e.target.value;
    refreshOverlay();
  });
  $('overlay-opacity').addEventListener('input', (e) => {
    overlayCanvas.style.opacity = e.target.value;
  });
}

// ---------------------------------------------------------------------------------------
// Mouse on the frame: left-drag orbits, right-drag or shift-drag pans, the wheel zooms

function setupMouse() {
  const stage = $('stage');
  let drag = null;
  stage.addEventListener('pointerdown', (e) => {
    if (!camera) return;
    const panning = e.button === 2 || e.button === 1 || (e.button === 0 && e.shiftKey);
    if (!panning && e.button !== 0) return;
    drag = {mode: panning ? 'pan' : 'orbit', x: e.clientX, y: e.clientY};
    stage.setPointerCapture(e.pointerId);
    stage.classList.add('dragging');
    e.preventDefault();
  });
  stage.addEventListener('pointermove', (e) => {
    if (!drag) {
      showReadout(e);
      return;
    }
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    if (!dx && !dy) return;
    drag.x = e.clientX;
    drag.y = e.clientY;
    const size = stage.clientHeight || 1;
    if (drag.mode === 'orbit') {
      // Half a turn for a drag across the frame's height.
      orbit(camera, (-dx * Math.PI) / size, (dy * Math.PI) / size);
    } else {
      pan(camera, dx, dy, size);
    }
    requestFrame();
  });
  const end = () => {
    drag = null;
    stage.classList.remove('dragging');
  };
  stage.addEventListener('pointerup', end);
  stage.addEventListener('pointercancel', end);
  stage.addEventListener('pointerleave', () => {
    $('readout').hidden = true;
  });
  stage.addEventListener('contextmenu', (e) => e.preventDefault());
  stage.addEventListener('wheel', (e) => {
    if (!camera) return;
    e.preventDefault();
    const pixels = e.deltaMode === 1 ? 33 * e.deltaY : e.deltaMode === 2 ? 400 * e.deltaY : e.deltaY;
    dolly(camera, Math.exp(pixels * 0.0015));
    requestFrame();
  }, {passive: false});
}

// ---------------------------------------------------------------------------------------
// Start: read /api/info, set up the panels from the scene, ask for the first frame

async function start() {
  $('message-close').addEventListener('click', clearMessage);
  // A view cancelled by another client is not rendered again by itself (two viewers would
  // cancel each other for ever), but on a click.
  $('render-again').addEventListener('click', requestFrame);
  setupOverlayControls();
  setupMouse();
  new ResizeObserver(layoutStage).observe($('view'));
  if (!token) {
    showMessage('no token: open this page as /?token=TOKEN with the token hpray serve printed');
    return;
  }
  let response;
  try {
    response = await api('/api/info');
  } catch (e) {
    showMessage(`no answer from the service: ${e.message}`);
    return;
  }
  if (!response.ok) {
    showMessage(`/api/info: ${await failureText(response)}`);
    return;
  }
  info = view.info = await response.json();
  scene = view.scene = applySetItems(info.scene, info.overrides);
  if (info.data.bounds) bounds = info.data.bounds;
  pointFields = listPointFields();
  camera = view.camera = initialCamera(scene.camera);
  homeCamera = deepCopy(camera);
  setupCameraPanel();
  showCamera();
  setupIsoPanel();
  setupVolumePanel();
  tfEditors.refresh();
  setupSlicePanel();
  setupClipPanel();
  setupExtraKeys();
  layoutStage();
  requestFrame();
}

start();
