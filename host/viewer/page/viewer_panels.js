// One part of the script of `tfmatch view`'s page; host/viewer/view_page.cpp joins the parts in
// order (viewer_core.js first, viewer_start.js last) inside one strict function scope, so they
// share its names. This one: metrics, slices, the series slider, TF plots.

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
