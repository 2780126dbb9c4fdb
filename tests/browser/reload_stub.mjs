// A stand-in for `texsyn watch --serve`, for `scripts/browser selftest`: serves on 127.0.0.1 a
// page that includes report.js and, at /version, the modification time and size of FILE.
//
//   node reload_stub.mjs FILE [--no-meta]   prints the page's URL, serves until killed
// --no-meta leaves out <meta name="texsyn-reload"> (a page that cannot reload).
import { createServer } from 'node:http';
import { readFileSync, statSync } from 'node:fs';
import { fileURLToPath } from 'node:url';

const file = process.argv[2];
const meta = !process.argv.includes('--no-meta');
const reportJs = readFileSync(fileURLToPath(new URL('../../src/report/assets/report.js', import.meta.url)));
const version = () => {
  const s = statSync(file);
  return `${s.mtimeMs}-${s.size}`;
};
const page = `<!DOCTYPE html><html><head><meta charset="utf-8">
${meta ? '<meta name="texsyn-reload" content="/version">' : ''}<title>reload stub</title></head>
<body><p>version at load: ${'%VERSION%'}</p><script src="/report.js"></script></body></html>`;

const server = createServer((req, res) => {
  const send = (type, body) => {
    res.writeHead(200, { 'content-type': type, 'cache-control': 'no-store' });
    res.end(body);
  };
  if (req.url === '/') send('text/html; charset=utf-8', page.replace('%VERSION%', version()));
  else if (req.url === '/version') send('text/plain', version());
  else if (req.url === '/report.js') send('text/javascript', reportJs);
  else { res.writeHead(404); res.end(); }
});
server.listen(0, '127.0.0.1', () => console.log(`http://127.0.0.1:${server.address().port}/`));
