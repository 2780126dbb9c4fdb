// Checks a `texsyn report` HTML page in headless chromium (run via `scripts/browser check-report`).
//
//   node check_report.mjs FILE.html [--sort TABLEID] [--screenshot OUT.png]
//
// Asserts: no console errors and no uncaught page errors; every window.texsynViewers entry
// (one per .texsyn-viewer, opened out of any <details> and scrolled into view) loads within
// 60 s, for each of its models (clicking its .texsyn-viewer-toggle buttons), with at least
// MIN_FRACTION of the canvas differing from the #e8e8e8 background; dragging on the canvas
// changes the picture and "reset view" restores it; every select.filter shows exactly the rows
// whose column holds the chosen value; with --sort, clicking the header of the table's last
// numeric column sorts its rows ascending, then descending. Prints a JSON summary; exit 0 on
// pass, 1 on failure (summary.reason says why), 2 on bad usage.
import { resolve } from 'node:path';
import { existsSync } from 'node:fs';
import { pathToFileURL } from 'node:url';
import { launch, finish } from './common.mjs';

const LOAD_TIMEOUT_MS = 60_000;
const MIN_FRACTION = 0.01; // share of canvas pixels that must differ from the background
const BG = [0xe8, 0xe8, 0xe8];
const TOLERANCE = 10;

function usage(msg) {
  console.error(`${msg}\nusage: check_report.mjs FILE.html [--sort TABLEID] [--screenshot OUT.png]`);
  process.exit(2);
}

const opts = { file: null, sort: null, screenshot: null };
const argv = process.argv.slice(2);
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  if (a === '--sort' || a === '--screenshot') {
    if (argv[i + 1] === undefined) usage(`${a} needs a value`);
    opts[a.slice(2)] = argv[++i];
  } else if (a.startsWith('--')) usage(`unknown option ${a}`);
  else if (opts.file) usage(`unexpected argument ${a}`);
  else opts.file = a;
}
if (!opts.file) usage('no FILE given');
if (!existsSync(opts.file)) usage(`no such file: ${opts.file}`);

const summary = {
  file: resolve(opts.file), pass: false, reason: null,
  viewers: [], filters: [], sort: null, screenshot: null, consoleErrors: [], pageErrors: [],
};
const failures = [];
const fail = (msg) => failures.push(msg);

/** In the page: share of viewer i's canvas pixels that differ from the background, and a digest. */
function canvasStats([i, bg, tol]) {
  const el = document.querySelectorAll('.texsyn-viewer')[i];
  const c = el && el.querySelector('canvas');
  if (!c || !c.width || !c.height) return null;
  const copy = document.createElement('canvas');
  copy.width = c.width;
  copy.height = c.height;
  const g = copy.getContext('2d', { willReadFrequently: true });
  g.drawImage(c, 0, 0);
  const d = g.getImageData(0, 0, c.width, c.height).data;
  let n = 0;
  const sample = [];
  for (let p = 0; p < d.length; p += 4) {
    if (Math.abs(d[p] - bg[0]) > tol || Math.abs(d[p + 1] - bg[1]) > tol ||
        Math.abs(d[p + 2] - bg[2]) > tol) n++;
    if (p % 64 === 0) sample.push(d[p], d[p + 1], d[p + 2]);
  }
  return { width: c.width, height: c.height, fraction: n / (c.width * c.height), sample };
}

function sampleDiff(a, b) {
  let diff = 0;
  for (let k = 0; k < a.length; k += 3) {
    if (Math.abs(a[k] - b[k]) + Math.abs(a[k + 1] - b[k + 1]) + Math.abs(a[k + 2] - b[k + 2]) > 30) diff++;
  }
  return diff / (a.length / 3);
}

const nextFrames = (page) => page.evaluate(() => new Promise((r) =>
  requestAnimationFrame(() => requestAnimationFrame(r))));

async function checkViewer(page, i) {
  const result = { index: i, models: [], interaction: null };
  summary.viewers.push(result);
  await page.evaluate((i) => {
    const el = document.querySelectorAll('.texsyn-viewer')[i];
    for (let d = el.closest('details'); d; d = d.parentElement && d.parentElement.closest('details')) {
      d.open = true;
    }
  }, i);
  const div = page.locator('.texsyn-viewer').nth(i);
  await div.scrollIntoViewIfNeeded();
  const toggles = div.locator('.texsyn-viewer-toggle');
  const nToggles = await toggles.count();
  for (let j = 0; j < Math.max(nToggles, 1); j++) {
    if (nToggles > 0) await toggles.nth(j).click();
    const started = Date.now();
    const settled = await page.waitForFunction((i) => {
      const s = window.texsynViewers[i];
      return s && (s.loaded || s.error);
    }, i, { timeout: LOAD_TIMEOUT_MS }).then(() => true, () => false);
    const status = await page.evaluate((i) => window.texsynViewers[i], i);
    const model = { label: status.model, loaded: status.loaded, error: status.error,
      ms: Date.now() - started, fraction: null };
    result.models.push(model);
    const name = `viewer ${i} model "${status.model}"`;
    if (!settled) { fail(`${name} did not load within ${LOAD_TIMEOUT_MS / 1000} s`); continue; }
    if (status.error) { fail(`${name} failed to load: ${status.error}`); continue; }
    const stats = await page.evaluate(canvasStats, [i, BG, TOLERANCE]);
    if (!stats) { fail(`${name}: no canvas with a size`); continue; }
    model.fraction = Number(stats.fraction.toFixed(4));
    model.canvas = `${stats.width}x${stats.height}`;
    if (stats.fraction < MIN_FRACTION) {
      fail(`${name}: only ${(100 * stats.fraction).toFixed(2)}% of the canvas differs from the ` +
        `background (need ${100 * MIN_FRACTION}%)`);
    }
  }
  if (failures.length) return;
  // Orbit: a drag must change the picture, "reset view" must bring it back.
  // The mouse acts in the viewport: bring the canvas into it first.
  await div.locator('canvas').scrollIntoViewIfNeeded();
  await nextFrames(page);
  const before = await page.evaluate(canvasStats, [i, BG, TOLERANCE]);
  const box = await div.locator('canvas').boundingBox();
  const cx = box.x + box.width / 2;
  const cy = box.y + box.height / 2;
  await page.mouse.move(cx, cy);
  await page.mouse.down();
  await page.mouse.move(cx + 120, cy + 40, { steps: 6 });
  await page.mouse.up();
  await nextFrames(page);
  const dragged = await page.evaluate(canvasStats, [i, BG, TOLERANCE]);
  await div.locator('.texsyn-viewer-reset').click();
  await nextFrames(page);
  const reset = await page.evaluate(canvasStats, [i, BG, TOLERANCE]);
  result.interaction = {
    dragChanged: Number(sampleDiff(before.sample, dragged.sample).toFixed(4)),
    resetDiffers: Number(sampleDiff(before.sample, reset.sample).toFixed(4)),
  };
  if (result.interaction.dragChanged < 0.001) fail(`viewer ${i}: dragging did not rotate the view`);
  if (result.interaction.resetDiffers > 0.01) fail(`viewer ${i}: "reset view" did not restore the view`);
}

/** In the page: the rows of table #id as [{text, hidden, cells: [key]}], key = data-value or text. */
function tableRows(id) {
  const table = document.getElementById(id);
  if (!table) return null;
  const rows = [];
  for (const body of table.tBodies) {
    for (const row of body.rows) {
      if (!row.querySelector('td')) continue; // a header row inside tbody
      rows.push({
        text: row.textContent.replace(/\s+/g, ' ').trim(),
        hidden: row.hidden || getComputedStyle(row).display === 'none',
        cells: [...row.cells].map((c) => c.getAttribute('data-value') ?? c.textContent.trim()),
        texts: [...row.cells].map((c) => c.textContent.trim()),
      });
    }
  }
  return rows;
}

function asNumber(s) {
  if (s === '' || s == null) return null;
  const n = Number(s);
  if (!Number.isNaN(n)) return n;
  const l = s.toLowerCase();
  if (['inf', '+inf', 'infinity'].includes(l)) return Infinity;
  if (['-inf', '-infinity'].includes(l)) return -Infinity;
  return null;
}

async function checkFilters(page) {
  const selects = page.locator('select.filter[data-table]');
  const n = await selects.count();
  for (let k = 0; k < n; k++) {
    const sel = selects.nth(k);
    const tableId = await sel.getAttribute('data-table');
    const col = Number(await sel.getAttribute('data-column'));
    const values = (await sel.locator('option').evaluateAll((os) => os.map((o) => o.value)))
      .filter((v) => v !== '');
    const rec = { table: tableId, column: col, tried: [] };
    summary.filters.push(rec);
    for (const value of values.slice(0, 3)) {
      await sel.selectOption(value);
      const rows = await page.evaluate(tableRows, tableId);
      if (!rows) { fail(`filter on missing table #${tableId}`); break; }
      const shown = rows.filter((r) => !r.hidden);
      const want = rows.filter((r) => r.texts[col] === value);
      rec.tried.push({ value, shown: shown.length, matching: want.length });
      if (shown.length !== want.length || shown.some((r) => r.texts[col] !== value)) {
        fail(`filter #${tableId} column ${col} = "${value}" shows ${shown.length} rows, ` +
          `expected the ${want.length} rows holding that value`);
      }
    }
    await sel.selectOption('');
    const rows = await page.evaluate(tableRows, tableId);
    if (rows && rows.some((r) => r.hidden)) fail(`filter #${tableId}: "all" leaves rows hidden`);
  }
}

async function checkSort(page, id) {
  const rec = { table: id, column: null, header: null, initial: null, ascending: null, descending: null };
  summary.sort = rec;
  const rows = await page.evaluate(tableRows, id);
  if (!rows) { fail(`--sort: no table with id "${id}"`); return; }
  if (rows.length === 0) { fail(`--sort: table #${id} has no body rows`); return; }
  const ncol = Math.max(...rows.map((r) => r.cells.length));
  let col = -1;
  for (let c = 0; c < ncol; c++) {
    if (rows.every((r) => asNumber(r.cells[c]) !== null)) col = c;
  }
  if (col < 0) { fail(`--sort: table #${id} has no numeric column`); return; }
  rec.column = col;
  // The header cell over column `col` (counting colspans) in the table's first row.
  const th = await page.evaluateHandle(([id, col]) => {
    const table = document.getElementById(id);
    const head = table.tHead ? table.tHead.rows[0] : table.rows[0];
    let at = 0;
    for (const cell of head.cells) {
      if (at === col) return cell;
      at += cell.colSpan || 1;
    }
    return null;
  }, [id, col]);
  const el = th.asElement();
  if (!el) { fail(`--sort: table #${id} has no header cell over column ${col}`); return; }
  rec.header = (await el.textContent()).trim();
  const column = (rs) => rs.map((r) => asNumber(r.cells[col]));
  const rowSet = (rs) => rs.map((r) => r.text).sort().join('\n');
  rec.initial = column(rows);
  for (const dir of ['ascending', 'descending']) {
    await el.click();
    const now = await page.evaluate(tableRows, id);
    const vals = column(now);
    rec[dir] = vals;
    if (rowSet(now) !== rowSet(rows)) { fail(`--sort: sorting #${id} changed its set of rows`); return; }
    const ok = vals.every((v, k) => k === 0 || (dir === 'ascending' ? vals[k - 1] <= v : vals[k - 1] >= v));
    if (!ok) fail(`--sort: after ${dir === 'ascending' ? 'one click' : 'two clicks'} on "${rec.header}" ` +
      `column ${col} of #${id} is not ${dir}: ${JSON.stringify(vals)}`);
    const aria = await el.getAttribute('aria-sort');
    if (aria !== dir) fail(`--sort: header "${rec.header}" has aria-sort=${aria}, expected ${dir}`);
  }
  const distinct = new Set(rec.initial).size > 1;
  if (distinct && JSON.stringify(rec.ascending) === JSON.stringify(rec.descending)) {
    fail(`--sort: clicking "${rec.header}" twice did not change the row order of #${id}`);
  }
}

let browser = null;
try {
  browser = await launch();
  const { page } = browser;
  page.on('console', (m) => {
    if (m.type() === 'error') {
      const loc = m.location();
      summary.consoleErrors.push(m.text() + (loc && loc.url ? ` (${loc.url.slice(0, 120)}:${loc.lineNumber})` : ''));
    }
  });
  page.on('pageerror', (e) => summary.pageErrors.push(String(e && e.stack ? e.stack : e).slice(0, 500)));
  await page.goto(pathToFileURL(summary.file).href, { waitUntil: 'load', timeout: LOAD_TIMEOUT_MS });
  const nDivs = await page.locator('.texsyn-viewer').count();
  const nStatus = await page.evaluate(() =>
    (Array.isArray(window.texsynViewers) ? window.texsynViewers.length : -1));
  if (nDivs > 0 && nStatus !== nDivs) {
    fail(nStatus < 0 ? `${nDivs} .texsyn-viewer elements but no window.texsynViewers (viewer bundle not run)`
      : `${nDivs} .texsyn-viewer elements but ${nStatus} window.texsynViewers entries`);
  } else {
    for (let i = 0; i < nDivs; i++) await checkViewer(page, i);
  }
  await checkFilters(page);
  if (opts.sort) await checkSort(page, opts.sort);
  if (opts.screenshot) {
    await page.evaluate(() => window.scrollTo(0, 0));
    await nextFrames(page);
    await page.screenshot({ path: opts.screenshot, fullPage: true });
    summary.screenshot = resolve(opts.screenshot);
  }
} catch (e) {
  fail(`check crashed: ${e && e.message ? e.message : e}`);
} finally {
  if (browser) await browser.close();
}
if (summary.consoleErrors.length) fail(`console error: ${summary.consoleErrors[0]}`);
if (summary.pageErrors.length) fail(`page error: ${summary.pageErrors[0]}`);
summary.reason = failures.length ? failures.join('; ') : null;
finish(summary);
