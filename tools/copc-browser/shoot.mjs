// Serves index.html, main.js, three.js (from node_modules) and a folder decode.mjs wrote on
// 127.0.0.1 (a port the system picks), opens the page in Debian's headless Chromium through
// playwright-core, waits for it to have drawn once and saves a screenshot of the page (the
// canvas, WxH at one device pixel per pixel, transparent where nothing is drawn). Prints one JSON
// object (the page's report and the times).
//
//   node shoot.mjs --data DIR --centre X,Y,Z --radius R [--view AZ,EL,DIST] [--size WxH]
//                  [--up y|z] [--shade 0|1] [--chromium PATH] -o SHOT.png
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const opt = { view: '30,20,3', size: '512x512', up: 'y', shade: '1', chromium: '/usr/bin/chromium' };
const argv = process.argv.slice(2);
for (let i = 0; i < argv.length; ++i) {
  const k = argv[i];
  if (k === '-o') opt.out = argv[++i];
  else if (k.startsWith('--') && k.includes('=')) opt[k.slice(2, k.indexOf('='))] = k.slice(k.indexOf('=') + 1);
  else if (k.startsWith('--') && i + 1 < argv.length) opt[k.slice(2)] = argv[++i];
  else {
    console.error(`shoot.mjs: unexpected argument ${k}`);
    process.exit(2);
  }
}
for (const k of ['data', 'centre', 'radius', 'out'])
  if (!opt[k]) {
    console.error('usage: node shoot.mjs --data DIR --centre X,Y,Z --radius R [--view AZ,EL,DIST] ' +
                  '[--size WxH] [--up y|z] [--shade 0|1] [--chromium PATH] -o SHOT.png');
    process.exit(2);
  }
const [w, h] = opt.size.split('x').map(Number);
const dataDir = path.resolve(opt.data);

const types = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript',
                '.json': 'application/json', '.bin': 'application/octet-stream' };
// Only these: the page, its module, three.js, and the data folder.
function resolve(urlPath) {
  const p = decodeURIComponent(urlPath);
  const inside = (root, rel) => {
    const f = path.resolve(root, '.' + rel);
    return f === root || f.startsWith(root + path.sep) ? f : null;
  };
  if (p === '/' || p === '/index.html') return path.join(here, 'index.html');
  if (p === '/main.js') return path.join(here, 'main.js');
  if (p.startsWith('/node_modules/three/')) return inside(path.join(here, 'node_modules/three'), p.slice('/node_modules/three'.length));
  if (p.startsWith('/data/')) return inside(dataDir, p.slice('/data'.length));
  return null;
}
const server = http.createServer((req, res) => {
  const f = resolve(new URL(req.url, 'http://localhost').pathname);
  if (!f || !fs.existsSync(f) || !fs.statSync(f).isFile()) {
    res.writeHead(404).end('not found');
    return;
  }
  res.writeHead(200, { 'content-type': types[path.extname(f)] || 'application/octet-stream' });
  fs.createReadStream(f).pipe(res);
});
await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
const port = server.address().port;

const t0 = performance.now();
const browser = await chromium.launch({
  executablePath: opt.chromium,
  headless: true,
  // WebGL without a GPU: SwiftShader (a CPU implementation) through ANGLE.
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
         '--no-sandbox'],
});
let result;
try {
  const page = await browser.newPage({ viewport: { width: w, height: h }, deviceScaleFactor: 1 });
  const logs = [];
  page.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  page.on('pageerror', (e) => logs.push(`pageerror: ${e.message}`));
  const query = new URLSearchParams({ data: '/data', view: opt.view, size: opt.size, up: opt.up,
                                      centre: opt.centre, radius: opt.radius, shade: opt.shade });
  const url = `http://127.0.0.1:${port}/index.html?${query}`;
  await page.goto(url);
  await page.waitForFunction(() => window.copcDone !== undefined, null, { timeout: 120000 });
  const done = await page.evaluate(() => window.copcDone);
  // A shader that does not compile leaves the canvas empty without throwing: fail on it.
  const glErrors = logs.filter((l) => /Shader Error|INVALID_OPERATION|INVALID_VALUE|CONTEXT_LOST/.test(l));
  if (!done.ok || glErrors.length)
    throw new Error(`the page failed: ${done.error || glErrors[0]}\n${logs.join('\n')}`);
  await page.screenshot({ path: opt.out, omitBackground: true, clip: { x: 0, y: 0, width: w, height: h } });
  result = { ...done, screenshot: path.resolve(opt.out), browser: browser.version(),
             browser_seconds: (performance.now() - t0) / 1000,
             console: logs.length ? logs : undefined };
} finally {
  await browser.close();
  server.close();
}
console.log(JSON.stringify(result));
