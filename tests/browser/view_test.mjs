// Real-browser test of `tfmatch view`: headless Chromium (Debian's /usr/bin/chromium) driven by
// puppeteer-core loads the page the server prints, drags, zooms, switches solver and runs it,
// moves a slice, edits the reference TF, in ensemble mode clicks a reference point, and in series
// mode moves the field slider; it checks that the images and numbers change as they should.
//
//   node view_test.mjs PATH/TO/tfmatch
//
// Exit 0: every check passed; 1: a check failed; 2: usage; 77: skipped (no Chromium or no
// puppeteer-core: run `npm ci` in tests/browser). TFMATCH_SCREENSHOT_DIR=DIR saves
// view-pair.png and view-ensemble.png (the 1280x900 window) and view-*-full.png (the whole
// page) there. TFMATCH_CHROMIUM overrides /usr/bin/chromium.

import { spawn, execFile } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';

import { browserEnvironment } from './browser_env.mjs';

const { binary, chromium, puppeteer, screenshotDir } = await browserEnvironment('view_test.mjs', 'tfmatch view');

// ---- checks ---------------------------------------------------------------------------------------
let passed = 0, failed = 0;
const fullResTimes = [];
function check(name, ok, detail = '') {
  if (ok) { passed++; console.log(`  ok   ${name}  [${since()}]`); } else { failed++; console.log(`  FAIL ${name}${detail ? ': ' + detail : ''}`); }
  return ok;
}
const t00 = Date.now();
const since = () => `${((Date.now() - t00) / 1000).toFixed(1)} s`;
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Whole-run guard: a hung server or browser must not hang ctest.
const guard = setTimeout(() => {
  console.log(`FAIL: the test ran past 240 s (${passed} passed, ${failed} failed so far)`);
  for (const s of servers) try { s.child.kill('SIGKILL'); } catch (_) { /* gone */ }
  process.exit(1);
}, 240000);

// ---- the server -------------------------------------------------------------------------------------
const servers = [];
const SIGINT_EXIT = 0;   // Ctrl-C is how `tfmatch view` ends: a normal end
function startServer(args) {
  return new Promise((resolve, reject) => {
    const child = spawn(binary, ['view', ...args], { stdio: ['ignore', 'pipe', 'pipe'] });
    const srv = { child, out: '', err: '', exit: null };
    servers.push(srv);
    const timer = setTimeout(() => reject(new Error(`no URL from tfmatch view within 90 s; stderr:\n${srv.err}`)), 90000);
    child.stdout.on('data', (d) => {
      srv.out += d;
      const m = /http:\/\/127\.0\.0\.1:(\d+)\/\?token=([0-9a-fA-F]+)/.exec(srv.out);
      if (m && !srv.url) {
        clearTimeout(timer);
        srv.url = m[0];
        srv.origin = `http://127.0.0.1:${m[1]}`;
        srv.token = m[2];
        resolve(srv);
      }
    });
    child.stderr.on('data', (d) => { srv.err += d; });
    srv.exited = new Promise((r) => child.on('exit', (code, signal) => { srv.exit = { code, signal }; r(srv.exit); }));
    srv.exited.then((e) => { if (!srv.url) { clearTimeout(timer); reject(new Error(`tfmatch view exited (${e.code ?? e.signal}) before printing its URL; stderr:\n${srv.err}`)); } });
  });
}

async function stopServer(srv, label) {
  if (srv.exit) return check(`${label}: server still running at the end`, false, `exited ${JSON.stringify(srv.exit)}; stderr:\n${srv.err}`);
  srv.child.kill('SIGINT');
  const e = await Promise.race([srv.exited, sleep(30000).then(() => null)]);
  if (!e) { srv.child.kill('SIGKILL'); return check(`${label}: server exits on SIGINT`, false, 'still running 30 s after SIGINT'); }
  return check(`${label}: server exits with ${SIGINT_EXIT} on SIGINT`, e.code === SIGINT_EXIT, `exit ${JSON.stringify(e)}; stderr tail:\n${srv.err.slice(-2000)}`);
}

// ---- browser helpers ----------------------------------------------------------------------------
async function waitIdle(page, cond, what, timeout = 60000) {
  try {
    await page.waitForFunction(`(() => { const v = window.tfmViewer; return !!v && !v.busy && (${cond}); })()`, { timeout, polling: 100 });
    return true;
  } catch (e) {
    const snap = await page.evaluate(() => {
      const v = window.tfmViewer;
      return v ? JSON.stringify({ busy: v.busy, imageVersion: v.imageVersion, sliceVersion: v.sliceVersion, plotVersion: v.plotVersion,
        metricsVersion: v.metricsVersion, jobsDone: v.jobsDone, errors: v.errors, lastJob: v.lastJob }) : 'no tfmViewer';
    }).catch(() => '?');
    check(`wait for ${what}`, false, `timed out after ${timeout} ms: ${snap}`);
    return false;
  }
}
const viewer = (page) => page.evaluate(() => {
  const v = window.tfmViewer;
  return {
    camera: { ...v.camera }, imageVersion: v.imageVersion, lowResVersion: v.lowResVersion, sliceVersion: v.sliceVersion,
    plotVersion: v.plotVersion, metricsVersion: v.metricsVersion, jobsDone: v.jobsDone, progressEvents: v.progressEvents,
    lastFullResMs: v.lastFullResMs, imageHashes: { ...v.imageHashes }, sliceHashes: { ...v.sliceHashes },
    plotHashes: { ...v.plotHashes }, state: v.state, lastJob: v.lastJob, imageMetrics: v.imageMetrics,
    lastDistance: v.lastDistance, errors: [...v.errors],
  };
});
const text = (page, sel) => page.$eval(sel, (e) => e.textContent.trim());
const visible = (page, sel) => page.$eval(sel, (e) => !e.hidden && e.offsetParent !== null);

async function openPage(browser, srv, label) {
  const page = await browser.newPage();
  await page.setViewport({ width: 1280, height: 900 });
  const issues = { pageErrors: [], foreign: [], requests: [] };
  page.on('pageerror', (e) => issues.pageErrors.push(String(e)));
  page.on('request', (r) => {
    const u = r.url();
    issues.requests.push(u);
    if (!u.startsWith(srv.origin + '/') && !u.startsWith('blob:') && !u.startsWith('data:')) issues.foreign.push(u);
  });
  // small images keep a CPU Vulkan driver quick: the page honours ?size= (rendering, longer side)
  await page.goto(`${srv.url}&size=256`, { waitUntil: 'load' });
  const ok = await waitIdle(page, 'v.imageVersion >= 1 && v.sliceVersion >= 1 && v.plotVersion >= 1 && v.metricsVersion >= 1',
    `${label}: first images, slices, plots and metrics`, 90000);
  return { page, issues, ok };
}

// The element's box in viewport coordinates, scrolled into view first (mouse events go to what
// is on screen).
async function boxOf(page, sel) {
  const h = await page.$(sel);
  if (!h) throw new Error(`no element ${sel} on the page`);
  await h.evaluate((e) => e.scrollIntoView({ block: 'center', inline: 'center' }));
  await sleep(50);
  return h.boundingBox();
}

async function dragOnView(page, view, dx, dy) {
  const box = await boxOf(page, `.view[data-view="${view}"] .view-frame`);
  const x = box.x + box.width / 2, y = box.y + box.height / 2;
  await page.mouse.move(x, y);
  await page.mouse.down();
  for (let i = 1; i <= 10; i++) {       // a human-speed drag: low-res images are fetched meanwhile
    await page.mouse.move(x + (dx * i) / 10, y + (dy * i) / 10);
    await sleep(50);
  }
  await page.mouse.up();
}

// TFMATCH_SCREENSHOT_DIR: view-MODE.png (the 1280x900 window) and view-MODE-full.png (the page).
async function screenshot(page, mode) {
  if (!screenshotDir) return;
  await page.mouse.move(0, 0);
  await page.evaluate(() => window.scrollTo(0, 0));
  await sleep(100);
  await page.screenshot({ path: path.join(screenshotDir, `view-${mode}.png`) });
  await page.screenshot({ path: path.join(screenshotDir, `view-${mode}-full.png`), fullPage: true });
  console.log(`  screenshots ${path.join(screenshotDir, `view-${mode}.png`)} (1280×900) and view-${mode}-full.png (whole page)`);
}

const differs = (a, b) => a !== undefined && b !== undefined && a !== b;
const num = (s) => parseFloat(String(s).replace(/[^0-9eE+\-.]/g, ''));

// ---- token and plain HTTP -------------------------------------------------------------------------
async function checkAccess(srv, label) {
  const noToken = await fetch(`${srv.origin}/api/state`);
  check(`${label}: /api/state without token is 403`, noToken.status === 403, `status ${noToken.status}`);
  const wrong = await fetch(`${srv.origin}/?token=${'0'.repeat(srv.token.length)}`);
  check(`${label}: the page with a wrong token is 403`, wrong.status === 403, `status ${wrong.status}`);
  const page = await fetch(srv.url);
  const html = await page.text();
  check(`${label}: the page is one document with its CSS and JavaScript inlined`,
    page.status === 200 && html.includes('<style>') && html.includes('window.tfmViewer') && !html.includes('<!-- viewer script -->'),
    `status ${page.status}, ${html.length} bytes`);
}

// ---- pair mode --------------------------------------------------------------------------------------
async function pairMode(browser) {
  console.log(`pair mode: tfmatch view --demo --size 40 (${since()})`);
  const srv = await startServer(['--demo', '--size', '40', '--port', '0']);
  await checkAccess(srv, 'pair');
  const { page, issues, ok } = await openPage(browser, srv, 'pair');
  if (!ok) { await page.close(); await stopServer(srv, 'pair'); return; }

  let v = await viewer(page);
  check('pair: mode is pair, ensemble panel hidden', v.state.mode === 'pair' && !(await visible(page, '#ensemble-panel')));
  const sizes = await page.$$eval('.view img', (imgs) => imgs.map((i) => `${i.naturalWidth}x${i.naturalHeight}`));
  check('pair: four renderings at the ?size= of the page', sizes.length === 4 && sizes.every((s) => s === sizes[0]) &&
    Math.max(...sizes[0].split('x').map(Number)) === 256, sizes.join(', '));
  const cmd0 = await text(page, '#render-command');
  check('pair: the camera as a tfmatch render command line', /^tfmatch render /.test(cmd0) &&
    ['--azimuth', '--elevation', '--distance', '--fov', '--width', '--height'].every((f) => cmd0.includes(f)), cmd0);
  check('pair: voxel RMSE before/after shown', Number.isFinite(num(await text(page, '#m-vox-ref'))) &&
    Number.isFinite(num(await text(page, '#m-vox-opt'))));
  check('pair: image RMSE/PSNR/SSIM shown', Number.isFinite(num(await text(page, '#m-rmse-opt'))) &&
    Number.isFinite(num(await text(page, '#m-ssim-opt'))), JSON.stringify(v.imageMetrics));
  const solverNames = await page.$$eval('#solver-select option', (o) => o.map((x) => x.value));
  check('pair: solver choice from the registry', solverNames.length === v.state.solvers.length &&
    ['cgls', 'gradient-descent'].every((n) => solverNames.includes(n)), solverNames.join(', '));

  // drag: orbit
  const before = v;
  const lowRequests = () => issues.requests.filter((u) => u.includes('/api/render') && /[?&]w=64(&|$)/.test(u)).length;
  const low0 = lowRequests();
  await dragOnView(page, 'field-opt-tf', 80, 30);
  await waitIdle(page, `v.imageVersion > ${before.imageVersion} && v.metricsVersion > ${before.metricsVersion}`, 'pair: images after the drag');
  v = await viewer(page);
  check('pair: dragging changes azimuth and elevation', v.camera.az !== before.camera.az && v.camera.el > before.camera.el,
    `${JSON.stringify(before.camera)} -> ${JSON.stringify(v.camera)}`);
  check('pair: camera numbers on the page follow', Number(await page.$eval('#cam-az', (e) => e.value)) === v.camera.az &&
    (await text(page, '#render-command')).includes(`--azimuth ${v.camera.az} --elevation ${v.camera.el}`));
  check('pair: low-resolution images requested while dragging', lowRequests() > low0, `${lowRequests() - low0} requests`);
  check('pair: all four full-resolution images changed after the drag',
    ['reference', 'field-ref-tf', 'field-opt-tf', 'residual'].every((k) => differs(before.imageHashes[k], v.imageHashes[k])),
    `${JSON.stringify(before.imageHashes)} -> ${JSON.stringify(v.imageHashes)}`);
  const fullText = await text(page, '#fullres-text');
  check('pair: "full image in N ms" measured and shown', Number.isFinite(v.lastFullResMs) && v.lastFullResMs > 0 &&
    fullText === `full image in ${v.lastFullResMs} ms`, fullText);
  fullResTimes.push({ what: 'pair, drag 256²', ms: v.lastFullResMs });
  check('pair: the metrics follow the camera', JSON.stringify(v.imageMetrics) !== JSON.stringify(before.imageMetrics));

  // wheel: zoom (from the framed distance of the last rendering)
  const beforeZoom = v;
  const vbox = await boxOf(page, '.view[data-view="reference"] .view-frame');
  await page.mouse.move(vbox.x + vbox.width / 2, vbox.y + vbox.height / 2);
  await page.mouse.wheel({ deltaY: -100 });
  await waitIdle(page, `v.imageVersion > ${beforeZoom.imageVersion}`, 'pair: images after the wheel');
  v = await viewer(page);
  check('pair: wheel zooms in from the distance the server used', beforeZoom.camera.dist === 0 && v.camera.dist > 1 &&
    Math.abs(v.camera.dist - beforeZoom.lastDistance * Math.exp(-0.15)) < 0.01 * beforeZoom.lastDistance,
    `dist ${beforeZoom.camera.dist} (framed: ${beforeZoom.lastDistance}) -> ${v.camera.dist}`);
  check('pair: the images changed after zooming', differs(beforeZoom.imageHashes.reference, v.imageHashes.reference));
  fullResTimes.push({ what: 'pair, wheel 256²', ms: v.lastFullResMs });

  // downloads
  const links = await page.evaluate(() => Object.fromEntries(
    ['#dl-opt-json', '#dl-opt-pv', '#dl-ref-json', '#dl-residual', '#dl-ref-vti', 'a[data-dl-view="field-opt-tf"]', 'a[data-dl-view="reference"]'].map((s) => [s, document.querySelector(s).href])));
  const dl = async (sel) => { const r = await fetch(links[sel]); return { r, body: Buffer.from(await r.arrayBuffer()) }; };
  {
    const a = await dl('#dl-opt-json');
    let json = null; try { json = JSON.parse(a.body.toString()); } catch (_) { /* checked below */ }
    check('pair: optimized TF downloads as JSON', a.r.status === 200 && json !== null &&
      /attachment/.test(a.r.headers.get('content-disposition') || ''), `status ${a.r.status}`);
    const b = await dl('#dl-opt-pv');
    check('pair: optimized TF downloads as a ParaView preset', b.r.status === 200 && /RGBPoints/.test(b.body.toString()));
    const c = await dl('#dl-residual');
    check('pair: residual map downloads as .vti', c.r.status === 200 && /<VTKFile/.test(c.body.subarray(0, 400).toString()));
    const d = await dl('a[data-dl-view="field-opt-tf"]');
    check('pair: current image downloads as PNG at the current camera', d.r.status === 200 &&
      d.body.subarray(1, 4).toString() === 'PNG' && /field-opt-tf\.png/.test(d.r.headers.get('content-disposition') || '') &&
      links['a[data-dl-view="field-opt-tf"]'].includes(`dist=${v.camera.dist}`));
  }

  // the page's command line reproduces the reference view with tfmatch render, byte for byte
  {
    const cmd = await text(page, '#render-command');
    const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tfmatch-view-test-'));
    try {
      const files = v.state.render_commands ? { 'reference.vti': links['#dl-ref-vti'], 'reference-tf.json': links['#dl-ref-json'] } : null;
      if (!check('pair: the server gives per-view render commands and their input files', files !== null)) throw new Error('skip');
      for (const [name, href] of Object.entries(files)) fs.writeFileSync(path.join(dir, name), Buffer.from(await (await fetch(href)).arrayBuffer()));
      const shown = Buffer.from(await (await fetch(links['a[data-dl-view="reference"]'])).arrayBuffer());
      const line = cmd.replace(/^tfmatch /, `exec '${path.resolve(binary)}' -q `) + ' --out repro.png';
      const run = await new Promise((resolve) => execFile('sh', ['-c', line], { cwd: dir, timeout: 60000 },
        (error, stdout, stderr) => resolve({ error, stderr })));
      const repro = fs.existsSync(path.join(dir, 'repro.png')) ? fs.readFileSync(path.join(dir, 'repro.png')) : Buffer.alloc(0);
      check('pair: tfmatch render with the page\'s command line gives the image shown, byte for byte',
        !run.error && repro.length > 0 && repro.equals(shown), `${line}\n${run.error ? run.error.message : ''}${run.stderr}` +
        ` (${repro.length} vs ${shown.length} bytes)`);
    } catch (e) {
      if (e.message !== 'skip') check('pair: reproduce the view with tfmatch render', false, e.stack);
    } finally {
      fs.rmSync(dir, { recursive: true, force: true });
    }
  }

  // solver: cgls, then a bad value (400 shown next to the form), then gradient descent, 20 iterations
  const beforeCgls = v;
  await page.select('#solver-select', 'cgls');
  await page.click('#run-button');
  await waitIdle(page, `v.jobsDone > ${beforeCgls.jobsDone}`, 'pair: cgls job', 90000);
  v = await viewer(page);
  check('pair: cgls ran and its TF is the one shown', v.lastJob && v.lastJob.state === 'done' &&
    v.state.optimized_tf.solver === 'cgls', JSON.stringify(v.lastJob));
  check('pair: voxel RMSE shown after the job', Number.isFinite(num(await text(page, '#m-vox-opt'))) &&
    Math.abs(num(await text(page, '#m-vox-opt')) - v.state.metrics.voxel_rmse_optimized_tf) < 1e-3);
  check('pair: images, slices and plots refreshed after the job', v.imageVersion > beforeCgls.imageVersion &&
    v.sliceVersion > beforeCgls.sliceVersion && v.plotVersion > beforeCgls.plotVersion);
  await screenshot(page, 'pair');   // the README's picture: a converged solver, after an orbit and a zoom

  await page.select('#solver-select', 'gradient-descent');
  check('pair: gradient-descent options generated', (await page.$('#opt-iterations')) !== null);
  await page.$eval('#opt-iterations', (e) => { e.value = ''; });
  await page.type('#opt-iterations', '999999');
  await page.click('#run-button');
  await page.waitForFunction(() => !document.querySelector('#solver-error').hidden, { timeout: 10000 }).catch(() => {});
  const err = await page.$eval('#solver-error', (e) => (e.hidden ? '' : e.textContent));
  check('pair: a value over the bounds is refused and the message shown by the form', /iterations/.test(err), err || '(no message)');

  const beforeGd = await viewer(page);
  await page.$eval('#opt-iterations', (e) => { e.value = ''; });
  await page.type('#opt-iterations', '20');
  await page.click('#run-button');
  await waitIdle(page, `v.jobsDone > ${beforeGd.jobsDone}`, 'pair: gradient-descent job', 90000);
  v = await viewer(page);
  check('pair: gradient descent (20 iterations) ran', v.lastJob && v.lastJob.state === 'done' &&
    v.state.optimized_tf.solver === 'gradient-descent' && v.state.solver.name === 'gradient-descent', JSON.stringify(v.lastJob));
  check('pair: the optimized-TF image changed', differs(beforeGd.imageHashes['field-opt-tf'], v.imageHashes['field-opt-tf']));
  check('pair: the reference image did not', beforeGd.imageHashes.reference === v.imageHashes.reference);
  check('pair: the voxel RMSE of the optimized TF changed', v.state.metrics.voxel_rmse_optimized_tf !== beforeGd.state.metrics.voxel_rmse_optimized_tf,
    `${beforeGd.state.metrics.voxel_rmse_optimized_tf} -> ${v.state.metrics.voxel_rmse_optimized_tf}`);
  check('pair: solver error cleared, job message shown', !(await visible(page, '#solver-error').catch(() => false)) &&
    /done/.test(await text(page, '#job-message')));
  console.log(`  (progress events seen during gradient descent: ${v.progressEvents - beforeGd.progressEvents})`);

  // two pages on one server: a second page follows the first page's job to its end, and both
  // show a change applied by another client (here a plain POST) without being told to reload
  {
    const otherBrowser = await browser.createBrowserContext();  // its own connections, as another browser
    const second = await openPage(otherBrowser, srv, 'pair: second page');
    await page.bringToFront();
    if (second.ok) {
      const one = await viewer(page), two = await viewer(second.page);
      await page.$eval('#opt-iterations', (e) => { e.value = ''; });
      await page.type('#opt-iterations', '25');
      await page.click('#run-button');
      await waitIdle(page, `v.jobsDone > ${one.jobsDone}`, 'pair: the job started on the first page', 90000);
      const ended = await viewer(page);
      await waitIdle(second.page, `v.jobsDone > ${two.jobsDone} && v.state.version === ${ended.state.version}`,
        'pair: the second page following that job', 30000);
      const seen = await viewer(second.page);
      check('pair: a second page follows a job started on the first, and refreshes after it',
        seen.lastJob && seen.lastJob.id === ended.lastJob.id && seen.imageVersion > two.imageVersion &&
        seen.state.optimized_tf.solver === 'gradient-descent', JSON.stringify(seen.lastJob));
      const points = ended.state.ref_tf.points;
      const edit = await fetch(`${srv.origin}/api/ref-tf?token=${srv.token}`, {
        method: 'POST', headers: { 'Content-Type': 'application/json' },
        body: JSON.stringify({ ...points, opacity: points.opacity.map((p) => ({ ...p, a: p.a * 0.8 })) }) });
      const version = (await edit.json()).version;
      const shown1 = await waitIdle(page, `v.state.version === ${version}`, 'pair: the first page showing another client\'s edit', 30000);
      const shown2 = await waitIdle(second.page, `v.state.version === ${version}`, 'pair: the second page showing it', 30000);
      const after1 = await viewer(page), after2 = await viewer(second.page);
      check('pair: both pages show another client\'s reference-TF edit', edit.status === 200 && shown1 && shown2 &&
        differs(ended.imageHashes.reference, after1.imageHashes.reference) &&
        differs(seen.imageHashes.reference, after2.imageHashes.reference));
      check('pair: the second page shows no errors', after2.errors.length === 0 && second.issues.pageErrors.length === 0,
        JSON.stringify([after2.errors, second.issues.pageErrors]));
    }
    await otherBrowser.close();
    v = await viewer(page);
  }

  // slices: move the slider, then change the axis
  const beforeSlice = v;
  await page.focus('#slice-index');
  for (let i = 0; i < 6; i++) await page.keyboard.press('ArrowRight');
  const idx = await page.$eval('#slice-index', (e) => Number(e.value));
  await waitIdle(page, `v.sliceVersion > ${beforeSlice.sliceVersion} && document.querySelector('#slice-label').textContent.includes('index ${idx} ')`,
    'pair: slices after moving the slider');
  await sleep(300);
  await waitIdle(page, 'true', 'pair: slices settled');
  v = await viewer(page);
  check('pair: the slider moved the slice', idx === Math.floor(v.state.grid.dims[2] / 2) + 6, `index ${idx}`);
  check('pair: all four slice images changed', ['reference', 'field-ref-tf', 'field-opt-tf', 'residual']
    .every((k) => differs(beforeSlice.sliceHashes[k], v.sliceHashes[k])), `${JSON.stringify(beforeSlice.sliceHashes)} -> ${JSON.stringify(v.sliceHashes)}`);
  const beforeAxis = v;
  await page.click('input[name="slice-axis"][value="x"]');
  await waitIdle(page, `v.sliceVersion > ${beforeAxis.sliceVersion}`, 'pair: slices after the axis change');
  v = await viewer(page);
  check('pair: the x axis shows other slices', differs(beforeAxis.sliceHashes.reference, v.sliceHashes.reference) &&
    (await text(page, '#slice-label')).startsWith('x index'));

  // reference-TF editor: add a point and delete it again (client side), drag an opacity point, apply
  const pts0 = await page.evaluate(() => window.tfmViewer.editor.points());
  const canvas = await boxOf(page, '#tf-canvas');
  const emptyX = await page.evaluate(() => {
    const p = window.tfmViewer.editor.points().opacity;
    let best = 0, gap = -1;
    for (let i = 1; i < p.length; i++) if (p[i].x - p[i - 1].x > gap) { gap = p[i].x - p[i - 1].x; best = (p[i].x + p[i - 1].x) / 2; }
    return best;
  });
  const cw = canvas.width;
  await page.mouse.click(canvas.x + 48 + emptyX * (cw - 48 - 14), canvas.y + 40, { count: 2 });
  const ptsAdded = await page.evaluate(() => window.tfmViewer.editor.points());
  check('editor: double-click adds an opacity point', ptsAdded.opacity.length === pts0.opacity.length + 1,
    `${pts0.opacity.length} -> ${ptsAdded.opacity.length}`);
  await page.keyboard.press('Delete');
  const ptsDeleted = await page.evaluate(() => window.tfmViewer.editor.points());
  check('editor: Delete removes the selected point', ptsDeleted.opacity.length === pts0.opacity.length);

  const target = pts0.opacity.reduce((bi, p, i, a) => (p.a > a[bi].a ? i : bi), 0);
  const pp = await page.evaluate((i) => window.tfmViewer.editor.opacityPointPosition(i), target);
  await page.mouse.move(canvas.x + pp.x, canvas.y + pp.y);
  await page.mouse.down();
  for (let i = 1; i <= 5; i++) await page.mouse.move(canvas.x + pp.x + 3 * i, canvas.y + pp.y + 12 * i);
  await page.mouse.up();
  const pts1 = await page.evaluate(() => window.tfmViewer.editor.points());
  check('editor: dragging an opacity point lowers it', pts1.opacity[target].a < pts0.opacity[target].a - 0.01,
    `a ${pts0.opacity[target].a} -> ${pts1.opacity[target].a}`);
  // colour: select the last colour point and pick a colour (the picker's value, as the dialog would set it)
  const cp = await page.evaluate(() => window.tfmViewer.editor.colorPointPosition(1));
  await page.mouse.click(canvas.x + cp.x, canvas.y + cp.y);
  await page.$eval('#tf-color', (e) => { e.value = '#00c040'; e.dispatchEvent(new Event('input', { bubbles: true })); });
  const pts2 = await page.evaluate(() => window.tfmViewer.editor.points());
  check('editor: clicking a colour point and picking a colour sets it', pts2.color[1].rgb === '#00c040', JSON.stringify(pts2.color[1]));

  const beforeApply = await viewer(page);
  await page.$eval('#tf-reoptimize', (e) => { e.checked = false; });
  await page.click('#tf-apply');
  await waitIdle(page, `v.jobsDone > ${beforeApply.jobsDone}`, 'pair: apply the edited reference TF');
  v = await viewer(page);
  check('editor: Apply changes the reference image', differs(beforeApply.imageHashes.reference, v.imageHashes.reference));
  check('editor: and the field with the reference TF', differs(beforeApply.imageHashes['field-ref-tf'], v.imageHashes['field-ref-tf']));
  check('editor: without re-optimizing, the optimized-TF image stays', beforeApply.imageHashes['field-opt-tf'] === v.imageHashes['field-opt-tf']);
  check('editor: the reference TF plot changed', differs(beforeApply.plotHashes.reference, v.plotHashes.reference));
  check('editor: the state holds the edited points', v.state.version > beforeApply.state.version &&
    v.state.ref_tf.points.color.some((c) => c.rgb.toLowerCase() === '#00c040'), JSON.stringify(v.state.ref_tf.points.color));

  // the same TF again with re-optimization: the current solver (gradient descent) runs
  const beforeRe = v;
  await page.$eval('#tf-reoptimize', (e) => { e.checked = true; });
  const canvas2 = await boxOf(page, '#tf-canvas');
  const pp2 = await page.evaluate((i) => window.tfmViewer.editor.opacityPointPosition(i), target);
  await page.mouse.move(canvas2.x + pp2.x, canvas2.y + pp2.y);
  await page.mouse.down();
  for (let i = 1; i <= 5; i++) await page.mouse.move(canvas2.x + pp2.x, canvas2.y + pp2.y - 8 * i);
  await page.mouse.up();
  await page.click('#tf-apply');
  await waitIdle(page, `v.jobsDone > ${beforeRe.jobsDone} && v.lastJob && v.lastJob.state !== 'running'`, 'pair: apply with re-optimize', 90000);
  v = await viewer(page);
  check('editor: Apply with re-optimize runs the solver again', v.lastJob.state === 'done' &&
    v.lastJob.id > beforeRe.lastJob.id && v.state.optimized_tf.solver === 'gradient-descent', JSON.stringify(v.lastJob));
  check('editor: and every view follows', differs(beforeRe.imageHashes.reference, v.imageHashes.reference) &&
    differs(beforeRe.imageHashes['field-opt-tf'], v.imageHashes['field-opt-tf']));

  // ensemble requests are refused in pair mode
  const pt = await fetch(`${srv.origin}/api/point?token=${srv.token}`, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: '{"point":[1,1,1]}' });
  check('pair: POST /api/point is 409 in pair mode', pt.status === 409, `status ${pt.status}`);

  // a last drag: the time to the full image, with everything settled
  const beforeLast = await viewer(page);
  await dragOnView(page, 'reference', -60, -20);
  await waitIdle(page, `v.imageVersion > ${beforeLast.imageVersion}`, 'pair: images after the second drag');
  v = await viewer(page);
  fullResTimes.push({ what: 'pair, drag 256²', ms: v.lastFullResMs });

  check('pair: no JavaScript errors', issues.pageErrors.length === 0, issues.pageErrors.join(' | '));
  check('pair: nothing requested outside the server', issues.foreign.length === 0, issues.foreign.join(', '));
  check('pair: no errors shown', v.errors.length === 0 && !(await visible(page, '#global-error').catch(() => false)), v.errors.join(' | '));
  await page.close();
  await stopServer(srv, 'pair');
}

// ---- ensemble mode ----------------------------------------------------------------------------------
async function ensembleMode(browser) {
  console.log(`ensemble mode: tfmatch view --demo --ensemble --size 24 (${since()})`);
  const srv = await startServer(['--demo', '--ensemble', '--size', '24', '--port', '0']);
  await checkAccess(srv, 'ensemble');
  const { page, issues, ok } = await openPage(browser, srv, 'ensemble');
  if (!ok) { await page.close(); await stopServer(srv, 'ensemble'); return; }
  let v = await viewer(page);
  const ens0 = v.state.ensemble;
  check('ensemble: mode, measure vs versus and the point shown', v.state.mode === 'ensemble' && ens0 &&
    (await visible(page, '#ensemble-panel')) && (await text(page, '#point-text')) === ens0.point_text &&
    (await text(page, '#ensemble-text')).includes(ens0.measure) && (await text(page, '#ensemble-text')).includes(ens0.versus),
    JSON.stringify(ens0));
  const p0 = ens0.point;
  check('ensemble: the slice shows the reference point\'s z plane', (await text(page, '#slice-label')).startsWith(`z index ${p0[2]} `));
  check('ensemble: the point is marked on the slices', (await page.$$eval('.slice .marker', (m) => m.filter((e) => !e.hidden).length)) === 4);

  // click a voxel on the z slice, away from the current point
  const [nx, ny] = v.state.grid.dims;
  const target = [(p0[0] + Math.floor(nx / 2)) % nx, (p0[1] + Math.floor(ny / 3)) % ny, p0[2]];
  const img = await boxOf(page, '.slice[data-view="reference"] img');
  const cx = img.x + ((target[0] + 0.5) / nx) * img.width, cy = img.y + (1 - (target[1] + 0.5) / ny) * img.height;
  await page.mouse.move(cx, cy);
  const hover = await text(page, '#slice-hover');
  check('ensemble: hovering names the voxel under the cursor', hover.startsWith(`voxel (${target.join(', ')})`), hover);
  const before = v;
  await page.mouse.click(cx, cy);
  await waitIdle(page, `v.jobsDone > ${before.jobsDone}`, 'ensemble: the job for the new reference point', 120000);
  v = await viewer(page);
  check('ensemble: the job for the point finished', v.lastJob && v.lastJob.state === 'done' && v.lastJob.kind === 'point', JSON.stringify(v.lastJob));
  check('ensemble: the clicked voxel is the reference point', JSON.stringify(v.state.ensemble.point) === JSON.stringify(target),
    `${JSON.stringify(v.state.ensemble.point)} vs ${JSON.stringify(target)}`);
  check('ensemble: the point text changed', v.state.ensemble.point_text !== ens0.point_text &&
    (await text(page, '#point-text')) === v.state.ensemble.point_text, await text(page, '#point-text'));
  check('ensemble: every rendering changed', ['reference', 'field-ref-tf', 'field-opt-tf', 'residual']
    .every((k) => differs(before.imageHashes[k], v.imageHashes[k])), `${JSON.stringify(before.imageHashes)} -> ${JSON.stringify(v.imageHashes)}`);
  check('ensemble: the slices changed', differs(before.sliceHashes.reference, v.sliceHashes.reference));
  check('ensemble: the plots changed', differs(before.plotHashes.reference, v.plotHashes.reference));
  const marker = await page.$eval('.slice[data-view="reference"] .marker', (m) => ({ hidden: m.hidden, left: m.style.left, top: m.style.top }));
  check('ensemble: the marker moved to the clicked voxel', !marker.hidden &&
    Math.abs(parseFloat(marker.left) - ((target[0] + 0.5) / nx) * 100) < 0.01 &&
    Math.abs(parseFloat(marker.top) - (1 - (target[1] + 0.5) / ny) * 100) < 0.01, JSON.stringify(marker));

  // a point outside the grid is refused with a message
  const bad = await fetch(`${srv.origin}/api/point?token=${srv.token}`, { method: 'POST', headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify({ point: [nx + 5, 0, 0] }) });
  const badBody = await bad.json().catch(() => ({}));
  check('ensemble: a point outside the grid is 400 with a message', bad.status === 400 && typeof badBody.error === 'string', `${bad.status} ${JSON.stringify(badBody)}`);

  // a drag in ensemble mode: the time to the full image
  const beforeDrag = await viewer(page);
  await dragOnView(page, 'reference', 70, 20);
  await waitIdle(page, `v.imageVersion > ${beforeDrag.imageVersion}`, 'ensemble: images after a drag');
  v = await viewer(page);
  check('ensemble: dragging re-renders', differs(beforeDrag.imageHashes.reference, v.imageHashes.reference));
  fullResTimes.push({ what: 'ensemble, drag 256²', ms: v.lastFullResMs });

  check('ensemble: no JavaScript errors', issues.pageErrors.length === 0, issues.pageErrors.join(' | '));
  check('ensemble: nothing requested outside the server', issues.foreign.length === 0, issues.foreign.join(', '));
  check('ensemble: no errors shown', v.errors.length === 0, v.errors.join(' | '));
  await screenshot(page, 'ensemble');
  await page.close();
  await stopServer(srv, 'ensemble');
}

// ---- series mode ------------------------------------------------------------------------------------
// Several --field: the page shows one at a time; the slider chooses another, which is loaded and
// its TF fitted as a job. The fields: `tfmatch demo`'s files at 24^3 (its field, and the reference
// itself, whose fitted TF is nearly the reference TF).
async function seriesMode(browser) {
  const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'tfmatch-view-series-'));
  try {
    await new Promise((resolve, reject) => execFile(binary, ['demo', '--out', dir, '--size', '24', '-q'],
      (err) => (err ? reject(err) : resolve())));
    const ref = path.join(dir, 'reference_24x24x24_float32.raw');
    const field = path.join(dir, 'field_24x24x24_float32.raw');
    console.log(`series mode: tfmatch view --ref REF --field FIELD --field REF (${since()})`);
    const srv = await startServer(['--ref', ref, '--ref-tf', path.join(dir, 'reference_tf.json'), '--field', field,
                                   '--field', ref, '--tf-size', '32', '--port', '0']);
    const { page, issues, ok } = await openPage(browser, srv, 'series');
    if (!ok) { await page.close(); await stopServer(srv, 'series'); return; }
    let v = await viewer(page);
    check('series: mode, the series panel and the field shown', v.state.mode === 'series' && v.state.series &&
      v.state.series.count === 2 && v.state.series.index === 0 && (await visible(page, '#series-panel')) &&
      !(await visible(page, '#ensemble-panel')) && (await text(page, '#series-index')).startsWith('0: field_24x24x24'),
      JSON.stringify(v.state.series) + ' ' + (await text(page, '#series-index')));
    check('series: the slider spans the fields', (await page.$eval('#series-slider', (e) => [e.min, e.max, e.value].join())) === '0,1,0');
    const before = v;
    await page.$eval('#series-slider', (e) => { e.value = '1'; e.dispatchEvent(new Event('input')); e.dispatchEvent(new Event('change')); });
    await waitIdle(page, `v.jobsDone > ${before.jobsDone} && v.state.series.index === 1`, 'series: the job for field 1', 120000);
    v = await viewer(page);
    check('series: the job for the field finished', v.lastJob && v.lastJob.state === 'done' && v.lastJob.kind === 'field',
      JSON.stringify(v.lastJob));
    check('series: field 1 is shown', (await text(page, '#series-index')).startsWith('1: reference_24x24x24') &&
      v.state.fields.field.name !== before.state.fields.field.name, await text(page, '#series-index'));
    check('series: its renderings changed', differs(before.imageHashes['field-ref-tf'], v.imageHashes['field-ref-tf']) &&
      differs(before.imageHashes['field-opt-tf'], v.imageHashes['field-opt-tf']));
    check('series: the reference against itself fits closely', v.state.metrics.voxel_rmse_optimized_tf < 0.02,
      String(v.state.metrics.voxel_rmse_optimized_tf));
    const bad = await fetch(`${srv.origin}/api/field?token=${srv.token}`, { method: 'POST', headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ index: 5 }) });
    check('series: a field past the series is 400', bad.status === 400, String(bad.status));
    check('series: no JavaScript errors', issues.pageErrors.length === 0, issues.pageErrors.join(' | '));
    check('series: no errors shown', v.errors.length === 0, v.errors.join(' | '));
    await screenshot(page, 'series');
    await page.close();
    await stopServer(srv, 'series');
  } finally {
    fs.rmSync(dir, { recursive: true, force: true });
  }
}

// ---- main -------------------------------------------------------------------------------------------
let browser;
try {
  browser = await puppeteer.launch({
    executablePath: chromium,
    headless: true,
    // A page in a background tab must keep running (timers, animation frames): the test drives
    // two pages of one server at once.
    args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage', '--no-first-run', '--no-default-browser-check',
           '--disable-background-timer-throttling', '--disable-renderer-backgrounding',
           '--disable-backgrounding-occluded-windows'],
  });
  await pairMode(browser);
  await ensembleMode(browser);
  await seriesMode(browser);
} catch (e) {
  check('test ran to its end', false, e && e.stack ? e.stack : String(e));
  for (const s of servers) if (!s.exit) { console.log(`stderr of tfmatch view:\n${s.err.slice(-3000)}`); }
} finally {
  if (browser) await browser.close().catch(() => {});
  for (const s of servers) if (!s.exit) { s.child.kill('SIGKILL'); }
  clearTimeout(guard);
}
for (const t of fullResTimes) console.log(`full image in ${t.ms} ms (${t.what})`);
console.log(`view browser test: ${passed} passed, ${failed} failed (${since()})`);
process.exit(failed === 0 ? 0 : 1);
