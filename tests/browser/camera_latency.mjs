// Benchmark, not a test: `tfmatch view`'s latency from a plain HTTP client (Node's fetch, no
// browser): per camera change, the four pictures fetched in parallel as the page fetches them,
// timed from the first request to the last byte, with the server's own breakdown of each picture
// (its Server-Timing header: wait, render, readback, compose, decorate, encode).
//
//   node camera_latency.mjs PATH/TO/tfmatch [SIZE] [CHANGES] [QUERY] [-- VIEW ARGS...]
//
// SIZE: image side (default 512); CHANGES: camera changes (default 7, after 2 unmeasured);
// QUERY: extra query parameters of every picture request, as the page adds them (default the
// page's: "frame=fast&client=bench"; "-" for none: plain PNGs as downloads get them); VIEW ARGS:
// what `tfmatch view` loads (default --demo, the 96^3 demo pair). Prints the medians and "beyond
// the renders": (client time - the four renders' sum) / 4, per picture.

import { spawn } from 'node:child_process';
import fs from 'node:fs';

const args = process.argv.slice(2);
const dash = args.indexOf('--');
const [binary, sizeArg, changesArg, queryArg] = dash >= 0 ? args.slice(0, dash) : args;
const viewArgs = dash >= 0 ? args.slice(dash + 1) : ['--demo'];
if (!binary || !fs.existsSync(binary)) {
  console.error('usage: node camera_latency.mjs PATH/TO/tfmatch [SIZE] [CHANGES] [QUERY] [-- VIEW ARGS...]');
  process.exit(2);
}
const size = parseInt(sizeArg || '512', 10);
const changes = parseInt(changesArg || '7', 10);
const extra = queryArg === '-' ? '' : (queryArg || 'frame=fast&client=bench');
const VIEWS = ['reference', 'field-ref-tf', 'field-opt-tf', 'residual'];

const child = spawn(binary, ['view', '--port', '0', ...viewArgs], { stdio: ['ignore', 'pipe', 'inherit'] });
const base = await new Promise((resolve, reject) => {
  let out = '';
  child.stdout.on('data', (d) => {
    out += d;
    const m = /(http:\/\/127\.0\.0\.1:\d+)\/\?token=([0-9a-f]+)/.exec(out);
    if (m) resolve({ origin: m[1], token: m[2] });
  });
  child.on('exit', (code) => reject(new Error(`tfmatch view exited (${code}) before its URL`)));
});

function timing(header) {
  const parts = {};
  for (const p of (header || '').split(',')) {
    const m = /^\s*([a-z]+);dur=([0-9.]+)/.exec(p);
    if (m) parts[m[1]] = Number(m[2]);
  }
  return parts;
}
const median = (a) => [...a].sort((p, q) => p - q)[Math.floor(a.length / 2)];
const sum = (a) => a.reduce((x, y) => x + y, 0);

try {
  const totals = [], renders = [], parts = {};
  for (let i = -2; i < changes; i++) {
    const az = 30 + 7 * (i + 2), seq = i + 3;
    const t0 = performance.now();
    const responses = await Promise.all(VIEWS.map(async (view) => {
      const url = `${base.origin}/api/render?view=${view}&az=${az}&w=${size}&h=${size}&token=${base.token}` +
        (extra ? `&${extra}&seq=${seq}` : '');
      const r = await fetch(url);
      const body = await r.arrayBuffer();
      if (!r.ok) throw new Error(`${view}: HTTP ${r.status} ${Buffer.from(body).toString()}`);
      return { t: timing(r.headers.get('server-timing')), bytes: body.byteLength };
    }));
    const total = performance.now() - t0;
    if (i < 0) continue;  // warm-up: pipelines, first-touch memory
    totals.push(total);
    renders.push(sum(responses.map((r) => r.t.render || 0)));
    for (const r of responses)
      for (const [k, v] of Object.entries({ ...r.t, kB: r.bytes / 1024 })) (parts[k] ||= []).push(v);
  }
  const beyond = totals.map((t, i) => (t - renders[i]) / VIEWS.length);
  console.log(`tfmatch view ${viewArgs.join(' ')}: four ${size}² pictures per camera change, ${changes} changes` +
              (extra ? ` (${extra})` : ' (plain PNG)'));
  console.log(`client: ${totals.map((t) => t.toFixed(0)).join(', ')} ms; median ${median(totals).toFixed(1)} ms`);
  console.log(`four renders (sum): median ${median(renders).toFixed(1)} ms; beyond the renders per picture: median ` +
              `${median(beyond).toFixed(1)} ms`);
  console.log('per picture, median: ' + Object.entries(parts).map(([k, v]) => `${k} ${median(v).toFixed(2)}`).join(', '));
} finally {
  child.kill('SIGINT');
}
