// One part of the script of `tfmatch view`'s page; host/viewer/view_page.cpp joins the parts in
// order (viewer_core.js first, viewer_start.js last) inside one strict function scope, so they
// share its names. This one: the camera, the four renderings and dragging them.

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
