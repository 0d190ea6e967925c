// One part of the script of `tfmatch view`'s page; host/viewer/view_page.cpp joins the parts in
// order (viewer_core.js first, viewer_start.js last) inside one strict function scope, so they
// share its names. This one: the reference-TF editor.

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
