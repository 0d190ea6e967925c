// One part of the script of `tfmatch view`'s page; host/viewer/view_page.cpp joins the parts in
// order (viewer_core.js first, viewer_start.js last) inside one strict function scope, so they
// share its names. This one: the state, the solver form, jobs and their progress, other
// pages on the same server.

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
