// Decodes the nodes of a COPC file up to COPC level L (every node whose key level is <= L, as a
// COPC viewer shows levels 0..L) with the `copc` package from the npm registry (copc.js 0.0.8 on
// laz-perf, a reader pbr_lod did not write) into a compact binary that index.html draws.
// Decoding here, in Node, spares the page laz-perf's wasm; the page only draws.
//
//   node decode.mjs FILE.copc.laz [--level L] -o OUTDIR
//
// Writes OUTDIR/points.bin and OUTDIR/points.json (the layout, the COPC cube centre the positions
// are relative to, the spacing) and prints one JSON object. points.bin, for n points:
//   Float32 x,y,z × n   position minus the COPC cube centre (subtracted in double)
//   Float32 d × n       spacing (world units): the distance to the 8th nearest other decoded
//                       point, the k-NN spacing pbrlod sizes an unstructured cloud's splats by
//                       (raster/reference.cpp: radius 0.8 × the distance to the 8th neighbour)
//   Int16 nx,ny,nz × n  normal × 32767 (NormalX/Y/Z extra bytes), when the file has them
//   Uint8 r,g,b × n     colour (the 16-bit LAS colour / 257), for point formats 7 and 8
import { Copc } from 'copc';
import fs from 'node:fs';
import path from 'node:path';

const K = 8;

function usage(msg) {
  if (msg) console.error(`decode.mjs: ${msg}`);
  console.error('usage: node decode.mjs FILE.copc.laz [--level L] -o OUTDIR');
  process.exit(2);
}

const args = process.argv.slice(2);
let file = null, level = null, out = null;
for (let i = 0; i < args.length; ++i) {
  if (args[i] === '--level') level = Number(args[++i]);
  else if (args[i] === '-o') out = args[++i];
  else if (!file) file = args[i];
  else usage(`unexpected argument ${args[i]}`);
}
if (!file || !out) usage();
if (level !== null && !(Number.isInteger(level) && level >= 0)) usage('--level: expected an integer >= 0');

const t0 = performance.now();
const copc = await Copc.create(file);
const { header, info } = copc;

// Every node of every hierarchy page.
const nodes = {};
const pending = [info.rootHierarchyPage];
while (pending.length) {
  const page = await Copc.loadHierarchyPage(file, pending.pop());
  Object.assign(nodes, page.nodes);
  for (const p of Object.values(page.pages)) if (p) pending.push(p);
}
const keyLevel = (key) => Number(key.split('-')[0]);
const copcLevels = 1 + Math.max(...Object.keys(nodes).map(keyLevel));
if (level === null) level = copcLevels - 1;
if (level >= copcLevels) usage(`--level ${level}: the file has COPC levels 0..${copcLevels - 1}`);

const [cx0, cy0, cz0, cx1, cy1, cz1] = info.cube;
const centre = [(cx0 + cx1) / 2, (cy0 + cy1) / 2, (cz0 + cz1) / 2];
const ebNames = copc.eb.map((e) => e.name);
const hasRgb = header.pointDataRecordFormat === 7 || header.pointDataRecordFormat === 8;
const hasNormals = ['NormalX', 'NormalY', 'NormalZ'].every((n) => ebNames.includes(n));

const keys = Object.keys(nodes).filter((k) => keyLevel(k) <= level && nodes[k].pointCount > 0).sort();
const n = keys.reduce((s, k) => s + nodes[k].pointCount, 0);
const pos = new Float32Array(3 * n);
const nrm = hasNormals ? new Int16Array(3 * n) : null;
const rgb = hasRgb ? new Uint8Array(3 * n) : null;
const perHierarchyLevel = {};  // user data: pbr_lod's hierarchy level
let at = 0;
for (const key of keys) {
  const view = await Copc.loadPointDataView(file, copc, nodes[key]);
  const X = view.getter('X'), Y = view.getter('Y'), Z = view.getter('Z'), U = view.getter('UserData');
  const R = hasRgb ? view.getter('Red') : null, G = hasRgb ? view.getter('Green') : null;
  const B = hasRgb ? view.getter('Blue') : null;
  const N = hasNormals ? ['NormalX', 'NormalY', 'NormalZ'].map((c) => view.getter(c)) : null;
  for (let i = 0; i < view.pointCount; ++i, ++at) {
    pos[3 * at] = X(i) - centre[0];
    pos[3 * at + 1] = Y(i) - centre[1];
    pos[3 * at + 2] = Z(i) - centre[2];
    if (hasNormals)
      for (let a = 0; a < 3; ++a) nrm[3 * at + a] = Math.round(32767 * Math.max(-1, Math.min(1, N[a](i))));
    if (hasRgb) {
      rgb[3 * at] = Math.round(R(i) / 257);
      rgb[3 * at + 1] = Math.round(G(i) / 257);
      rgb[3 * at + 2] = Math.round(B(i) / 257);
    }
    const l = U(i);
    perHierarchyLevel[l] = (perHierarchyLevel[l] || 0) + 1;
  }
}
if (at !== n) throw new Error(`decoded ${at} points, the hierarchy says ${n}`);
const tDecode = performance.now();

// Spacing: the distance to the K-th nearest other point, by a uniform grid searched in growing
// shells of cells (exact: a shell is searched until it lies beyond the K-th distance).
const spacing = new Float32Array(n);
if (n > 1) {
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < n; ++i)
    for (let a = 0; a < 3; ++a) {
      lo[a] = Math.min(lo[a], pos[3 * i + a]);
      hi[a] = Math.max(hi[a], pos[3 * i + a]);
    }
  // Cells of about the spacing of points on a surface: area ~ (box diagonal)², K per cell-ish.
  const diag = Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;
  const h = Math.max(diag * Math.sqrt(K / n), diag * 1e-6);
  const dims = [0, 1, 2].map((a) => Math.max(1, Math.min(1024, Math.ceil((hi[a] - lo[a]) / h) + 1)));
  const cellOf = (i, a) => Math.min(dims[a] - 1, Math.floor((pos[3 * i + a] - lo[a]) / h));
  const cell = new Map();  // cell index -> point indices
  for (let i = 0; i < n; ++i) {
    const c = (cellOf(i, 2) * dims[1] + cellOf(i, 1)) * dims[0] + cellOf(i, 0);
    let list = cell.get(c);
    if (!list) cell.set(c, (list = []));
    list.push(i);
  }
  const best = new Float64Array(K);  // squared distances, ascending
  const k = Math.min(K, n - 1);
  const maxShell = Math.max(...dims);
  for (let i = 0; i < n; ++i) {
    best.fill(Infinity);
    const c = [cellOf(i, 0), cellOf(i, 1), cellOf(i, 2)];
    for (let s = 0; s <= maxShell; ++s) {
      for (let z = c[2] - s; z <= c[2] + s; ++z) {
        if (z < 0 || z >= dims[2]) continue;
        for (let y = c[1] - s; y <= c[1] + s; ++y) {
          if (y < 0 || y >= dims[1]) continue;
          const onShellYZ = Math.abs(z - c[2]) === s || Math.abs(y - c[1]) === s;
          for (let x = c[0] - s; x <= c[0] + s; x += onShellYZ || s === 0 ? 1 : 2 * s) {
            if (x < 0 || x >= dims[0]) continue;
            const list = cell.get((z * dims[1] + y) * dims[0] + x);
            if (!list) continue;
            for (const j of list) {
              if (j === i) continue;
              const dx = pos[3 * j] - pos[3 * i], dy = pos[3 * j + 1] - pos[3 * i + 1];
              const dz = pos[3 * j + 2] - pos[3 * i + 2];
              const d2 = dx * dx + dy * dy + dz * dz;
              if (d2 >= best[k - 1]) continue;
              let m = k - 1;
              while (m > 0 && best[m - 1] > d2) {
                best[m] = best[m - 1];
                --m;
              }
              best[m] = d2;
            }
          }
        }
      }
      // Every point not yet seen lies at least s·h away.
      if (best[k - 1] <= (s * h) ** 2) break;
    }
    spacing[i] = Math.sqrt(best[k - 1]);
  }
}
const tSpacing = performance.now();

fs.mkdirSync(out, { recursive: true });
const parts = [['position', pos], ['spacing', spacing]];
if (nrm) parts.push(['normal', nrm]);
if (rgb) parts.push(['rgb', rgb]);
const layout = {};
let offset = 0;
const buffers = [];
for (const [name, arr] of parts) {
  const pad = (4 - (offset % 4)) % 4;
  if (pad) buffers.push(Buffer.alloc(pad));
  offset += pad;
  layout[name] = { offset, type: arr.constructor.name, length: arr.length };
  buffers.push(Buffer.from(arr.buffer, arr.byteOffset, arr.byteLength));
  offset += arr.byteLength;
}
fs.writeFileSync(path.join(out, 'points.bin'), Buffer.concat(buffers));
const sorted = Array.from(spacing).sort((a, b) => a - b);
const meta = {
  file: path.resolve(file),
  points: n,
  copc_level: level,
  copc_levels: copcLevels,
  nodes: keys.length,
  cube_centre: centre,
  cube_halfsize: (cx1 - cx0) / 2,
  spacing: info.spacing,
  spacing_at_level: info.spacing / 2 ** level,
  point_format: header.pointDataRecordFormat,
  has_rgb: hasRgb,
  has_normals: hasNormals,
  points_per_hierarchy_level: perHierarchyLevel,
  knn_spacing_median: n ? sorted[Math.floor(n / 2)] : 0,
  knn_spacing_max: n ? sorted[n - 1] : 0,
  knn: K,
  layout,
  bytes: offset,
};
fs.writeFileSync(path.join(out, 'points.json'), JSON.stringify(meta, null, 1) + '\n');
console.log(JSON.stringify({
  ...meta,
  layout: undefined,
  decode_seconds: (tDecode - t0) / 1000,
  knn_seconds: (tSpacing - tDecode) / 1000,
}));
