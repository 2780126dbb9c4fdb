// Checks live reload of a page served by `texsyn watch --serve` (run via
// `scripts/browser check-reload`).
//
//   node check_reload.mjs URL FILE [--timeout SECONDS] [--keep]
//
// Opens URL, waits for it to load and for its <meta name="texsyn-reload"> URL to answer once,
// appends "# touched by the reload check" to FILE (a config the server watches) and expects the
// page to load again within the timeout (60 s). FILE's previous content is put back afterwards
// unless --keep. Console errors are recorded but do not fail the check (polls fail while the
// server restarts). Prints a JSON summary; exit 0 on pass, 1 on failure, 2 on bad usage.
import { appendFileSync, existsSync, readFileSync, writeFileSync } from 'node:fs';
import { resolve } from 'node:path';
import { launch, finish } from './common.mjs';

const LINE = '# touched by the reload check';

function usage(msg) {
  console.error(`${msg}\nusage: check_reload.mjs URL FILE [--timeout SECONDS] [--keep]`);
  process.exit(2);
}

const opts = { url: null, file: null, timeout: 60, keep: false };
const argv = process.argv.slice(2);
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  if (a === '--timeout') opts.timeout = Number(argv[++i]);
  else if (a === '--keep') opts.keep = true;
  else if (a.startsWith('--')) usage(`unknown option ${a}`);
  else if (!opts.url) opts.url = a;
  else if (!opts.file) opts.file = a;
  else usage(`unexpected argument ${a}`);
}
if (!opts.url || !opts.file) usage('URL and FILE are needed');
if (!(opts.timeout > 0)) usage('--timeout needs a positive number of seconds');
if (!existsSync(opts.file)) usage(`no such file: ${opts.file}`);

const summary = {
  url: opts.url, file: resolve(opts.file), pass: false, reason: null,
  reloadUrl: null, polls: 0, reloaded: false, seconds: null, restored: null, consoleErrors: [],
  pageErrors: [],
};
let browser = null;
let original = null;
try {
  browser = await launch();
  const { page } = browser;
  page.on('console', (m) => { if (m.type() === 'error') summary.consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => summary.pageErrors.push(String(e)));
  await page.goto(opts.url, { waitUntil: 'load', timeout: 60_000 });
  summary.reloadUrl = await page.evaluate(() => {
    const m = document.querySelector('meta[name="texsyn-reload"]');
    return m ? new URL(m.getAttribute('content'), location.href).href : null;
  });
  if (!summary.reloadUrl) throw new Error('the page has no <meta name="texsyn-reload" content="URL">');
  // The page remembers the first version it sees: wait for that poll before touching FILE.
  const polled = (r) => r.url() === summary.reloadUrl && r.ok();
  page.on('response', (r) => { if (polled(r)) summary.polls++; });
  if (summary.polls === 0) {
    await page.waitForResponse(polled, { timeout: 10_000 }).catch(() => {
      throw new Error(`the page did not poll ${summary.reloadUrl} successfully within 10 s`);
    });
  }
  await page.waitForTimeout(100);
  const reload = page.waitForEvent('load', { timeout: opts.timeout * 1000 }).then(() => true, () => false);
  original = readFileSync(opts.file);
  const sep = original.length && original[original.length - 1] !== 0x0a ? '\n' : '';
  const started = Date.now();
  appendFileSync(opts.file, `${sep}${LINE}\n`);
  summary.reloaded = await reload;
  summary.seconds = Number(((Date.now() - started) / 1000).toFixed(2));
  if (!summary.reloaded) summary.reason = `the page did not reload within ${opts.timeout} s of touching ${opts.file}`;
} catch (e) {
  summary.reason = `check failed: ${e && e.message ? e.message : e}`;
} finally {
  if (original !== null && !opts.keep) {
    writeFileSync(opts.file, original);
    summary.restored = true;
  }
  if (browser) await browser.close();
}
finish(summary);
