// Real-browser test of the report pages (`optimize --report`, `demo`): headless Chromium driven by
// puppeteer-core opens a pair report and a series report, written here with long file names, at a
// desktop width (1400 px) and a phone's (420 px), and checks what a reader sees: every picture
// loaded, nothing wider than the window (no sideways scrolling; long names wrap, wide tables
// scroll in their own box), figures side by side on the desktop and stacked on the phone, and no
// caption printed over another figure.
//
//   node report_test.mjs PATH/TO/tfmatch
//
// Exit 0: every check passed; 1: a check failed; 2: usage; 77: skipped (no Chromium or no
// puppeteer-core: run `npm ci` in tests/browser). TFMATCH_SCREENSHOT_DIR=DIR saves
// report-{pair,series}-{1400,420}.png (whole pages) there. TFMATCH_CHROMIUM overrides /usr/bin/chromium.

import { execFile } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { pathToFileURL } from 'node:url';

import { browserEnvironment } from './browser_env.mjs';

const { binary, chromium, puppeteer, screenshotDir } = await browserEnvironment('report_test.mjs', 'the report pages');

let passed = 0, failed = 0;
function check(name, ok, detail = '') {
  if (ok) { passed++; console.log(`  ok   ${name}`); } else { failed++; console.log(`  FAIL ${name}${detail ? ': ' + detail : ''}`); }
  return ok;
}
const guard = setTimeout(() => {
  console.log(`FAIL: the test ran past 240 s (${passed} passed, ${failed} failed so far)`);
  process.exit(1);
}, 240000);

function tfmatch(args) {
  return new Promise((resolve, reject) => {
    execFile(binary, args, { timeout: 180000, maxBuffer: 1 << 24 }, (err, stdout, stderr) => {
      if (err) reject(new Error(`tfmatch ${args.join(' ')} failed: ${err.message}\n${stderr}`));
      else resolve(stdout);
    });
  });
}

// A smooth field and a remap of it, with bumps that no TF explains, as float32 raw files.
function writeField(file, n, f) {
  const buf = Buffer.alloc(n * n * n * 4);
  let i = 0;
  for (let z = 0; z < n; ++z)
    for (let y = 0; y < n; ++y)
      for (let x = 0; x < n; ++x) buf.writeFloatLE(f(x / (n - 1), y / (n - 1), z / (n - 1)), 4 * i++);
  fs.writeFileSync(file, buf);
}

const work = fs.mkdtempSync(path.join(os.tmpdir(), 'tfmatch-report-test-'));
const n = 24;
// Long names without break points: a path people have (a model run, its variable, its date).
const stem = 'simulation_run_2026_11_27T12_00_00_ensemble_member_temperature_at_all_levels';
const ref = path.join(work, `${stem}_reference_${n}x${n}x${n}_float32.raw`);
const base = (x, y, z) => Math.sin(3 * x) * Math.cos(2 * y) + z;
writeField(ref, n, base);
const fields = [1, 2, 3].map((k) => {
  const file = path.join(work, `${stem}_second_${k}_${n}x${n}x${n}_float32.raw`);
  writeField(file, n, (x, y, z) => Math.pow(base(x, y, z) + 2, 1 + 0.2 * k) + (Math.hypot(x - 0.3 * k, y - 0.5, z - 0.5) < 0.15 ? 1 : 0));
  return file;
});
const common = ['--ref', ref, '--ref-tf', 'viridis', '--width', '160', '--height', '160'];
const pairDir = path.join(work, 'pair'), seriesDir = path.join(work, 'series');
try {
  await tfmatch(['-q', 'optimize', ...common, '--field', fields[0], '--out', path.join(work, 'pair_tf.json'), '--report', pairDir]);
  await tfmatch(['-q', 'optimize', ...common, ...fields.flatMap((f) => ['--field', f]), '--out', path.join(work, 'series_tf.json'),
    '--report', seriesDir]);
} catch (e) {
  check('reports written', false, e.message);
  process.exit(1);
}

const browser = await puppeteer.launch({
  executablePath: chromium,
  headless: true,
  args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage', '--no-first-run', '--no-default-browser-check',
    '--allow-file-access-from-files'],
});
try {
  for (const [label, dir] of [['pair', pairDir], ['series', seriesDir]]) {
    const url = pathToFileURL(path.join(dir, 'index.html')).href;
    for (const width of [1400, 420]) {
      const page = await browser.newPage();
      const errors = [];
      page.on('pageerror', (e) => errors.push(String(e)));
      await page.setViewport({ width, height: 900 });
      await page.goto(url, { waitUntil: 'load' });
      const seen = await page.evaluate(() => {
        const doc = document.documentElement;
        const images = [...document.images].map((img) => ({ src: img.getAttribute('src'), ok: img.complete && img.naturalWidth > 0 }));
        // Figures of each grid: their boxes, and their captions' boxes.
        const grids = [...document.querySelectorAll('.grid')].map((g) => [...g.querySelectorAll(':scope > figure')].map((f) => {
          const r = f.getBoundingClientRect();
          const c = f.querySelector('figcaption');
          const cr = c ? c.getBoundingClientRect() : r;
          return { left: r.left, top: r.top, right: r.right, bottom: r.bottom, width: r.width,
            caption: { left: cr.left, top: cr.top, right: cr.right, bottom: cr.bottom } };
        }));
        // Elements sticking out of the window on the right (the page would scroll sideways).
        const wide = [...document.body.querySelectorAll('*')].filter((e) => {
          const r = e.getBoundingClientRect();
          return r.width > 0 && r.right > window.innerWidth + 1 && !e.closest('table');
        }).map((e) => e.tagName + (e.className ? '.' + e.className : '')).slice(0, 5);
        const tables = [...document.querySelectorAll('table')].map((t) => t.getBoundingClientRect().right);
        return { scrollWidth: doc.scrollWidth, innerWidth: window.innerWidth, images, grids, wide, tables,
          viewport: !!document.querySelector('meta[name=viewport]') };
      });
      const what = `${label} report at ${width} px`;
      check(`${what}: ${seen.images.length} pictures, all loaded`, seen.images.length >= 4 && seen.images.every((i) => i.ok),
        JSON.stringify(seen.images.filter((i) => !i.ok)));
      check(`${what}: no sideways scrolling`, seen.scrollWidth <= seen.innerWidth && seen.wide.length === 0,
        `page ${seen.scrollWidth} px wide in a ${seen.innerWidth} px window; sticking out: ${seen.wide.join(', ')}`);
      check(`${what}: tables inside the window`, seen.tables.every((r) => r <= seen.innerWidth + 1), JSON.stringify(seen.tables));
      check(`${what}: a viewport meta tag`, seen.viewport);
      const multi = seen.grids.filter((g) => g.length >= 2);
      check(`${what}: figures in grids`, multi.length >= 1, JSON.stringify(seen.grids.map((g) => g.length)));
      for (const [k, g] of multi.entries()) {
        const firstRow = g.filter((f) => Math.abs(f.top - g[0].top) < 2).length;
        if (width === 1400) check(`${what}: grid ${k} side by side`, firstRow >= 2, JSON.stringify(g.map((f) => f.top)));
        else check(`${what}: grid ${k} stacked, each figure the window's width`,
          g.every((f) => f.width > 0.8 * (seen.innerWidth - 20)) && g.every((f, i) => i === 0 || f.top >= g[i - 1].bottom - 1),
          JSON.stringify(g.map((f) => [f.left, f.top, f.width])));
        // A caption stays inside its own figure, so it never prints over a neighbour.
        check(`${what}: grid ${k} captions inside their figures`, g.every((f) => f.caption.left >= f.left - 1 &&
          f.caption.right <= f.right + 1 && f.caption.bottom <= f.bottom + 1), JSON.stringify(g.map((f) => [f.left, f.right, f.caption])));
      }
      check(`${what}: no script errors`, errors.length === 0, errors.join('; '));
      if (screenshotDir) await page.screenshot({ path: path.join(screenshotDir, `report-${label}-${width}.png`), fullPage: true });
      await page.close();
    }
  }
} finally {
  await browser.close();
  clearTimeout(guard);
  if (!process.env.TFMATCH_KEEP) fs.rmSync(work, { recursive: true, force: true });
}
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
