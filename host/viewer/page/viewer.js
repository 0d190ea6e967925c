// tfmatch view: the page. Plain JavaScript, no libraries, nothing from the network: every request
// goes to the tfmatch process that served this page (host/viewer/http_api.md is the contract).
(() => {
  'use strict';

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

  // ---- camera -----------------------------------------------------------------------------------
  let defaultSize = null;     // {w, h}: the image size the page starts with (state or ?size=)

  function initialSize(st) {
    const w0 = st.render.width, h0 = st.render.height;
    const s = parseInt(params.get('size') || '', 10);
    if (!(s >= 16)) return { w: w0, h: h0 };
    const maxSide = Math.min(s, (st.limits && st.limits.max_image_side) || 2048);
    const k = maxSide / Math.max(w0, h0);
    return { w: clamp(Math.round(w0 * k), 16, 2048), h: clamp(Math.round(h0 * k), 16, 2048) };
  }

  function resetCamera() {
    const c = V.state.render.camera;
    V.camera = {
      az: round(c.azimuth_deg, 2), el: round(c.elevation_deg, 2), dist: round(c.distance, 3),
      fov: round(c.fov_deg, 2), w: defaultSize.w, h: defaultSize.h,
    };
  }

  function cameraQuery(cam, w, h) {
    return { az: cam.az, el: cam.el, dist: cam.dist, fov: cam.fov, w: w ?? cam.w, h: h ?? cam.h };
  }

  function renderCommand() {
    const c = V.camera;
    const view = $('#command-view').value;
    const fixed = (V.state.render_commands && V.state.render_commands[view]) || V.state.render_command;
    return `${fixed} --azimuth ${c.az} --elevation ${c.el} --distance ${c.dist} ` +
      `--fov ${c.fov} --width ${c.w} --height ${c.h}`;
  }

  function updateCameraUI() {
    const c = V.camera;
    const set = (id, v) => { const el = $(id); if (document.activeElement !== el) { el.value = v; el.classList.remove('invalid'); } };
    set('#cam-az', c.az); set('#cam-el', c.el); set('#cam-dist', c.dist);
    set('#cam-fov', c.fov); set('#cam-w', c.w); set('#cam-h', c.h);
    $('#render-command').textContent = renderCommand();
    for (const f of $$('.view-frame')) f.style.aspectRatio = `${c.w} / ${c.h}`;
    for (const a of $$('a[data-dl-view]')) {
      a.href = apiUrl('/api/render', { view: a.dataset.dlView, ...cameraQuery(c), download: 1 });
    }
    const sel = $('#image-size');
    const key = `${c.w}x${c.h}`;
    if (!Array.from(sel.options).some((o) => o.value === key)) {
      const o = document.createElement('option');
      o.value = key; o.textContent = `${c.w} × ${c.h}`;
      sel.appendChild(o);
    }
    sel.value = key;
  }

  function buildSizeChoices() {
    const sel = $('#image-size');
    sel.textContent = '';
    const w0 = V.state.render.width, h0 = V.state.render.height;
    const maxSide = (V.state.limits && V.state.limits.max_image_side) || 2048;
    const seen = new Set();
    for (const side of [128, 256, 384, 512, 768, 1024, Math.max(w0, h0), Math.max(defaultSize.w, defaultSize.h)].sort((a, b) => a - b)) {
      if (side > maxSide) continue;
      const k = side / Math.max(w0, h0);
      const w = clamp(Math.round(w0 * k), 16, 2048), h = clamp(Math.round(h0 * k), 16, 2048);
      const key = `${w}x${h}`;
      if (seen.has(key)) continue;
      seen.add(key);
      const o = document.createElement('option');
      o.value = key;
      o.textContent = `${w} × ${h}` + (w === w0 && h === h0 ? ' (command line)' : '');
      sel.appendChild(o);
    }
  }

  // ---- the four renderings ----------------------------------------------------------------------
  let imageGen = 0;
  let imageAbort = null;
  let lowInFlight = false, lowQueued = false, lastLowStart = 0;

  // Renders the four views at the current camera. full: the camera's size; else 1/4 of it.
  // t0: performance.now() of the interaction's end, to measure "full image in N ms".
  async function loadImages(full, t0) {
    if (jobRunning) return;
    const gen = ++imageGen;
    if (full && imageAbort) imageAbort.abort();
    const abort = new AbortController();
    if (full) imageAbort = abort;
    const cam = { ...V.camera };
    const w = full ? cam.w : Math.max(16, Math.round(cam.w / LOWRES_DIVISOR));
    const h = full ? cam.h : Math.max(16, Math.round(cam.h / LOWRES_DIVISOR));
    const seq = ++cameraSeq;
    begin();
    try {
      // frame=fast: PNGs encoded for speed, the same pixels as the downloads.
      const pngs = await Promise.all(VIEWS.map((view) =>
        fetchPng('/api/render', { view, ...cameraQuery(cam, w, h), frame: 'fast', client: CLIENT, seq }, abort.signal)));
      if (gen !== imageGen) { pngs.forEach((p) => URL.revokeObjectURL(p.url)); return; }
      VIEWS.forEach((view, i) => {
        showPng($(`.view[data-view="${view}"] img`), pngs[i]);
        if (full) V.imageHashes[view] = pngs[i].hash;
      });
      for (const f of $$('.view-frame')) f.classList.toggle('lowres', !full);
      const d = parseFloat(pngs[0].headers.get('X-Tfmatch-Distance'));
      if (Number.isFinite(d)) V.lastDistance = d;
      const ms = pngs.map((p) => parseFloat(p.headers.get('X-Tfmatch-Render-Ms'))).filter(Number.isFinite);
      await nextFrame();
      if (gen !== imageGen) return;
      if (full) {
        V.imageVersion++;
        if (t0 !== undefined) {
          V.lastFullResMs = Math.round(performance.now() - t0);
          $('#fullres-text').textContent = `full image in ${V.lastFullResMs} ms`;
          $('#fullres-text').title = `from the end of the interaction until all four ${w}×${h} images were shown`;
        }
        if (ms.length) $('#render-ms').textContent = `(server: ${ms.map((x) => Math.round(x)).join(' + ')} ms)`;
        loadMetrics(cam, seq);
      } else {
        V.lowResVersion++;
      }
    } catch (e) {
      deviceError(e, 'rendering');
    } finally {
      end();
    }
  }

  // While dragging: one low-res set at a time, the newest camera when the last one is shown.
  function scheduleLowRes() {
    if (lowInFlight) { lowQueued = true; return; }
    lowInFlight = true;
    lowQueued = false;
    const wait = Math.max(0, LOWRES_MIN_INTERVAL_MS - (performance.now() - lastLowStart));
    sleep(wait).then(() => {
      if (!interacting()) return undefined;   // released meanwhile: the full set is on its way
      lastLowStart = performance.now();
      if (imageAbort) imageAbort.abort();   // a full set for an older camera is of no use now
      return loadImages(false);
    }).finally(() => {
      lowInFlight = false;
      if (lowQueued && interacting()) scheduleLowRes();
    });
  }

  let drag = null;
  let wheelTimer = null;
  const interacting = () => drag !== null || wheelTimer !== null;

  function setupViewInteraction() {
    for (const frame of $$('.view-frame')) {
      frame.addEventListener('pointerdown', (ev) => {
        if (ev.button !== 0 || jobRunning || !V.state) return;
        ev.preventDefault();
        frame.setPointerCapture(ev.pointerId);
        frame.classList.add('dragging');
        drag = { frame, id: ev.pointerId, x: ev.clientX, y: ev.clientY, az: V.camera.az, el: V.camera.el, moved: false };
      });
      frame.addEventListener('pointermove', (ev) => {
        if (!drag || drag.id !== ev.pointerId) return;
        const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
        if (!drag.moved && Math.abs(dx) + Math.abs(dy) < 2) return;
        drag.moved = true;
        V.camera.az = round(wrapDeg(drag.az - dx * DRAG_DEG_PER_PX), 2);
        V.camera.el = round(clamp(drag.el + dy * DRAG_DEG_PER_PX, -90, 90), 2);
        updateCameraUI();
        scheduleLowRes();
      });
      const finish = (ev) => {
        if (!drag || drag.id !== ev.pointerId) return;
        const t0 = performance.now();
        const moved = drag.moved;
        frame.classList.remove('dragging');
        drag = null;
        lowQueued = false;
        if (moved) loadImages(true, t0);
      };
      frame.addEventListener('pointerup', finish);
      frame.addEventListener('pointercancel', finish);
      frame.addEventListener('wheel', (ev) => {
        if (jobRunning || !V.state) return;
        ev.preventDefault();
        const base = V.camera.dist > 0 ? V.camera.dist : (V.lastDistance || 3);
        const step = ev.deltaMode === 1 ? ev.deltaY * 33 : ev.deltaMode === 2 ? ev.deltaY * 400 : ev.deltaY;
        V.camera.dist = round(clamp(base * Math.exp(step * 0.0015), MIN_DISTANCE, MAX_DISTANCE), 3);
        updateCameraUI();
        if (wheelTimer) clearTimeout(wheelTimer);
        wheelTimer = setTimeout(() => {
          wheelTimer = null;
          lowQueued = false;
          loadImages(true, performance.now());
        }, WHEEL_SETTLE_MS);
        scheduleLowRes();
      }, { passive: false });
    }

    $('#reset-camera').addEventListener('click', () => {
      if (!V.state) return;
      resetCamera();
      updateCameraUI();
      loadImages(true, performance.now());
    });

    $('#image-size').addEventListener('change', (ev) => {
      const [w, h] = ev.target.value.split('x').map(Number);
      V.camera.w = w; V.camera.h = h;
      updateCameraUI();
      loadImages(true, performance.now());
    });

    const fields = [
      ['#cam-az', 'az', (v) => Number.isFinite(v), (v) => round(wrapDeg(v), 2)],
      ['#cam-el', 'el', (v) => v >= -90 && v <= 90, (v) => round(v, 2)],
      ['#cam-dist', 'dist', (v) => v === 0 || (v > 1 && v <= 1e4), (v) => round(v, 3)],
      ['#cam-fov', 'fov', (v) => v >= 0.1 && v <= 179, (v) => round(v, 2)],
      ['#cam-w', 'w', (v) => Number.isInteger(v) && v >= 16 && v <= maxSide(), (v) => v],
      ['#cam-h', 'h', (v) => Number.isInteger(v) && v >= 16 && v <= maxSide(), (v) => v],
    ];
    for (const [id, key, ok, norm] of fields) {
      const el = $(id);
      const commit = () => {
        const t = el.value.trim();
        const v = t === '' ? NaN : Number(t);
        if (!ok(v)) {
          el.classList.add('invalid');
          el.title = 'not accepted: ' + ({
            az: 'degrees', el: 'degrees in [-90, 90]', dist: '0 (framed) or (1, 10000] radii',
            fov: 'degrees in [0.1, 179]', w: `16..${maxSide()} pixels`, h: `16..${maxSide()} pixels`,
          })[key];
          return;
        }
        el.classList.remove('invalid');
        el.title = '';
        const nv = norm(v);
        if (V.camera[key] === nv) return;
        V.camera[key] = nv;
        updateCameraUI();
        if (!jobRunning) loadImages(true, performance.now());
      };
      el.addEventListener('change', commit);
      el.addEventListener('keydown', (ev) => { if (ev.key === 'Enter') { commit(); el.blur(); } });
    }

    $('#command-view').addEventListener('change', updateCameraUI);

    $('#copy-command').addEventListener('click', async () => {
      const text = $('#render-command').textContent;
      try {
        await navigator.clipboard.writeText(text);
        $('#copy-command').textContent = 'Copied';
      } catch (_) {
        const r = document.createRange();
        r.selectNodeContents($('#render-command'));
        getSelection().removeAllRanges();
        getSelection().addRange(r);
        $('#copy-command').textContent = 'Selected';
      }
      setTimeout(() => { $('#copy-command').textContent = 'Copy'; }, 1500);
    });
  }

  const maxSide = () => Math.min(2048, (V.state && V.state.limits && V.state.limits.max_image_side) || 2048);

  // ---- metrics ----------------------------------------------------------------------------------
  let metricsAbort = null;
  async function loadMetrics(cam, seq) {
    if (metricsAbort) metricsAbort.abort();
    const abort = metricsAbort = new AbortController();
    begin();
    try {
      const query = seq === undefined ? cameraQuery(cam) : { ...cameraQuery(cam), client: CLIENT, seq };
      const res = await api('/api/metrics', query, { signal: abort.signal });
      const m = await res.json();
      if (abort !== metricsAbort) return;
      V.imageMetrics = m;
      showImageMetrics(m);
      $('#metrics-note').textContent =
        `Image metrics at the current camera (${cam.w}×${cam.h}), against the reference image.`;
      V.metricsVersion++;
    } catch (e) {
      deviceError(e, 'metrics');
    } finally {
      end();
    }
  }

  function numberOf(v) { return typeof v === 'number' ? v : (v === 'inf' ? Infinity : parseFloat(v)); }

  function setPair(idRef, idOpt, a, b, lowerIsBetter, digits) {
    const ra = $(idRef), rb = $(idOpt);
    const fa = (v) => (v === 'inf' || v === Infinity) ? '∞' : fmt(numberOf(v), digits);
    ra.textContent = a === undefined ? '–' : fa(a);
    rb.textContent = b === undefined ? '–' : fa(b);
    const na = numberOf(a), nb = numberOf(b);
    rb.classList.toggle('better', Number.isFinite(na) && !Number.isNaN(nb) && (lowerIsBetter ? nb < na : nb > na));
  }

  function showImageMetrics(m) {
    const r = m.reference_tf || {}, o = m.optimized_tf || {};
    setPair('#m-rmse-ref', '#m-rmse-opt', r.rmse, o.rmse, true, 2);
    setPair('#m-psnr-ref', '#m-psnr-opt', r.psnr, o.psnr, false, 2);
    setPair('#m-ssim-ref', '#m-ssim-opt', r.ssim, o.ssim, false, 4);
  }

  function showStateMetrics() {
    const m = V.state.metrics || {};
    setPair('#m-vox-ref', '#m-vox-opt', m.voxel_rmse_reference_tf, m.voxel_rmse_optimized_tf, true, 4);
    const list = $('#warnings');
    list.textContent = '';
    for (const w of V.state.warnings || []) {
      const li = document.createElement('li');
      li.textContent = w;
      list.appendChild(li);
    }
    $('#warnings-box').hidden = !(V.state.warnings && V.state.warnings.length);
  }

  // ---- slices -----------------------------------------------------------------------------------
  let sliceGen = 0, sliceInFlight = false, sliceQueued = false;
  let sliceShown = null;   // {axis, index} of the images on screen

  const sliceAxis = () => $('input[name="slice-axis"]:checked').value;
  const sliceIndex = () => parseInt($('#slice-index').value, 10);
  const dims = () => V.state.grid.dims;

  function sliceSize() {
    const s = parseInt(params.get('slice') || '', 10);
    const lim = (V.state.limits && V.state.limits.max_slice_size) || 1024;
    if (s >= 64) return Math.min(s, lim);
    const fig = $('.slice');
    const css = fig ? fig.clientWidth : 300;
    return clamp(Math.round(css * Math.min(2, window.devicePixelRatio || 1)), 64, Math.min(lim, 768));
  }

  // across/up axes of a slice picture (http_api.md: z -> x,y; y -> x,z; x -> y,z)
  function sliceLayout(axis) {
    const d = dims();
    if (axis === 'z') return { across: 0, up: 1, nAcross: d[0], nUp: d[1] };
    if (axis === 'y') return { across: 0, up: 2, nAcross: d[0], nUp: d[2] };
    return { across: 1, up: 2, nAcross: d[1], nUp: d[2] };
  }

  function axisName(i) {
    const a = V.state.grid.axes && V.state.grid.axes[i];
    return a && a.name ? a.name : AXES[i];
  }

  function setSliceAxis(axis, index) {
    const n = dims()[AXES.indexOf(axis)];
    $(`input[name="slice-axis"][value="${axis}"]`).checked = true;
    const s = $('#slice-index');
    s.max = String(n - 1);
    s.value = String(clamp(index, 0, n - 1));
    updateSliceLabel();
  }

  // Each slice picture framed by its axes: the vertical axis's last and first coordinates at its
  // top and bottom, the horizontal axis's first and last below it, both named (the picture itself
  // stays the click target, so http_api.md's click formula holds).
  function buildSliceAxes() {
    for (const frame of $$('.slice-frame')) {
      const body = document.createElement('div');
      body.className = 'slice-body';
      frame.replaceWith(body);
      const v = document.createElement('div');
      v.className = 'axis-v';
      v.innerHTML = '<span class="last"></span><span class="name"></span><span class="first"></span>';
      const h = document.createElement('div');
      h.className = 'axis-h';
      h.innerHTML = '<span class="first"></span><span class="name"></span><span class="last"></span>';
      body.append(v, frame, document.createElement('div'), h);
    }
  }

  function updateSliceAxes(axis) {
    const L = sliceLayout(axis);
    const ax = (i) => (V.state.grid.axes && V.state.grid.axes[i]) || {};
    const label = (i) => axisName(i) + (ax(i).units ? ` (${ax(i).units})` : '');
    const value = (i, key, n) => fmt(ax(i)[key] !== undefined ? ax(i)[key] : (key === 'first' ? 0 : n - 1), 4);
    for (const [cls, i, n] of [['.axis-h', L.across, L.nAcross], ['.axis-v', L.up, L.nUp]]) {
      for (const el of $$(cls)) {
        $('.first', el).textContent = value(i, 'first', n);
        $('.last', el).textContent = value(i, 'last', n);
        $('.name', el).textContent = label(i);
      }
    }
  }

  function updateSliceLabel() {
    const axis = sliceAxis(), i = AXES.indexOf(axis);
    const ax = V.state.grid.axes && V.state.grid.axes[i];
    const units = ax && ax.units ? ` ${ax.units}` : '';
    $('#slice-label').textContent = `${axis} index ${sliceIndex()} of 0…${dims()[i] - 1}` +
      (ax && ax.name && ax.name !== axis ? ` (${ax.name}${units})` : '');
  }

  function scheduleSlices() {
    if (jobRunning) return;
    if (sliceInFlight) { sliceQueued = true; return; }
    sliceInFlight = true;
    sliceQueued = false;
    loadSlices().finally(() => {
      sliceInFlight = false;
      if (sliceQueued) scheduleSlices();
    });
  }

  async function loadSlices() {
    if (jobRunning) return;
    const gen = ++sliceGen;
    const axis = sliceAxis(), index = sliceIndex(), size = sliceSize();
    const shade = $('#slice-shade').checked ? 'opacity' : 'colour';
    begin();
    try {
      const pngs = await Promise.all(VIEWS.map((view) => fetchPng('/api/slice', { view, axis, index, size, shade })));
      if (gen !== sliceGen) { pngs.forEach((p) => URL.revokeObjectURL(p.url)); return; }
      VIEWS.forEach((view, i) => {
        showPng($(`.slice[data-view="${view}"] img`), pngs[i]);
        V.sliceHashes[view] = pngs[i].hash;
      });
      sliceShown = { axis, index };
      updateSliceAxes(axis);
      updateMarkers();
      await nextFrame();
      V.sliceVersion++;
    } catch (e) {
      deviceError(e, 'slices');
    } finally {
      end();
    }
  }

  function updateMarkers() {
    const st = V.state;
    const point = st && st.mode === 'ensemble' && st.ensemble && st.ensemble.point;
    for (const m of $$('.slice .marker')) {
      if (!point || !sliceShown) { m.hidden = true; continue; }
      const a = AXES.indexOf(sliceShown.axis);
      const L = sliceLayout(sliceShown.axis);
      if (point[a] !== sliceShown.index) { m.hidden = true; continue; }
      m.style.left = `${((point[L.across] + 0.5) / L.nAcross) * 100}%`;
      m.style.top = `${(1 - (point[L.up] + 0.5) / L.nUp) * 100}%`;
      m.title = `reference point (${point.join(', ')})`;
      m.hidden = false;
    }
  }

  // The voxel under a position on a slice picture (http_api.md's click formula).
  function voxelAt(img, clientX, clientY) {
    if (!sliceShown) return null;
    const r = img.getBoundingClientRect();
    const fx = (clientX - r.left) / r.width, fy = (clientY - r.top) / r.height;
    if (!(fx >= 0 && fx < 1 && fy >= 0 && fy < 1)) return null;
    const L = sliceLayout(sliceShown.axis);
    const p = [0, 0, 0];
    p[AXES.indexOf(sliceShown.axis)] = sliceShown.index;
    p[L.across] = Math.floor(fx * L.nAcross);
    p[L.up] = L.nUp - 1 - Math.floor(fy * L.nUp);
    return p;
  }

  function setupSlices() {
    for (const r of $$('input[name="slice-axis"]')) {
      r.addEventListener('change', () => {
        const axis = sliceAxis(), a = AXES.indexOf(axis);
        const st = V.state;
        const p = st.mode === 'ensemble' && st.ensemble && st.ensemble.point;
        setSliceAxis(axis, p ? p[a] : Math.floor(dims()[a] / 2));
        scheduleSlices();
      });
    }
    $('#slice-index').addEventListener('input', () => { updateSliceLabel(); scheduleSlices(); });
    $('#slice-shade').addEventListener('change', scheduleSlices);
    buildSliceAxes();
    for (const img of $$('.slice img')) {
      img.addEventListener('mousemove', (ev) => {
        const p = voxelAt(img, ev.clientX, ev.clientY);
        $('#slice-hover').textContent = p ? `voxel (${p.join(', ')})` +
          (V.state.mode === 'ensemble' && !jobRunning ? ' — click to make it the reference point' : '') : '';
      });
      img.addEventListener('mouseleave', () => { $('#slice-hover').textContent = ''; });
      img.addEventListener('click', (ev) => {
        if (!V.state || V.state.mode !== 'ensemble' || jobRunning) return;
        const p = voxelAt(img, ev.clientX, ev.clientY);
        if (p) setReferencePoint(p);
      });
    }
  }

  // ---- series: the field shown -------------------------------------------------------------------
  let seriesDragging = false;  // the slider is being moved: state updates leave it alone
  function initSeries() {
    const slider = $('#series-slider');
    slider.addEventListener('input', () => {
      seriesDragging = true;
      const ser = V.state && V.state.series;
      if (ser) $('#series-index').textContent = `${slider.value}: ${ser.labels[Number(slider.value)]}`;
    });
    slider.addEventListener('change', () => {
      seriesDragging = false;
      if (!V.state || V.state.mode !== 'series' || jobRunning) return;
      if (Number(slider.value) !== V.state.series.index) setField(Number(slider.value));
    });
  }

  // POSTs a change that runs as a job (`kind`): its error in `box`, `pending` shown in `label`
  // while it starts. Returns whether the job started.
  async function postJob(path, body, box, label, pending, kind) {
    box.hidden = true;
    begin();
    try {
      const res = await postJson(path, body);
      const started = await res.json();
      label.textContent = pending;
      startJob(started.job, kind);
      return true;
    } catch (e) {
      if (e instanceof ApiError && e.status === 409) { watchJob(); }
      box.textContent = e.message || String(e);
      box.hidden = false;
      return false;
    } finally {
      end();
    }
  }

  async function setField(index) {
    const started = await postJob('/api/field', { index }, $('#series-error'), $('#series-index'),
      `${index}: ${V.state.series.labels[index]} — loading and fitting…`, 'field');
    if (!started) $('#series-slider').value = String(V.state.series.index);  // back to the field shown
  }

  async function setReferencePoint(p) {
    await postJob('/api/point', { point: p }, $('#point-error'), $('#point-text'), `(${p.join(', ')}) — computing…`, 'point');
  }

  // ---- TF plots ---------------------------------------------------------------------------------
  let plotGen = 0;
  async function loadPlots() {
    if (jobRunning) return;
    const gen = ++plotGen;
    const fig = $('.plot');
    const pw = parseInt(params.get('plot') || '', 10);
    const w = clamp(pw >= 160 ? pw : Math.round((fig ? fig.clientWidth : 300) * Math.min(2, window.devicePixelRatio || 1)), 160, 2048);
    const h = clamp(Math.round(w * 0.62), 140, 1024);
    const histogram = $('#histogram-scale').value;
    begin();
    try {
      const pngs = await Promise.all(VIEWS.map((which) => fetchPng('/api/tf-plot', { which, w, h, histogram })));
      if (gen !== plotGen) { pngs.forEach((p) => URL.revokeObjectURL(p.url)); return; }
      VIEWS.forEach((which, i) => {
        showPng($(`.plot[data-which="${which}"] img`), pngs[i]);
        V.plotHashes[which] = pngs[i].hash;
      });
      await nextFrame();
      V.plotVersion++;
    } catch (e) {
      deviceError(e, 'TF plots');
    } finally {
      end();
    }
  }

  // ---- state ------------------------------------------------------------------------------------
  async function loadState() {
    begin();
    try {
      const res = await api('/api/state');
      V.state = await res.json();
      applyState();
      return V.state;
    } finally {
      end();
    }
  }

  let solversKey = '';
  function applyState() {
    const st = V.state;
    document.title = `tfmatch view — ${st.title || ''}`;
    $('#title').textContent = st.title || '';
    $('#mode-badge').textContent = st.mode === 'ensemble' ? 'ensemble' : st.mode === 'series' ? 'series of fields' : 'pair of fields';
    document.body.classList.toggle('ensemble', st.mode === 'ensemble');
    const fr = st.fields || {};
    const range = (f) => f && f.range ? ` [${fmt(f.range[0])}, ${fmt(f.range[1])}]` : '';
    $('[data-caption="reference"]').textContent = fr.reference ? `${fr.reference.name}${range(fr.reference)}` : '';
    $('[data-caption="field"]').textContent = fr.field ? `${fr.field.name}${range(fr.field)}` : '';
    const opt = st.optimized_tf || {};
    $('#opt-solver-caption').textContent = opt.solver ? `solver ${opt.solver}` : '';
    $('#current-solver').textContent = st.solver ? `current TF from ${opt.solver || st.solver.name}` : '';

    const ens = st.mode === 'ensemble' && st.ensemble;
    $('#ensemble-panel').hidden = !ens;
    if (ens) {
      $('#ensemble-text').textContent =
        `${ens.members} members: the TF of the ${ens.versus} field is fitted to the ${ens.measure} field (reference).`;
      $('#point-text').textContent = ens.point_text || `(${(ens.point || []).join(', ')})`;
    }

    const ser = st.mode === 'series' && st.series;
    $('#series-panel').hidden = !ser;
    if (ser) {
      const slider = $('#series-slider');
      slider.max = String(ser.count - 1);
      if (!seriesDragging) slider.value = String(ser.index);
      $('#series-text').textContent = `${ser.count} fields against one reference; each gets its own TF when shown.`;
      $('#series-index').textContent = `${ser.index}: ${ser.labels[ser.index]}`;
    }

    showStateMetrics();

    const key = JSON.stringify(st.solvers.map((s) => [s.name, s.options.map((o) => o.name), s.ridge, s.smooth]));
    if (key !== solversKey) { solversKey = key; buildSolverForm(); }

    $('#dl-opt-json').href = apiUrl('/api/download', { what: 'optimized-tf.json' });
    $('#dl-opt-pv').href = apiUrl('/api/download', { what: 'optimized-tf.paraview.json' });
    $('#dl-ref-json').href = apiUrl('/api/download', { what: 'reference-tf.json' });
    $('#dl-residual').href = apiUrl('/api/download', { what: 'residual.vti' });
    // The render commands name these files; servers that give per-view commands serve them.
    $('#dl-inputs').hidden = !st.render_commands;
    $('#dl-ref-vti').href = apiUrl('/api/download', { what: 'reference.vti' });
    $('#dl-field-vti').href = apiUrl('/api/download', { what: 'field.vti' });
    $('#dl-res-tf').href = apiUrl('/api/download', { what: 'residual-tf.json' });
    $('#command-view').hidden = !st.render_commands;
    if (V.camera && defaultSize) $('#render-command').textContent = renderCommand();

    if (!editor.dirty) editor.load(st.ref_tf.points);
    updateMarkers();
  }

  // Everything that depends on the TFs or fields, shown again (after a job, after Apply, after
  // another page's change). `refreshing` lets a version event wait for a refresh already on its way.
  let refreshing = null;
  async function refreshAll() {
    const p = refreshing = (async () => {
      await loadState();
      if (jobRunning) return;
      await Promise.all([loadImages(true), loadSlices(), loadPlots()]);
    })();
    try {
      await p;
    } finally {
      if (refreshing === p) refreshing = null;
    }
  }

  // ---- solver form ------------------------------------------------------------------------------
  const formValues = {};   // solver -> {option -> value typed}, kept while switching solvers

  function buildSolverForm() {
    const sel = $('#solver-select');
    const chosen = sel.value || V.state.solver.name;
    sel.textContent = '';
    for (const s of V.state.solvers) {
      const o = document.createElement('option');
      o.value = s.name;
      o.textContent = s.name + (s.image_based ? ' (image-based)' : '');
      sel.appendChild(o);
    }
    sel.value = V.state.solvers.some((s) => s.name === chosen) ? chosen : V.state.solvers[0].name;
    renderSolverOptions();
  }

  function solverByName(name) { return V.state.solvers.find((s) => s.name === name); }

  function startingValue(solver, name, fallback) {
    const typed = formValues[solver] && formValues[solver][name];
    if (typed !== undefined) return typed;
    const cur = V.state.solver;
    if (cur && cur.name === solver) {
      if (name === 'ridge' || name === 'smooth') return String(cur[name] ?? fallback);
      if (cur.options && cur.options[name] !== undefined) return String(cur.options[name]);
    }
    return fallback;
  }

  function remember(solver, name, value) {
    (formValues[solver] = formValues[solver] || {})[name] = value;
  }

  function renderSolverOptions() {
    const name = $('#solver-select').value;
    const s = solverByName(name);
    const box = $('#solver-options');
    box.textContent = '';
    $('#solver-summary').textContent = s ? s.summary + (s.box ? ` (box [0, 1]: ${s.box})` : '') : '';
    $('#solver-error').hidden = true;
    if (!s) return;

    const addRow = (optName, control, hintText, help) => {
      const label = document.createElement('label');
      label.className = 'opt-name';
      label.textContent = optName;
      label.htmlFor = control.id;
      if (help) label.title = help;
      const wrap = document.createElement('div');
      wrap.className = 'opt-input';
      wrap.appendChild(control);
      if (hintText) {
        const h = document.createElement('span');
        h.className = 'hint';
        h.textContent = hintText;
        wrap.appendChild(h);
      }
      box.appendChild(label);
      box.appendChild(wrap);
    };

    for (const o of s.options) {
      let control;
      const id = 'opt-' + o.name;
      if (o.type === 'choice') {
        control = document.createElement('select');
        for (const c of o.choices || []) {
          const op = document.createElement('option');
          op.value = c; op.textContent = c;
          control.appendChild(op);
        }
        control.value = startingValue(name, o.name, o.default);
        control.addEventListener('change', () => remember(name, o.name, control.value));
      } else if (o.type === 'flag') {
        control = document.createElement('input');
        control.type = 'checkbox';
        const v = startingValue(name, o.name, o.default || '');
        control.checked = ['true', '1', 'on', 'yes'].includes(String(v).toLowerCase());
        control.addEventListener('change', () => remember(name, o.name, control.checked ? 'true' : 'false'));
      } else {
        control = document.createElement('input');
        control.type = 'text';
        control.inputMode = o.type === 'text' ? 'text' : 'decimal';
        // A default that is a value fills the field; one that describes a rule ("0.02 with adam,
        // 1 with sgd") stays a placeholder, and an empty field means "the default".
        const def = o.default || '';
        const isValue = o.type === 'text' || (def !== '' && valueLooksValid(o.type, def));
        control.value = startingValue(name, o.name, isValue ? def : '');
        control.placeholder = def ? `default: ${def}` : '';
        control.addEventListener('input', () => {
          remember(name, o.name, control.value);
          control.classList.toggle('invalid', !valueLooksValid(o.type, control.value));
        });
      }
      control.id = id;
      control.dataset.option = o.name;
      control.dataset.type = o.type;
      control.dataset.default = o.default || '';
      const hint = [o.help, o.values ? o.values : '', o.default ? `default ${o.default}` : ''].filter(Boolean).join('; ');
      addRow(o.name, control, hint, o.help);
    }
    for (const reg of ['ridge', 'smooth']) {
      if (!s[reg]) continue;
      const control = document.createElement('input');
      control.type = 'text';
      control.inputMode = 'decimal';
      control.id = 'opt-' + reg;
      control.dataset.regularization = reg;
      control.value = startingValue(name, reg, '0');
      control.addEventListener('input', () => {
        remember(name, reg, control.value);
        control.classList.toggle('invalid', !valueLooksValid('number', control.value) || Number(control.value) < 0);
      });
      addRow(reg, control, reg === 'ridge' ? 'Tikhonov weight λ ≥ 0; default 0' : 'smoothness weight λ ≥ 0 (first differences); default 0');
    }
  }

  function valueLooksValid(type, text) {
    const t = text.trim();
    if (t === '') return true;  // the default
    if (type === 'number') return Number.isFinite(Number(t));
    if (type === 'integer') return /^\d+$/.test(t);
    return true;
  }

  function collectSolverRequest() {
    const name = $('#solver-select').value;
    const body = { solver: name, options: {} };
    for (const c of $$('#solver-options [data-option]')) {
      const type = c.dataset.type, def = c.dataset.default;
      if (type === 'flag') {
        if (c.checked) body.options[c.dataset.option] = 'true';
        else if (['true', '1', 'on'].includes(def)) body.options[c.dataset.option] = 'false';
        continue;
      }
      const v = c.value.trim();
      if (v === '' || v === def) continue;
      body.options[c.dataset.option] = v;
    }
    for (const c of $$('#solver-options [data-regularization]')) {
      const t = c.value.trim();
      const v = t === '' ? 0 : Number(t);
      if (!Number.isFinite(v) || v < 0) throw new Error(`${c.dataset.regularization}: not a number ≥ 0: '${t}'`);
      body[c.dataset.regularization] = v;
    }
    return body;
  }

  function setupSolverForm() {
    $('#solver-select').addEventListener('change', renderSolverOptions);
    $('#solver-form').addEventListener('submit', async (ev) => {
      ev.preventDefault();
      if (jobRunning) return;
      const err = $('#solver-error');
      err.hidden = true;
      let body;
      try { body = collectSolverRequest(); } catch (e) { err.textContent = e.message; err.hidden = false; return; }
      $('#run-button').disabled = true;
      try {
        const res = await postJson('/api/optimize', body);
        const r = await res.json();
        startJob(r.job, 'optimize');
      } catch (e) {
        err.textContent = e.message || String(e);
        err.hidden = false;
        if (e instanceof ApiError && e.status === 409) watchJob();
      } finally {
        $('#run-button').disabled = jobRunning;
      }
    });
  }

  // ---- jobs -------------------------------------------------------------------------------------
  let jobSource = null;      // EventSource of the job followed
  let jobExpected = null;    // id of the job started here (events of older jobs are ignored)
  let jobPoll = null;

  function setJobUI(running) {
    document.body.classList.toggle('job-running', running);
    for (const el of ['#run-button', '#tf-apply', '#reset-camera', '#image-size', '#slice-index', '#histogram-scale',
                      '#series-slider']) {
      $(el).disabled = running;
    }
    for (const el of $$('input[name="slice-axis"], .camera-fields input')) el.disabled = running;
  }

  function startJob(id, kind) {
    jobExpected = id;
    jobRunning = true;
    setJobUI(true);
    if (imageAbort) imageAbort.abort();
    const bar = $('#progress-bar');
    bar.style.width = '0';
    $('#progress-label').textContent = kind === 'point' ? 'reference point: starting…' : kind === 'field' ? 'field: loading…' : 'starting…';
    $('#progress-numbers').textContent = '';
    $('#progress').hidden = false;
    $('#job-message').hidden = true;
    setStatus('job running…', 'busy');
    if (!pageStream) followProgress();  // else the page's own stream brings the job's progress
  }

  // ---- other pages on the same server ----------------------------------------------------------
  // One stream for the page's life (?follow=1): a job started and a change applied from another
  // page or browser show here too. Pushed out by newer streams (the server keeps 16), it stops;
  // the page then notices others' jobs when the device answers 503, as before.
  let pageStream = null;
  let ownChanges = 0;        // this page's changes in flight: their versions are refreshed by them

  function followServer() {
    const es = pageStream = new EventSource(apiUrl('/api/progress', { follow: 1 }));
    es.onmessage = (ev) => {
      let job;
      try { job = JSON.parse(ev.data); } catch (_) { return; }
      if (job.state === 'running' && !jobRunning && (jobExpected === null || job.id >= jobExpected)) {
        startJob(job.id, job.kind);
        return;
      }
      onJobUpdate(job);
    };
    es.addEventListener('version', async (ev) => {
      let version;
      try { version = JSON.parse(ev.data).version; } catch (_) { return; }
      if (refreshing) await refreshing.catch(() => {});
      if (!V.state || jobRunning || ownChanges > 0 || !(version > V.state.version)) return;
      refreshAll().catch((e) => deviceError(e, "showing another page's change"));
    });
    es.addEventListener('replaced', () => {
      es.close();
      if (pageStream === es) pageStream = null;
    });
  }

  // Something answered 503 or 409: a job runs that this page did not start (or lost track of).
  async function watchJob() {
    if (jobRunning) return;
    try {
      const res = await api('/api/job');
      const job = await res.json();
      if (job.state === 'running' && !jobRunning) startJob(job.id, job.kind);
    } catch (_) { /* the next action tries again */ }
  }

  function followProgress() {
    if (jobSource) jobSource.close();
    const es = jobSource = new EventSource(apiUrl('/api/progress'));
    es.onmessage = (ev) => {
      let job;
      try { job = JSON.parse(ev.data); } catch (_) { return; }
      onJobUpdate(job);
    };
    es.onerror = () => {
      // The server closes the stream after the last event; if the end was missed, ask /api/job.
      es.close();
      if (jobSource === es) jobSource = null;
      if (jobRunning) pollJob();
    };
  }

  function pollJob() {
    if (jobPoll) return;
    jobPoll = setInterval(async () => {
      try {
        const job = await (await api('/api/job')).json();
        onJobUpdate(job);
      } catch (_) { /* keep polling */ }
      if (!jobRunning) { clearInterval(jobPoll); jobPoll = null; }
    }, 500);
  }

  function onJobUpdate(job) {
    if (!jobRunning) return;
    if (jobExpected !== null && job.id !== undefined && job.id < jobExpected) return;  // an older job
    if (job.state === 'running') {
      V.progressEvents++;
      showProgress(job);
      return;
    }
    if (job.state === 'idle') return;
    if (jobSource) { jobSource.close(); jobSource = null; }
    onJobEnd(job);
  }

  function elapsedText(s) {
    if (!Number.isFinite(s)) return '';
    if (s < 60) return `${s.toFixed(1)} s`;
    return `${Math.floor(s / 60)}m${String(Math.round(s % 60)).padStart(2, '0')}s`;
  }

  function showProgress(job) {
    const bar = $('#progress-bar');
    const total = Number(job.total), done = Number(job.done);
    let pct = null;
    if (total > 0 && Number.isFinite(done)) pct = clamp(100 * done / total, 0, 100);
    bar.classList.toggle('indeterminate', pct === null);
    bar.style.width = pct === null ? '' : `${pct}%`;
    $('#progress-label').textContent = (job.kind === 'point' ? 'reference point: ' : '') + (job.label || 'running');
    $('#progress-numbers').textContent =
      (pct === null ? '' : `${Math.floor(pct)}% (${done}/${total})`) + (job.elapsed_s !== undefined ? ` · ${elapsedText(job.elapsed_s)}` : '');
    setStatus(`${job.label || 'job'} ${pct === null ? '' : Math.floor(pct) + '%'}`, 'busy');
  }

  async function onJobEnd(job) {
    if (jobPoll) { clearInterval(jobPoll); jobPoll = null; }
    jobRunning = false;
    jobExpected = null;
    setJobUI(false);
    V.lastJob = job;
    $('#progress').hidden = true;
    const msg = $('#job-message');
    if (job.state === 'done') {
      const r = job.result || {};
      msg.className = 'job-message ok';
      msg.textContent = `${job.kind === 'point' ? 'New reference point; ' : ''}${r.solver || job.label || 'solver'} done` +
        (r.ms !== undefined ? ` in ${fmt(r.ms / 1000, 2)} s` : '') +
        (r.voxel_rmse_optimized_tf !== undefined ? `: voxel RMSE ${fmt(r.voxel_rmse_reference_tf, 4)} → ${fmt(r.voxel_rmse_optimized_tf, 4)}` : '');
    } else {
      msg.className = 'job-message bad';
      msg.textContent = `${job.kind === 'point' ? 'Reference point' : 'Optimization'} failed: ${job.error || 'unknown error'}`;
      if (job.kind === 'point') { $('#point-error').textContent = job.error || 'failed'; $('#point-error').hidden = false; }
      else { $('#solver-error').textContent = job.error || 'failed'; $('#solver-error').hidden = false; }
    }
    msg.hidden = false;
    refreshStatus();
    try {
      await refreshAll();
    } catch (e) {
      deviceError(e, 'refresh after the job');
    }
    V.jobsDone++;
  }

  // ---- reference-TF editor ----------------------------------------------------------------------
  const editor = (() => {
    const canvas = $('#tf-canvas');
    const ctx = canvas.getContext('2d');
    const PAD_L = 48, PAD_R = 14, PAD_T = 12;
    const BAR_H = 20, HANDLE = 12;
    const ed = {
      opacity: [], color: [], sel: null, drag: null, dirty: false, amax: 1,
    };

    function geometry() {
      const W = canvas.clientWidth, H = canvas.clientHeight;
      const plotBottom = H - 70;
      return {
        W, H, x0: PAD_L, x1: W - PAD_R, y0: PAD_T, y1: plotBottom,
        barTop: plotBottom + 8, barBottom: plotBottom + 8 + BAR_H,
        handleY: plotBottom + 8 + BAR_H + 4 + HANDLE / 2,
      };
    }
    const gx = (g, x) => g.x0 + x * (g.x1 - g.x0);
    const gy = (g, a) => g.y1 - (a / ed.amax) * (g.y1 - g.y0);
    const fromX = (g, px) => clamp((px - g.x0) / (g.x1 - g.x0), 0, 1);
    const fromY = (g, py) => clamp(((g.y1 - py) / (g.y1 - g.y0)) * ed.amax, 0, Math.min(1, ed.amax));

    function hexToRgb(h) {
      const n = parseInt(h.slice(1), 16);
      return [(n >> 16) & 255, (n >> 8) & 255, n & 255];
    }
    function rgbToHex(c) { return '#' + c.map((v) => clamp(Math.round(v), 0, 255).toString(16).padStart(2, '0')).join(''); }
    function colorAt(x) {
      const c = ed.color;
      if (x <= c[0].x) return hexToRgb(c[0].rgb);
      for (let i = 1; i < c.length; i++) {
        if (x <= c[i].x) {
          const w = (x - c[i - 1].x) / Math.max(1e-9, c[i].x - c[i - 1].x);
          const a = hexToRgb(c[i - 1].rgb), b = hexToRgb(c[i].rgb);
          return a.map((v, k) => v + w * (b[k] - v));
        }
      }
      return hexToRgb(c[c.length - 1].rgb);
    }
    function opacityAt(x) {
      const o = ed.opacity;
      if (x <= o[0].x) return o[0].a;
      for (let i = 1; i < o.length; i++) {
        if (x <= o[i].x) {
          const w = (x - o[i - 1].x) / Math.max(1e-9, o[i].x - o[i - 1].x);
          return o[i - 1].a + w * (o[i].a - o[i - 1].a);
        }
      }
      return o[o.length - 1].a;
    }

    const AMAX_CHOICES = [1, 0.5, 0.25, 0.1, 0.05, 0.02];
    function chooseAmax() {
      const m = Math.max(...ed.opacity.map((p) => p.a), 1e-6);
      let best = 1;
      for (const c of AMAX_CHOICES) if (c >= m * 1.15) best = c;
      ed.amax = best;
      $('#editor-amax').value = String(best);
    }

    function load(points) {
      ed.opacity = points.opacity.map((p) => ({ x: p.x, a: p.a }));
      ed.color = points.color.map((p) => ({ x: p.x, rgb: p.rgb.toLowerCase() }));
      ed.sel = null;
      ed.dirty = false;
      chooseAmax();
      selectionChanged();
      draw();
    }

    function rangeValue(x) {
      const f = V.state && V.state.fields && V.state.fields.reference;
      if (!f || !f.range) return '';
      return fmt(f.range[0] + x * (f.range[1] - f.range[0]));
    }

    function selectionChanged() {
      const s = ed.sel;
      const info = $('#editor-selection');
      const color = $('#tf-color');
      if (!s) {
        info.textContent = `${ed.opacity.length} opacity points, ${ed.color.length} colour points` + (ed.dirty ? ' (edited, not applied)' : '');
        color.disabled = true;
        $('#tf-remove').disabled = true;
        return;
      }
      if (s.kind === 'o') {
        const p = ed.opacity[s.i];
        info.textContent = `opacity point ${s.i + 1}/${ed.opacity.length}: x ${p.x.toFixed(3)} (value ${rangeValue(p.x)}), opacity ${p.a.toFixed(3)}`;
        color.disabled = true;
        $('#tf-remove').disabled = ed.opacity.length <= 2;
      } else {
        const p = ed.color[s.i];
        info.textContent = `colour point ${s.i + 1}/${ed.color.length}: x ${p.x.toFixed(3)} (value ${rangeValue(p.x)}), ${p.rgb}`;
        color.disabled = false;
        color.value = p.rgb;
        $('#tf-remove').disabled = ed.color.length <= 2;
      }
    }

    function resize() {
      const dpr = window.devicePixelRatio || 1;
      const w = Math.max(100, Math.round(canvas.clientWidth * dpr)), h = Math.max(100, Math.round(canvas.clientHeight * dpr));
      if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
      ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    }

    function draw() {
      if (!ed.opacity.length || !ed.color.length) return;
      resize();
      const g = geometry();
      ctx.clearRect(0, 0, g.W, g.H);
      ctx.font = '12px "DejaVu Sans", sans-serif';
      // grid and axis labels
      ctx.strokeStyle = '#e3e6ea';
      ctx.fillStyle = '#5b6470';
      ctx.lineWidth = 1;
      ctx.textAlign = 'right';
      ctx.textBaseline = 'middle';
      for (let k = 0; k <= 4; k++) {
        const a = (ed.amax * k) / 4, y = Math.round(gy(g, a)) + 0.5;
        ctx.beginPath(); ctx.moveTo(g.x0, y); ctx.lineTo(g.x1, y); ctx.stroke();
        ctx.fillText(fmt(a, 3), g.x0 - 6, y);
      }
      ctx.textBaseline = 'alphabetic';
      for (let k = 0; k <= 4; k++) {
        const x = Math.round(gx(g, k / 4)) + 0.5;
        ctx.beginPath(); ctx.moveTo(x, g.y0); ctx.lineTo(x, g.y1); ctx.stroke();
        ctx.textAlign = k === 0 ? 'left' : k === 4 ? 'right' : 'center';
        ctx.fillText(rangeValue(k / 4), x, g.H - 4);
      }
      ctx.save();
      ctx.translate(12, (g.y0 + g.y1) / 2);
      ctx.rotate(-Math.PI / 2);
      ctx.textAlign = 'center';
      ctx.fillText('opacity', 0, 0);
      ctx.restore();

      // area under the opacity curve, coloured by the TF
      const grad = ctx.createLinearGradient(g.x0, 0, g.x1, 0);
      const stops = 64;
      for (let k = 0; k <= stops; k++) {
        const c = colorAt(k / stops);
        grad.addColorStop(k / stops, `rgba(${c[0] | 0},${c[1] | 0},${c[2] | 0},0.55)`);
      }
      ctx.beginPath();
      ctx.moveTo(gx(g, 0), g.y1);
      ctx.lineTo(gx(g, 0), gy(g, Math.min(ed.amax, opacityAt(0))));
      for (const p of ed.opacity) ctx.lineTo(gx(g, p.x), gy(g, Math.min(ed.amax, p.a)));
      ctx.lineTo(gx(g, 1), gy(g, Math.min(ed.amax, opacityAt(1))));
      ctx.lineTo(gx(g, 1), g.y1);
      ctx.closePath();
      ctx.fillStyle = grad;
      ctx.fill();
      ctx.beginPath();
      ctx.moveTo(gx(g, 0), gy(g, Math.min(ed.amax, opacityAt(0))));
      for (const p of ed.opacity) ctx.lineTo(gx(g, p.x), gy(g, Math.min(ed.amax, p.a)));
      ctx.lineTo(gx(g, 1), gy(g, Math.min(ed.amax, opacityAt(1))));
      ctx.strokeStyle = '#1f2328';
      ctx.lineWidth = 2;
      ctx.stroke();
      ctx.strokeStyle = '#9aa3ad';
      ctx.lineWidth = 1;
      ctx.strokeRect(g.x0 + 0.5, g.y0 + 0.5, g.x1 - g.x0 - 1, g.y1 - g.y0 - 1);

      // colour bar
      const bar = ctx.createLinearGradient(g.x0, 0, g.x1, 0);
      for (let k = 0; k <= stops; k++) {
        const c = colorAt(k / stops);
        bar.addColorStop(k / stops, `rgb(${c[0] | 0},${c[1] | 0},${c[2] | 0})`);
      }
      ctx.fillStyle = bar;
      ctx.fillRect(g.x0, g.barTop, g.x1 - g.x0, BAR_H);
      ctx.strokeStyle = '#6b737d';
      ctx.strokeRect(g.x0 + 0.5, g.barTop + 0.5, g.x1 - g.x0 - 1, BAR_H - 1);

      // opacity points
      ed.opacity.forEach((p, i) => {
        const sel = ed.sel && ed.sel.kind === 'o' && ed.sel.i === i;
        const clipped = p.a > ed.amax;
        ctx.beginPath();
        ctx.arc(gx(g, p.x), gy(g, Math.min(p.a, ed.amax)), sel ? 7 : 5, 0, 2 * Math.PI);
        ctx.fillStyle = sel ? '#1f5fbf' : '#ffffff';
        ctx.fill();
        ctx.lineWidth = 2;
        ctx.strokeStyle = clipped ? '#b42318' : '#1f2328';
        ctx.stroke();
      });
      // colour points: squares under the bar with a tick up to it
      ed.color.forEach((p, i) => {
        const sel = ed.sel && ed.sel.kind === 'c' && ed.sel.i === i;
        const x = gx(g, p.x), s = sel ? HANDLE + 4 : HANDLE;
        ctx.strokeStyle = '#1f2328';
        ctx.lineWidth = 1;
        ctx.beginPath(); ctx.moveTo(x + 0.5, g.barBottom); ctx.lineTo(x + 0.5, g.handleY - s / 2); ctx.stroke();
        ctx.fillStyle = p.rgb;
        ctx.fillRect(x - s / 2, g.handleY - s / 2, s, s);
        ctx.lineWidth = sel ? 3 : 1.5;
        ctx.strokeStyle = sel ? '#1f5fbf' : '#1f2328';
        ctx.strokeRect(x - s / 2, g.handleY - s / 2, s, s);
      });
    }

    function pos(ev) {
      const r = canvas.getBoundingClientRect();
      return { x: ev.clientX - r.left, y: ev.clientY - r.top };
    }

    function hit(p) {
      const g = geometry();
      let best = null, bestD = 10;
      if (p.y >= g.barTop - 4) {
        ed.color.forEach((c, i) => {
          const d = Math.abs(gx(g, c.x) - p.x);
          if (d < bestD) { bestD = d; best = { kind: 'c', i }; }
        });
        return best;
      }
      ed.opacity.forEach((o, i) => {
        const d = Math.hypot(gx(g, o.x) - p.x, gy(g, Math.min(o.a, ed.amax)) - p.y);
        if (d < bestD) { bestD = d; best = { kind: 'o', i }; }
      });
      return best;
    }

    const EPS = 1e-3;
    function moveSelected(p) {
      const g = geometry();
      const list = ed.sel.kind === 'o' ? ed.opacity : ed.color;
      const i = ed.sel.i;
      const lo = i > 0 ? list[i - 1].x + EPS : 0;
      const hi = i < list.length - 1 ? list[i + 1].x - EPS : 1;
      list[i].x = round(clamp(fromX(g, p.x), lo, hi), 4);
      if (ed.sel.kind === 'o') list[i].a = round(fromY(g, p.y), 4);
      ed.dirty = true;
      selectionChanged();
      draw();
    }

    function add(p) {
      const g = geometry();
      const x = round(fromX(g, p.x), 4);
      if (p.y >= g.barTop - 4) {
        if (ed.color.length >= 256 || ed.color.some((c) => Math.abs(c.x - x) < EPS)) return;
        const rgb = rgbToHex(colorAt(x));
        ed.color.push({ x, rgb });
        ed.color.sort((a, b) => a.x - b.x);
        ed.sel = { kind: 'c', i: ed.color.findIndex((c) => c.x === x) };
      } else {
        if (ed.opacity.length >= 256 || ed.opacity.some((o) => Math.abs(o.x - x) < EPS)) return;
        ed.opacity.push({ x, a: round(fromY(g, p.y), 4) });
        ed.opacity.sort((a, b) => a.x - b.x);
        ed.sel = { kind: 'o', i: ed.opacity.findIndex((o) => o.x === x) };
      }
      ed.dirty = true;
      selectionChanged();
      draw();
    }

    function removeSelected() {
      if (!ed.sel) return;
      const list = ed.sel.kind === 'o' ? ed.opacity : ed.color;
      if (list.length <= 2) return;
      list.splice(ed.sel.i, 1);
      ed.sel = null;
      ed.dirty = true;
      selectionChanged();
      draw();
    }

    canvas.addEventListener('pointerdown', (ev) => {
      if (ev.button !== 0) return;
      canvas.focus();
      const p = pos(ev);
      ed.sel = hit(p);
      ed.drag = ed.sel ? { id: ev.pointerId, start: p, moved: false } : null;
      if (ed.drag) canvas.setPointerCapture(ev.pointerId);
      selectionChanged();
      draw();
    });
    canvas.addEventListener('pointermove', (ev) => {
      const p = pos(ev);
      if (ed.drag && ed.drag.id === ev.pointerId) {
        if (!ed.drag.moved && Math.hypot(p.x - ed.drag.start.x, p.y - ed.drag.start.y) < 3) return;
        ed.drag.moved = true;
        moveSelected(p);
        return;
      }
      canvas.style.cursor = hit(p) ? 'pointer' : 'crosshair';
    });
    const up = (ev) => {
      if (!ed.drag || ed.drag.id !== ev.pointerId) return;
      const clicked = !ed.drag.moved;
      ed.drag = null;
      if (clicked && ed.sel && ed.sel.kind === 'c' && ev.type === 'pointerup') {
        const input = $('#tf-color');
        input.value = ed.color[ed.sel.i].rgb;
        try { input.showPicker(); } catch (_) { input.click(); }
      }
    };
    canvas.addEventListener('pointerup', up);
    canvas.addEventListener('pointercancel', up);
    canvas.addEventListener('dblclick', (ev) => {
      const p = pos(ev);
      if (hit(p)) return;
      add(p);
    });
    canvas.addEventListener('keydown', (ev) => {
      if (ev.key === 'Delete' || ev.key === 'Backspace') { ev.preventDefault(); removeSelected(); }
    });
    $('#tf-color').addEventListener('input', (ev) => {
      if (!ed.sel || ed.sel.kind !== 'c') return;
      ed.color[ed.sel.i].rgb = ev.target.value.toLowerCase();
      ed.dirty = true;
      selectionChanged();
      draw();
    });
    $('#tf-remove').addEventListener('click', removeSelected);
    $('#tf-revert').addEventListener('click', () => { if (V.state) load(V.state.ref_tf.points); $('#editor-error').hidden = true; });
    const amaxSel = $('#editor-amax');
    for (const c of AMAX_CHOICES) {
      const o = document.createElement('option');
      o.value = String(c); o.textContent = String(c);
      amaxSel.appendChild(o);
    }
    amaxSel.addEventListener('change', () => { ed.amax = Number(amaxSel.value); draw(); });
    window.addEventListener('resize', draw);

    $('#tf-apply').addEventListener('click', async () => {
      if (jobRunning) return;
      const err = $('#editor-error');
      err.hidden = true;
      const reoptimize = $('#tf-reoptimize').checked;
      const body = {
        opacity: ed.opacity.map((p) => ({ x: p.x, a: p.a })),
        color: ed.color.map((p) => ({ x: p.x, rgb: p.rgb })),
        reoptimize,
      };
      $('#tf-apply').disabled = true;
      begin();
      ownChanges++;
      try {
        const res = await postJson('/api/ref-tf', body);
        const r = await res.json();
        ed.dirty = false;
        if (res.status === 202 && r.job !== undefined) {
          startJob(r.job, 'optimize');
        } else {
          await refreshAll();
          V.jobsDone++;   // an Apply without a job counts as one finished change for the test's waits
        }
      } catch (e) {
        err.textContent = e.message || String(e);
        err.hidden = false;
        if (e instanceof ApiError && e.status === 409) watchJob();
      } finally {
        ownChanges--;
        end();
        $('#tf-apply').disabled = jobRunning;
      }
    });

    return {
      load,
      draw,
      get dirty() { return ed.dirty; },
      set dirty(v) { ed.dirty = v; },
      points: () => ({ opacity: ed.opacity.map((p) => ({ ...p })), color: ed.color.map((p) => ({ ...p })) }),
      // canvas position (CSS px, relative to the canvas) of an opacity point, for tests and tools
      opacityPointPosition: (i) => { const g = geometry(); const p = ed.opacity[i]; return { x: gx(g, p.x), y: gy(g, Math.min(p.a, ed.amax)) }; },
      colorPointPosition: (i) => { const g = geometry(); return { x: gx(g, ed.color[i].x), y: g.handleY }; },
      amax: () => ed.amax,
    };
  })();
  V.editor = editor;

  // ---- start ------------------------------------------------------------------------------------
  async function start() {
    if (!TOKEN) {
      showError('This page needs the address tfmatch view printed, with its ?token=…');
      return;
    }
    setupViewInteraction();
    setupSlices();
    setupSolverForm();
    initSeries();
    $('#histogram-scale').addEventListener('change', loadPlots);
    try {
      await loadState();
    } catch (e) {
      showError('could not load the state: ' + e.message);
      return;
    }
    const st = V.state;
    followServer();
    defaultSize = initialSize(st);
    buildSizeChoices();
    resetCamera();
    updateCameraUI();
    const d = st.grid.dims;
    if (st.mode === 'ensemble' && st.ensemble && st.ensemble.point) setSliceAxis('z', st.ensemble.point[2]);
    else setSliceAxis('z', Math.floor(d[2] / 2));
    if (st.job && st.job.state === 'running') {
      startJob(st.job.id, st.job.kind);
      return;
    }
    clearError();
    await Promise.all([loadImages(true), loadSlices(), loadPlots()]);
  }

  start();
})();
