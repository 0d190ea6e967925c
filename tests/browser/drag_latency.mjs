// Benchmark, not a test: the time from the end of a drag to the four full-resolution images of
// `tfmatch view` in a real browser (headless Chromium through puppeteer-core), as a user sees it.
//
//   node drag_latency.mjs PATH/TO/tfmatch [SIZE] [DRAGS] [-- VIEW ARGS...]
//
// SIZE: the page's image size (longer side, default 512); DRAGS: how many drags (default 7);
// VIEW ARGS: what `tfmatch view` loads (default --demo, the 96^3 demo pair). Prints each drag's
// time, the median, the server's own time of the four images (X-Tfmatch-Render-Ms) and of their
// renders (Server-Timing), measured in the same run.

import { spawn } from 'node:child_process';
import fs from 'node:fs';

const [binary, sizeArg, dragsArg] = process.argv.slice(2);
const dash = process.argv.indexOf('--');
const viewArgs = dash > 0 ? process.argv.slice(dash + 1) : ['--demo'];
if (!binary || !fs.existsSync(binary)) {
  console.error('usage: node drag_latency.mjs PATH/TO/tfmatch [SIZE] [DRAGS] [-- VIEW ARGS...]');
  process.exit(2);
}
const size = parseInt(sizeArg || '512', 10);
const drags = parseInt(dragsArg || '7', 10);
const puppeteer = (await import('puppeteer-core')).default;
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

const child = spawn(binary, ['view', '--port', '0', ...viewArgs], { stdio: ['ignore', 'pipe', 'inherit'] });
const url = await new Promise((resolve, reject) => {
  let out = '';
  child.stdout.on('data', (d) => {
    out += d;
    const m = /http:\/\/127\.0\.0\.1:\d+\/\?token=[0-9a-f]+/.exec(out);
    if (m) resolve(m[0]);
  });
  child.on('exit', (code) => reject(new Error(`tfmatch view exited (${code}) before its URL`)));
});

const browser = await puppeteer.launch({ executablePath: process.env.TFMATCH_CHROMIUM || '/usr/bin/chromium',
                                         headless: true, args: ['--no-sandbox'] });
try {
  const page = await browser.newPage();
  await page.setViewport({ width: 1400, height: 1000 });
  const renderMs = [];  // the server's own render time of each full-size image
  const dispatchMs = [];  // of that, the render's dispatch (Server-Timing "render")
  page.on('response', (r) => {
    if (r.url().includes('/api/render') && r.url().includes(`w=${size}`) && r.headers()['x-tfmatch-render-ms']) {
      renderMs.push(Number(r.headers()['x-tfmatch-render-ms']));
      const m = /render;dur=([0-9.]+)/.exec(r.headers()['server-timing'] || '');
      if (m) dispatchMs.push(Number(m[1]));
    }
  });
  await page.goto(`${url}&size=${size}`, { waitUntil: 'load' });
  const idle = (cond) => page.waitForFunction(`(() => { const v = window.tfmViewer; return !!v && !v.busy && (${cond}); })()`,
                                              { timeout: 300000, polling: 20 });
  await idle('v.imageVersion >= 1 && v.metricsVersion >= 1');
  const times = [], serverSums = [], dispatchSums = [];
  for (let i = 0; i < drags; i++) {
    const version = await page.evaluate(() => window.tfmViewer.imageVersion);
    const h = await page.$('.view[data-view="reference"] .view-frame');
    await h.evaluate((e) => e.scrollIntoView({ block: 'center' }));
    const box = await h.boundingBox();
    const x = box.x + box.width / 2, y = box.y + box.height / 2;
    await page.mouse.move(x, y);
    await page.mouse.down();
    for (let k = 1; k <= 8; k++) {
      await page.mouse.move(x + 6 * k * (i % 2 ? -1 : 1), y + 2 * k);
      await sleep(40);
    }
    renderMs.length = 0;
    dispatchMs.length = 0;
    await page.mouse.up();
    await idle(`v.imageVersion > ${version}`);
    times.push(await page.evaluate(() => window.tfmViewer.lastFullResMs));
    serverSums.push(renderMs.slice(0, 4).reduce((a, b) => a + b, 0));
    dispatchSums.push(dispatchMs.slice(0, 4).reduce((a, b) => a + b, 0));
    await sleep(300);
  }
  const median = (a) => [...a].sort((p, q) => p - q)[Math.floor(a.length / 2)];
  console.log(`tfmatch view ${viewArgs.join(' ')}, ${size}² images, ${drags} drags`);
  console.log(`drag end -> four full images: ${times.join(', ')} ms; median ${median(times)} ms`);
  console.log(`server render time of the four (sum): ${serverSums.map((s) => s.toFixed(0)).join(', ')} ms; median ${median(serverSums).toFixed(0)} ms`);
  const beyond = times.map((t, i) => (t - dispatchSums[i]) / 4);
  console.log(`the renders' dispatches (sum): median ${median(dispatchSums).toFixed(0)} ms; beyond them per picture: median ${median(beyond).toFixed(1)} ms`);
} finally {
  await browser.close();
  child.kill('SIGINT');
}
