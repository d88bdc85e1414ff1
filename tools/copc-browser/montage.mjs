// Puts two renders of the same view side by side, over white, with a third panel of their
// silhouettes (alpha > 0): grey where both cover a pixel, red where only the first does, blue where
// only the second does. Drawn in headless Chromium (a canvas), so it needs nothing beyond
// shoot.mjs's dependencies.
//
// Prints one JSON object: each silhouette's pixels, bounding box and centroid.
//
//   node montage.mjs A.png B.png [--labels "A label" "B label"] [--chromium PATH] -o OUT.png
import fs from 'node:fs';
import { chromium } from 'playwright-core';

const argv = process.argv.slice(2);
const files = [];
let out = null, labels = null, exe = '/usr/bin/chromium';
for (let i = 0; i < argv.length; ++i) {
  if (argv[i] === '-o') out = argv[++i];
  else if (argv[i] === '--labels') labels = [argv[++i], argv[++i]];
  else if (argv[i] === '--chromium') exe = argv[++i];
  else files.push(argv[i]);
}
if (files.length !== 2 || !out) {
  console.error('usage: node montage.mjs A.png B.png [--labels A B] [--chromium PATH] -o OUT.png');
  process.exit(2);
}
labels = labels || files;
const urls = files.map((f) => `data:image/png;base64,${fs.readFileSync(f).toString('base64')}`);

const browser = await chromium.launch({ executablePath: exe, headless: true, args: ['--no-sandbox'] });
try {
  const page = await browser.newPage({ deviceScaleFactor: 1 });
  await page.setContent('<html><body style="margin:0;background:#fff"></body></html>');
  const size = await page.evaluate(async ({ urls, labels }) => {
    const imgs = await Promise.all(urls.map((u) => new Promise((ok, err) => {
      const im = new Image();
      im.onload = () => ok(im);
      im.onerror = err;
      im.src = u;
    })));
    const [w, h] = [imgs[0].width, imgs[0].height];
    const pad = 8, top = 24;
    const c = document.createElement('canvas');
    c.width = 3 * w + 4 * pad;
    c.height = h + top + pad;
    document.body.appendChild(c);
    const g = c.getContext('2d');
    g.fillStyle = '#fff';
    g.fillRect(0, 0, c.width, c.height);
    g.font = '14px sans-serif';
    g.fillStyle = '#000';
    const alpha = imgs.map((im) => {
      const t = document.createElement('canvas');
      t.width = w;
      t.height = h;
      const tg = t.getContext('2d');
      tg.drawImage(im, 0, 0);
      return tg.getImageData(0, 0, w, h).data;
    });
    imgs.forEach((im, i) => {
      g.fillText(labels[i], pad + i * (w + pad), 17);
      g.drawImage(im, pad + i * (w + pad), top);
      g.strokeStyle = '#ccc';
      g.strokeRect(pad + i * (w + pad) - 0.5, top - 0.5, w + 1, h + 1);
    });
    const diff = g.createImageData(w, h);
    for (let p = 0; p < w * h; ++p) {
      const a = alpha[0][4 * p + 3] > 0, b = alpha[1][4 * p + 3] > 0;
      const rgb = a && b ? [170, 170, 170] : a ? [230, 0, 0] : b ? [0, 60, 255] : [255, 255, 255];
      diff.data.set([...rgb, 255], 4 * p);
    }
    g.putImageData(diff, pad + 2 * (w + pad), top);
    g.fillText('both / only first (red) / only second (blue)', pad + 2 * (w + pad), 17);
    // Each silhouette's bounding box and centroid (pixels): a framing error shows as an offset.
    const masks = alpha.map((d) => {
      let n = 0, sx = 0, sy = 0, x0 = w, y0 = h, x1 = -1, y1 = -1;
      for (let y = 0; y < h; ++y)
        for (let x = 0; x < w; ++x)
          if (d[4 * (y * w + x) + 3] > 0) {
            ++n; sx += x; sy += y;
            x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y);
          }
      return { pixels: n, centroid: n ? [sx / n, sy / n] : null, box: [x0, y0, x1, y1] };
    });
    return { size: [c.width, c.height], masks };
  }, { urls, labels });
  const [cw, ch] = size.size;
  await page.setViewportSize({ width: cw, height: ch });
  await page.screenshot({ path: out, clip: { x: 0, y: 0, width: cw, height: ch } });
  const [a, b] = size.masks;
  console.log(JSON.stringify({
    output: out, first: a, second: b,
    centroid_offset_px: a.centroid && b.centroid ? [b.centroid[0] - a.centroid[0], b.centroid[1] - a.centroid[1]] : null,
  }));
} finally {
  await browser.close();
}
