// One part of the script of `tfmatch view`'s page; host/viewer/view_page.cpp joins the parts in
// order (viewer_core.js first, viewer_start.js last) inside one strict function scope, so they
// share its names. This one: what the page exposes to tests, HTTP with the token, errors and
// status, formatting. Plain JavaScript, no libraries, nothing from the network: every request goes
// to the tfmatch process that served the page (host/viewer/http_api.md is the contract).

const params = new URLSearchParams(location.search);
const TOKEN = params.get('token') || '';
const VIEWS = ['reference', 'field-ref-tf', 'field-opt-tf', 'residual'];
const AXES = ['x', 'y', 'z'];
const DRAG_DEG_PER_PX = 0.4;
const LOWRES_DIVISOR = 4;
const LOWRES_MIN_INTERVAL_MS = 125;   // at most 8 sets of 4 low-res images a second (the server's limit: 40 requests/s)
const WHEEL_SETTLE_MS = 250;
// This page among others on the same server: its cameras are numbered, so the server drops a
// picture still waiting for a camera this page has moved past (410) instead of rendering it.
const CLIENT = Math.random().toString(36).slice(2, 10);
let cameraSeq = 0;
const MIN_DISTANCE = 1.05, MAX_DISTANCE = 1000;  // tfmatch render: 0 (framed) or (1, 10000]

const $ = (sel, root = document) => root.querySelector(sel);
const $$ = (sel, root = document) => Array.from(root.querySelectorAll(sel));

// ---- what the page exposes (the browser test waits on these counters) ------------------------
let pending = 0;            // requests whose result is still to be shown
let jobRunning = false;
const V = {
  state: null,
  camera: { az: 0, el: 0, dist: 0, fov: 30, w: 512, h: 512 },
  lastFullResMs: null,
  lastDistance: null,       // X-Tfmatch-Distance of the last rendering
  imageVersion: 0,          // full-resolution sets of four images shown
  lowResVersion: 0,
  sliceVersion: 0,
  plotVersion: 0,
  metricsVersion: 0,
  jobsDone: 0,              // jobs ended and everything refreshed after them
  progressEvents: 0,        // progress events received while a job ran
  lastJob: null,
  imageHashes: {},          // FNV-1a of the PNG bytes shown, per view
  sliceHashes: {},
  plotHashes: {},
  imageMetrics: null,
  errors: [],               // messages shown in the error banner
};
Object.defineProperty(V, 'busy', { get: () => pending > 0 || jobRunning || !V.state });
Object.defineProperty(V, 'jobRunning', { get: () => jobRunning });
window.tfmViewer = V;

// ---- HTTP -------------------------------------------------------------------------------------
class ApiError extends Error {
  constructor(status, message) { super(message); this.status = status; }
}

function apiUrl(path, query = {}) {
  const q = new URLSearchParams();
  for (const [k, v] of Object.entries(query)) if (v !== undefined && v !== null) q.set(k, String(v));
  q.set('token', TOKEN);
  return path + '?' + q.toString();
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// fetch with the token; retries 429 (rate limit) a few times; throws ApiError for other errors.
async function api(path, query = {}, init = {}) {
  for (let attempt = 0; ; attempt++) {
    const res = await fetch(apiUrl(path, query), init);
    if (res.ok) return res;
    if (res.status === 429 && attempt < 20) { await sleep(150 + 50 * attempt); continue; }
    let message = res.statusText || ('HTTP ' + res.status);
    try {
      const body = await res.json();
      if (body && body.error) message = body.error;
    } catch (_) { /* not JSON */ }
    throw new ApiError(res.status, message);
  }
}

async function postJson(path, body) {
  return api(path, {}, {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify(body),
  });
}

const isAbort = (e) => e && (e.name === 'AbortError');

// A device request failed: 503 means a job holds the device (it refreshes everything when it
// ends); anything else goes to the banner.
function deviceError(e, what) {
  if (isAbort(e)) return;
  if (e instanceof ApiError && e.status === 410) return;  // superseded: a newer camera is on its way
  if (e instanceof ApiError && e.status === 503) { watchJob(); return; }
  showError(what + ': ' + (e.message || e));
}

function showError(message) {
  V.errors.push(message);
  const banner = $('#global-error');
  banner.textContent = message;
  banner.hidden = false;
  setStatus('error', 'bad');
}
function clearError() { $('#global-error').hidden = true; }

function setStatus(text, cls = '') {
  const s = $('#status');
  s.textContent = text;
  s.className = 'status ' + cls;
}
function refreshStatus() {
  if (jobRunning) return;  // the progress handler writes it
  if (!$('#global-error').hidden) return;
  setStatus(pending > 0 ? 'rendering…' : 'ready', pending > 0 ? 'busy' : '');
}
function begin() { pending++; refreshStatus(); }
function end() { pending--; refreshStatus(); }

// FNV-1a over the bytes: lets a test tell whether an image changed.
function hashBytes(buf) {
  const b = new Uint8Array(buf);
  let h = 0x811c9dc5;
  for (let i = 0; i < b.length; i++) { h ^= b[i]; h = Math.imul(h, 0x01000193) >>> 0; }
  return h.toString(16).padStart(8, '0') + ':' + b.length;
}

// Fetches a PNG; returns {url, hash, headers} with an object URL already decoded.
async function fetchPng(path, query, signal) {
  const res = await api(path, query, { signal });
  const buf = await res.arrayBuffer();
  const blob = new Blob([buf], { type: 'image/png' });
  const url = URL.createObjectURL(blob);
  const probe = new Image();
  probe.src = url;
  try { await probe.decode(); } catch (e) { URL.revokeObjectURL(url); throw new Error('undecodable image from ' + path); }
  return { url, hash: hashBytes(buf), headers: res.headers, width: probe.naturalWidth, height: probe.naturalHeight };
}

function showPng(img, png) {
  const old = img.dataset.objectUrl;
  img.src = png.url;
  img.dataset.objectUrl = png.url;
  if (old) URL.revokeObjectURL(old);
}

const nextFrame = () => new Promise((r) => requestAnimationFrame(() => r()));

// ---- formatting -------------------------------------------------------------------------------
function fmt(x, digits = 3) {
  if (x === null || x === undefined || x === '') return '–';
  if (typeof x === 'string') return x;
  if (!Number.isFinite(x)) return String(x);
  const a = Math.abs(x);
  if (a !== 0 && (a < 1e-3 || a >= 1e6)) return x.toExponential(2);
  return String(Number(x.toFixed(digits)));
}
const round = (x, d) => Number(Number(x).toFixed(d));
const clamp = (x, lo, hi) => Math.min(hi, Math.max(lo, x));
function wrapDeg(a) { a = ((a + 180) % 360 + 360) % 360 - 180; return a === -180 ? 180 : a; }
