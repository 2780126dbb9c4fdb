// A picture of part of a report page for docs/ (run via `scripts/browser shot`).
//
//   node shot.mjs FILE.html OUT.png SELECTOR HEIGHT
//
// Opens FILE.html from disk at 1280 px wide, scrolls SELECTOR's element into view, waits for
// the viewers there to draw, and saves the HEIGHT pixels of the page from that element's top.
import { resolve } from 'node:path';
import { pathToFileURL } from 'node:url';
import { launch } from './common.mjs';

const [file, out, selector, height] = process.argv.slice(2);
if (!file || !out || !selector || !(Number(height) > 0)) {
  console.error('usage: shot.mjs FILE.html OUT.png SELECTOR HEIGHT');
  process.exit(2);
}
const browser = await launch();
try {
  const { page } = browser;
  await page.goto(pathToFileURL(resolve(file)).href, { waitUntil: 'load' });
  const el = await page.$(selector);
  if (!el) throw new Error(`no element ${selector}`);
  const top = await el.evaluate((e) => e.getBoundingClientRect().top + window.scrollY);
  // Viewers mount when they come near the viewport: pass over the region, waiting at each
  // step for a moment to let them load and draw.
  for (let y = top; y < top + Number(height); y += 400) {
    await page.evaluate((y) => window.scrollTo(0, y), y);
    await page.waitForTimeout(700);
  }
  await page.waitForTimeout(1000);
  await page.screenshot({
    path: out, fullPage: true,
    clip: { x: 0, y: Math.max(0, top - 8), width: 1280, height: Number(height) },
  });
  console.log(resolve(out));
} finally {
  await browser.close();
}
