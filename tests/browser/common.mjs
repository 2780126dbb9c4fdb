// Shared by the browser checks: starts Debian's headless chromium through playwright-core
// (installed into tools/browser by `scripts/browser install`).
import { createRequire } from 'node:module';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

export const CHROMIUM = process.env.TEXSYN_CHROMIUM || '/usr/bin/chromium';

// --use-angle=swiftshader is what gives WebGL (2.0, SwiftShader) under --disable-gpu on this
// machine; --enable-unsafe-swiftshader alone does not. Both are passed.
export const FLAGS = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
];

function playwright() {
  const dir = process.env.TEXSYN_BROWSER_DIR;
  if (!dir) throw new Error('TEXSYN_BROWSER_DIR is not set (run through scripts/browser)');
  return createRequire(join(dir, 'node_modules') + '/')('playwright-core');
}

/** Launches chromium with a fresh profile; returns {context, page, close}. */
export async function launch() {
  const { chromium } = playwright();
  const profile = mkdtempSync(join(tmpdir(), 'texsyn-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: CHROMIUM,
    headless: true,
    args: FLAGS,
    viewport: { width: 1280, height: 900 },
    deviceScaleFactor: 1,
  });
  const page = context.pages()[0] || (await context.newPage());
  const close = async () => {
    await context.close().catch(() => {});
    rmSync(profile, { recursive: true, force: true });
  };
  return { context, page, close };
}

/** Prints the JSON summary and exits 0 (pass) or 1 (fail, with summary.reason). */
export function finish(summary) {
  summary.pass = !summary.reason;
  console.log(JSON.stringify(summary, null, 2));
  if (summary.reason) console.error(`FAIL: ${summary.reason}`);
  process.exit(summary.pass ? 0 : 1);
}
