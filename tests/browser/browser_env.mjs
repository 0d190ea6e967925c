// What every real-browser test needs first: the tfmatch binary from its command line, Chromium and
// puppeteer-core. Exits 2 (usage) without a binary, and 77 (ctest: skipped), saying what is
// missing, without Chromium or puppeteer-core. TFMATCH_CHROMIUM overrides /usr/bin/chromium;
// TFMATCH_SCREENSHOT_DIR names a folder for screenshots (made here), or is empty.

import fs from 'node:fs';

export const SKIP = 77;

// `script`: the test's file name, `what`: what it tests ("tfmatch view"), for the messages.
export async function browserEnvironment(script, what) {
  const binary = process.argv[2];
  if (!binary) {
    console.error(`usage: node ${script} PATH/TO/tfmatch`);
    process.exit(2);
  }
  if (!fs.existsSync(binary)) {
    console.error(`${what} browser test: no tfmatch binary at ${binary}`);
    process.exit(2);
  }
  const chromium = process.env.TFMATCH_CHROMIUM || '/usr/bin/chromium';
  if (!fs.existsSync(chromium)) {
    console.log(`SKIPPED: no Chromium at ${chromium} (Debian package chromium); the browser test of ${what} did not run`);
    process.exit(SKIP);
  }
  let puppeteer;
  try {
    puppeteer = (await import('puppeteer-core')).default;
  } catch (e) {
    console.log(`SKIPPED: puppeteer-core is not installed (run \`npm ci\` in tests/browser); the browser test of ${what} did not run`);
    process.exit(SKIP);
  }
  const screenshotDir = process.env.TFMATCH_SCREENSHOT_DIR || '';
  if (screenshotDir) fs.mkdirSync(screenshotDir, { recursive: true });
  return { binary, chromium, puppeteer, screenshotDir };
}
