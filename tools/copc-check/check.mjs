// Reads a COPC file with the `copc` package from the npm registry (copc.js, on laz-perf) — a
// reader pbr_lod did not write — and prints one JSON object of what it found: the header, the
// info VLR, the extra bytes, the hierarchy and, decoded node by node, every point's position,
// colour, normal and user data (pbr_lod's hierarchy level) summarised. It also checks what a
// COPC reader relies on: each node's points lie in its voxel, and the nodes' counts add up to
// the header's. tools/copc-check/compare.py compares the output with `pbrlod stats`.
//
//   node tools/copc-check/check.mjs FILE.copc.laz
import { Copc } from 'copc';

const file = process.argv[2];
if (!file) {
  console.error('usage: node check.mjs FILE.copc.laz');
  process.exit(2);
}
const copc = await Copc.create(file);
const { header, info } = copc;
const { nodes, pages } = await Copc.loadHierarchyPage(file, info.rootHierarchyPage);
if (Object.keys(pages).length !== 0) throw new Error('child hierarchy pages: not expected here');

const [cx0, cy0, cz0, cx1, cy1, cz1] = info.cube;
const lo = [Infinity, Infinity, Infinity];
const hi = [-Infinity, -Infinity, -Infinity];
const eb = copc.eb.map((e) => e.name);
const hasRgb = header.pointDataRecordFormat === 7 || header.pointDataRecordFormat === 8;
const hasNormals = ['NormalX', 'NormalY', 'NormalZ'].every((n) => eb.includes(n));
let points = 0, dataNodes = 0, emptyNodes = 0, outside = 0, maxLevel = 0, badNormals = 0;
const xyz = [];  // every position, for the bounding sphere about the box centre
const rgbSum = [0, 0, 0];
const perLevel = {};  // hierarchy level (user data) -> points
const keys = Object.keys(nodes).sort();
for (const key of keys) {
  const node = nodes[key];
  if (node.pointCount === 0) {
    ++emptyNodes;
    continue;
  }
  ++dataNodes;
  const [d, x, y, z] = key.split('-').map(Number);
  maxLevel = Math.max(maxLevel, d);
  const view = await Copc.loadPointDataView(file, copc, node);
  if (view.pointCount !== node.pointCount) throw new Error(`node ${key}: ${view.pointCount} points`);
  const get = (name) => view.getter(name);
  const X = get('X'), Y = get('Y'), Z = get('Z'), U = get('UserData');
  const R = hasRgb ? get('Red') : null, G = hasRgb ? get('Green') : null;
  const B = hasRgb ? get('Blue') : null;
  const N = hasNormals ? ['NormalX', 'NormalY', 'NormalZ'].map(get) : null;
  const cell = [(cx1 - cx0) / 2 ** d, (cy1 - cy0) / 2 ** d, (cz1 - cz0) / 2 ** d];
  const v = [x, y, z];
  for (let i = 0; i < view.pointCount; ++i) {
    const p = [X(i), Y(i), Z(i)];
    xyz.push(p);
    for (let a = 0; a < 3; ++a) {
      lo[a] = Math.min(lo[a], p[a]);
      hi[a] = Math.max(hi[a], p[a]);
      const c0 = [cx0, cy0, cz0][a] + v[a] * cell[a];
      const slack = 1e-9 * cell[a] + header.scale[a];
      if (p[a] < c0 - slack || p[a] > c0 + cell[a] + slack) ++outside;
    }
    const level = U(i);
    perLevel[level] = (perLevel[level] || 0) + 1;
    if (hasRgb) {
      rgbSum[0] += R(i);
      rgbSum[1] += G(i);
      rgbSum[2] += B(i);
    }
    if (hasNormals) {
      const len = Math.hypot(N[0](i), N[1](i), N[2](i));
      if (!(len === 0 || Math.abs(len - 1) < 1e-3)) ++badNormals;
    }
  }
  points += view.pointCount;
}
const centre = [0, 1, 2].map((a) => 0.5 * (lo[a] + hi[a]));
const distinct = new Set(xyz.map((p) => p.join(','))).size;
let radius = 0;
for (const p of xyz) radius = Math.max(radius, Math.hypot(p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]));
console.log(JSON.stringify({
  file,
  header_points: header.pointCount,
  point_format: header.pointDataRecordFormat,
  record_length: header.pointDataRecordLength,
  scale: header.scale,
  cube: info.cube,
  spacing: info.spacing,
  extra_bytes: eb,
  wkt: copc.wkt !== undefined && copc.wkt.length > 0,
  nodes: dataNodes,
  empty_nodes: emptyNodes,
  levels: maxLevel + 1,
  points,
  distinct_positions: distinct,
  points_outside_their_voxel: outside,
  normals_not_unit: badNormals,
  points_per_hierarchy_level: perLevel,
  mean_rgb16: hasRgb ? rgbSum.map((s) => s / Math.max(1, points)) : null,
  bounds: { min: lo, max: hi },
  bounding_sphere: {
    x: centre[0], y: centre[1], z: centre[2],
    radius,
  },
}));
