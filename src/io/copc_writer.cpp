// pbr_lod — COPC out (include/pbr_lod/io/copc.hpp; COPC 1.0, copc.io, and the LAS 1.4 R15
// specification for the header, the VLRs and the Extra Bytes descriptors).
//
// File layout written here:
//   LAS 1.4 header (375 bytes, point format 6 or 7 with bit 7 set: LAZ)
//   VLR copc/1: the info record (first, at offset 375, as COPC requires)
//   VLR laszip encoded/22204: layered compressor, variable chunks (laz_writer.cpp)
//   VLR LASF_Spec/4: Extra Bytes descriptors (with normals)
//   VLR LASF_Projection/2112: OGC WKT (when given)
//   point data: the chunk table's offset (8 bytes), one LAZ chunk per octree node
//   the LAZ chunk table (each chunk's count and bytes)
//   EVLR copc/1000: the hierarchy, one page of 32-byte entries
#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <numeric>
#include <unordered_set>

#include "io_internal.hpp"
#include "laz_codec.hpp"
#include "laz_encoder.hpp"
#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/io/copc.hpp"
#include "point_formats.hpp"

namespace pbr_lod {
namespace {

using detail::cat;

using detail::laz::append_le;
template <class T>
void poke(unsigned char* p, T v) {
  detail::laz::store_le(p, v);
}
void put_text(std::string& s, std::string_view text, std::size_t width) {
  std::string field(width, '\0');
  std::copy_n(text.begin(), std::min(text.size(), width), field.begin());
  s += field;
}

/// A VLR (54-byte header) or, with `extended`, an EVLR (60-byte header), with its payload.
std::string vlr(std::string_view user, std::uint16_t record, std::string_view description,
                const std::string& payload, bool extended = false) {
  std::string v;
  append_le<std::uint16_t>(v, 0);  // reserved
  put_text(v, user, 16);
  append_le<std::uint16_t>(v, record);
  if (extended)
    append_le<std::uint64_t>(v, payload.size());
  else
    append_le<std::uint16_t>(v, static_cast<std::uint16_t>(payload.size()));
  put_text(v, description, 32);
  return v + payload;
}

/// One octree voxel: level and integer coordinates (COPC's VoxelKey), ordered level first.
struct voxel {
  std::int32_t level = 0, x = 0, y = 0, z = 0;
  friend auto operator<=>(const voxel&, const voxel&) = default;
  [[nodiscard]] voxel parent() const { return {level - 1, x >> 1, y >> 1, z >> 1}; }
  [[nodiscard]] std::uint64_t hash() const {
    return (std::uint64_t(std::uint32_t(level)) << 58) ^ (std::uint64_t(std::uint32_t(x)) << 38) ^
           (std::uint64_t(std::uint32_t(y)) << 19) ^ std::uint64_t(std::uint32_t(z));
  }
};
struct voxel_hash {
  std::size_t operator()(const voxel& v) const { return std::hash<std::uint64_t>{}(v.hash()); }
};

constexpr int max_copc_level = 30;  // 2^30 voxels a side: int32 keys, and far below any scale

/// The cube, the quantisation and each point's quantised position.
struct layout {
  vec3d lo = vec3d::Zero();  ///< the cube's low corner
  double size = 1;           ///< its edge
  double scale = 1e-3;
  vec3d offset = vec3d::Zero();
  std::vector<std::array<std::int32_t, 3>> xyz;
  std::array<std::int32_t, 3> xyz_lo{}, xyz_hi{};  ///< the quantised bounds (the header's)

  [[nodiscard]] vec3d world(std::size_t i) const {
    return {xyz[i][0] * scale + offset.x(), xyz[i][1] * scale + offset.y(),
            xyz[i][2] * scale + offset.z()};
  }
  [[nodiscard]] voxel voxel_of(std::size_t i, int level) const {
    const double cells = std::ldexp(1.0, level);
    const vec3d p = world(i);
    voxel v{level, 0, 0, 0};
    std::int32_t* c[3] = {&v.x, &v.y, &v.z};
    for (int a = 0; a < 3; ++a) {
      const double t = std::floor((p[a] - lo[a]) / size * cells);
      *c[a] = static_cast<std::int32_t>(std::clamp(t, 0.0, cells - 1));
    }
    return v;
  }
};

/// A power of ten for X, Y, Z that keeps the cube within 2^30 steps of its centre's offset.
layout make_layout(const point_cloud& c) {
  layout L;
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const vec3d p = c.world(i);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  if (c.size() == 0) lo = hi = c.origin;
  const vec3d centre = 0.5 * (lo + hi);
  const double extent = (hi - lo).maxCoeff();
  // A tiny margin so that the highest points fall inside the last voxel after quantisation.
  const double half = std::max(0.5 * extent * (1 + 1e-6), std::max(1e-9, 1e-12 * centre.norm()));
  L.scale = std::pow(10.0, std::ceil(std::log10(2 * half / double(1 << 30))));
  for (int a = 0; a < 3; ++a) L.offset[a] = std::round(centre[a] / L.scale) * L.scale;
  L.lo = centre - vec3d::Constant(half);
  L.size = 2 * half;
  L.xyz.resize(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const vec3d p = c.world(i);
    for (std::size_t a = 0; a < 3; ++a) {
      const auto q = static_cast<std::int32_t>(std::llround((p[a] - L.offset[a]) / L.scale));
      L.xyz[i][a] = q;
      L.xyz_lo[a] = i == 0 ? q : std::min(L.xyz_lo[a], q);
      L.xyz_hi[a] = i == 0 ? q : std::max(L.xyz_hi[a], q);
    }
  }
  return L;
}

/// Each point's voxel when hierarchy level l is stored at COPC level max(0, l − shift), into key
/// (one buffer for every shift tried).
void voxels_at(const layout& L, std::span<const std::uint8_t> levels, int shift, unsigned threads,
               std::vector<voxel>& key) {
  key.resize(levels.size());
  detail::parallel_chunks(
      key.size(), resolve_threads(threads), 1 << 16, [&](std::size_t lo, std::size_t hi) {
        for (std::size_t i = lo; i < hi; ++i)
          key[i] = L.voxel_of(i, std::min(max_copc_level, std::max(0, levels[i] - shift)));
      });
}

/// The smallest shift that gives at least `target` points per non-empty node on average (the
/// deepest level when none does), and the points' voxels at that shift.
std::pair<int, std::vector<voxel>> choose_shift(const layout& L,
                                                std::span<const std::uint8_t> levels,
                                                std::uint32_t target, unsigned threads) {
  const int deepest = levels.empty() ? 0 : *std::max_element(levels.begin(), levels.end());
  std::vector<voxel> key;
  for (int shift = 0;; ++shift) {
    voxels_at(L, levels, shift, threads, key);
    if (shift == deepest) return {shift, std::move(key)};
    const std::unordered_set<voxel, voxel_hash> nodes(key.begin(), key.end());
    if (levels.size() >= std::uint64_t{target} * nodes.size()) return {shift, std::move(key)};
  }
}

/// The LAS 1.4 record of point i: format 6 (30 bytes) or 7 (+ RGB), then the normal's floats.
void write_record(const point_cloud& c, const layout& L, std::uint8_t level, std::size_t i,
                  unsigned char* r, std::size_t record_length) {
  std::memset(r, 0, record_length);
  for (int a = 0; a < 3; ++a) poke<std::int32_t>(r + 4 * a, L.xyz[i][static_cast<std::size_t>(a)]);
  r[14] = 0x11;   // return 1 of 1
  r[17] = level;  // user data: the hierarchy level
  std::size_t at = 30;
  if (!c.colours.empty()) {
    const rgb8 k = c.colours[i];
    poke<std::uint16_t>(r + 30, static_cast<std::uint16_t>(k.r * 257));
    poke<std::uint16_t>(r + 32, static_cast<std::uint16_t>(k.g * 257));
    poke<std::uint16_t>(r + 34, static_cast<std::uint16_t>(k.b * 257));
    at = 36;
  }
  if (!c.normals.empty()) {  // a zero or non-finite normal is "no normal": written as zero
    const vec3f n = all_finite(c.normals[i]) ? c.normals[i] : vec3f::Zero();
    for (int a = 0; a < 3; ++a) poke<float>(r + at + 4 * a, n[a]);
  }
}

/// The Extra Bytes VLR's payload: one 192-byte descriptor (LAS 1.4 R15, Table 24) per float of
/// the normal: type 9 (float), no options, the name; zeros through byte 160, the description.
std::string normal_descriptors() {
  std::string s;
  for (const char axis : {'X', 'Y', 'Z'}) {
    std::string d;
    append_le<std::uint16_t>(d, 0);  // reserved
    d += '\x09';                     // data type 9: float
    d += '\0';                       // options: no no_data, min, max, scale or offset
    put_text(d, std::string("Normal") + axis, 32);
    d.resize(160, '\0');
    put_text(d, std::string("unit normal, ") + axis, 32);
    s += d;
  }
  return s;
}

/// The octree's nodes: the points of each, and the keys of every node in key order (those
/// without points lead to nodes with points: every ancestor of a node is listed).
struct octree {
  std::vector<voxel> keys;                ///< every entry, sorted
  std::vector<std::size_t> first, count;  ///< per entry: its run in `order` (count 0: empty)
  std::vector<std::size_t> order;         ///< point indices, node by node
};

/// The octree of the points whose voxels are `key`.
octree make_octree(const std::vector<voxel>& key) {
  const std::size_t n = key.size();
  octree t;
  t.order.resize(n);
  std::iota(t.order.begin(), t.order.end(), std::size_t{0});
  std::stable_sort(t.order.begin(), t.order.end(),
                   [&](std::size_t a, std::size_t b) { return key[a] < key[b]; });
  std::map<voxel, std::pair<std::size_t, std::size_t>> nodes;  // key → (first, count)
  for (std::size_t k = 0; k < n;) {
    std::size_t e = k + 1;
    while (e < n && key[t.order[e]] == key[t.order[k]]) ++e;
    nodes.emplace(key[t.order[k]], std::pair{k, e - k});
    k = e;
  }
  // Every ancestor of a node with points. In key order (level first) a parent met on the way up
  // already has its own ancestors, so the walk stops there.
  std::vector<voxel> data;
  for (const auto& [k, run] : nodes) data.push_back(k);
  for (voxel v : data)
    while (v.level > 0) {
      v = v.parent();
      if (!nodes.emplace(v, std::pair<std::size_t, std::size_t>{0, 0}).second) break;
    }
  for (const auto& [k, run] : nodes) {
    t.keys.push_back(k);
    t.first.push_back(run.first);
    t.count.push_back(run.second);
  }
  return t;
}

/// The 375-byte LAS 1.4 header.
std::string las14_header(const point_cloud& c, const layout& L, unsigned format,
                         std::uint16_t record_length, std::uint32_t data_offset, std::uint32_t vlrs,
                         std::uint64_t evlr_at) {
  std::string h(375, '\0');
  auto* b = reinterpret_cast<unsigned char*>(h.data());
  std::memcpy(b, "LASF", 4);
  poke<std::uint16_t>(b + 6, 16);  // global encoding: WKT (required with formats 6–10)
  b[24] = 1;
  b[25] = 4;
  std::memcpy(b + 26, "pbr_lod", 7);
  std::memcpy(b + 58, "pbr_lod COPC writer", 19);
  poke<std::uint16_t>(b + 94, 375);
  poke<std::uint32_t>(b + 96, data_offset);
  poke<std::uint32_t>(b + 100, vlrs);
  b[104] = static_cast<unsigned char>(format | 0x80);  // LAZ
  poke<std::uint16_t>(b + 105, record_length);
  for (int a = 0; a < 3; ++a) {
    const auto bound = [&](std::int32_t q) {
      return c.size() == 0 ? 0.0 : q * L.scale + L.offset[a];
    };
    poke<double>(b + 131 + 8 * a, L.scale);
    poke<double>(b + 155 + 8 * a, L.offset[a]);
    poke<double>(b + 179 + 16 * a, bound(L.xyz_hi[static_cast<std::size_t>(a)]));
    poke<double>(b + 187 + 16 * a, bound(L.xyz_lo[static_cast<std::size_t>(a)]));
  }
  poke<std::uint64_t>(b + 235, evlr_at);
  poke<std::uint32_t>(b + 243, 1);
  poke<std::uint64_t>(b + 247, c.size());
  poke<std::uint64_t>(b + 255, c.size());  // all first (and only) returns
  return h;
}

}  // namespace

copc_summary write_copc(const std::string& path, const point_cloud& c,
                        std::span<const std::uint8_t> levels, const copc_options& o) {
  c.validate();
  if (levels.size() != c.size())
    throw InvalidArgument(cat("write_copc: ", levels.size(), " levels for ", c.size(), " points"));
  if (o.node_points == 0) throw InvalidArgument("write_copc: node_points must be positive");
  if (o.wkt.size() + 1 > 0xFFFF) throw InvalidArgument("write_copc: WKT longer than 65534 bytes");
  const layout L = make_layout(c);
  copc_summary s;
  s.points = c.size();
  auto [shift, keys] = choose_shift(L, levels, o.node_points, o.threads);
  s.shift = shift;
  const octree t = make_octree(keys);
  keys = {};

  const unsigned format = c.colours.empty() ? 6 : 7;
  const std::size_t extra = c.normals.empty() ? 0 : 12;
  const auto record_length = static_cast<std::uint16_t>((format == 7 ? 36 : 30) + extra);
  std::vector<std::vector<unsigned char>> chunks(t.keys.size());
  detail::parallel_tasks(chunks.size(), resolve_threads(o.threads), [&](std::size_t k, unsigned) {
    if (t.count[k] == 0) return;
    std::vector<unsigned char> records(t.count[k] * record_length);
    for (std::size_t j = 0; j < t.count[k]; ++j) {
      const std::size_t i = t.order[t.first[k] + j];
      write_record(c, L, levels[i], i, records.data() + j * record_length, record_length);
    }
    chunks[k] = detail::encode_layered_chunk(format, record_length, records.data(), t.count[k]);
  });

  // The VLRs; the info VLR's hierarchy offset is filled in once the chunks' sizes are known.
  std::string info;
  const vec3d centre = L.lo + vec3d::Constant(0.5 * L.size);
  for (int a = 0; a < 3; ++a) append_le<double>(info, centre[a]);
  append_le<double>(info, 0.5 * L.size);
  std::size_t root_points = 0;
  for (std::size_t k = 0; k < t.keys.size() && t.keys[k].level == 0; ++k) root_points += t.count[k];
  s.spacing = L.size / std::sqrt(double(std::max<std::size_t>(1, root_points)));
  append_le<double>(info, s.spacing);
  const std::size_t hier_at_in_info = info.size();
  append_le<std::uint64_t>(info, 0);  // root_hier_offset
  append_le<std::uint64_t>(info, 0);  // root_hier_size
  append_le<double>(info, 0);         // gpstime min and max: the records hold none
  append_le<double>(info, 0);
  info.append(11 * 8, '\0');
  std::string vlrs = vlr("copc", 1, "COPC info", info);
  vlrs += detail::laszip_vlr(format, extra, 0xFFFFFFFFu);
  std::uint32_t vlr_count = 2;
  if (extra) {
    vlrs += vlr("LASF_Spec", 4, "Extra Bytes: the normal", normal_descriptors());
    ++vlr_count;
  }
  if (!o.wkt.empty()) {
    vlrs += vlr("LASF_Projection", 2112, "OGC WKT", o.wkt + '\0');
    ++vlr_count;
  }
  const std::uint64_t data_offset = 375 + vlrs.size();

  // Chunk offsets, the chunk table, the hierarchy page.
  std::vector<std::uint64_t> bytes, counts;
  std::uint64_t at = data_offset + 8;
  std::string page;
  for (std::size_t k = 0; k < t.keys.size(); ++k) {
    const voxel& v = t.keys[k];
    for (const std::int32_t x : {v.level, v.x, v.y, v.z}) append_le<std::int32_t>(page, x);
    if (t.count[k] == 0) {
      append_le<std::uint64_t>(page, 0);
      append_le<std::int32_t>(page, 0);
      append_le<std::int32_t>(page, 0);
      ++s.empty_nodes;
      continue;
    }
    if (t.count[k] > 0x7FFFFFFFu || chunks[k].size() > 0x7FFFFFFFu)
      throw InvalidArgument(cat("write_copc: node ", v.level, "-", v.x, "-", v.y, "-", v.z,
                                " holds ", t.count[k], " points (COPC allows 2^31 - 1)"));
    append_le<std::uint64_t>(page, at);
    append_le<std::int32_t>(page, static_cast<std::int32_t>(chunks[k].size()));
    append_le<std::int32_t>(page, static_cast<std::int32_t>(t.count[k]));
    at += chunks[k].size();
    bytes.push_back(chunks[k].size());
    counts.push_back(t.count[k]);
    ++s.nodes;
    s.max_level = std::max(s.max_level, int(v.level));
  }
  const std::uint64_t table_at = at;
  std::string table;
  detail::append_chunk_table(table, bytes, &counts);
  const std::uint64_t evlr_at = table_at + table.size();
  const std::uint64_t page_at = evlr_at + 60;
  poke<std::uint64_t>(reinterpret_cast<unsigned char*>(vlrs.data()) + 54 + hier_at_in_info,
                      page_at);
  poke<std::uint64_t>(reinterpret_cast<unsigned char*>(vlrs.data()) + 54 + hier_at_in_info + 8,
                      std::uint64_t{page.size()});
  if (data_offset > 0xFFFFFFFFu) throw InvalidArgument("write_copc: VLRs exceed 4 GiB");
  const std::string header = las14_header(
      c, L, format, record_length, static_cast<std::uint32_t>(data_offset), vlr_count, evlr_at);

  atomic_output file(path);
  std::ofstream out(file.temp_path(), std::ios::binary | std::ios::trunc);
  if (!out) throw IoError(path + ": cannot open for writing: " + std::strerror(errno));
  const auto write = [&](const void* p, std::size_t n) {
    out.write(static_cast<const char*>(p), static_cast<std::streamsize>(n));
  };
  write(header.data(), header.size());
  write(vlrs.data(), vlrs.size());
  std::string table_offset;
  append_le<std::int64_t>(table_offset, static_cast<std::int64_t>(table_at));
  write(table_offset.data(), table_offset.size());
  for (const auto& ch : chunks) write(ch.data(), ch.size());
  write(table.data(), table.size());
  const std::string hierarchy = vlr("copc", 1000, "COPC hierarchy", page, true);
  write(hierarchy.data(), hierarchy.size());
  out.flush();
  if (!out) throw IoError(path + ": write failed: " + std::strerror(errno));
  out.close();
  file.commit();

  s.centre = centre;
  s.halfsize = 0.5 * L.size;
  s.scale = L.scale;
  s.bytes = page_at + page.size();
  return s;
}

std::string las_wkt(const std::string& path) {
  const detail::posix_file f(path);
  std::vector<unsigned char> head(static_cast<std::size_t>(std::min<std::uint64_t>(f.size(), 375)));
  f.read_exact(0, head.size(), head.data());
  read_report report;
  const detail::las_header h = detail::parse_las_header(path, head.data(), f.size(), report);
  // One walk for the VLRs (54-byte headers, 16-bit lengths) between the header and the points
  // and for a LAS 1.4 file's EVLRs after them (60-byte headers, 64-bit lengths).
  std::string wkt;
  const auto find = [&](const char* what, std::uint64_t at, std::uint32_t count, bool extended) {
    const std::size_t head_bytes = extended ? 60 : 54;
    for (std::uint32_t i = 0; i < count && at != 0; ++i) {
      unsigned char v[60];
      if (at > f.size() || f.size() - at < head_bytes)
        detail::format_error(path, cat(what, " ", i), "runs past the file's end");
      f.read_exact(at, head_bytes, v);
      const std::uint16_t record = detail::load_le<std::uint16_t>(v + 18);
      const std::uint64_t length = extended ? detail::load_le<std::uint64_t>(v + 20)
                                            : detail::load_le<std::uint16_t>(v + 20);
      if (length > f.size() - at - head_bytes)
        detail::format_error(path, cat(what, " ", i), "runs past the file's end");
      if (std::memcmp(v + 2, "LASF_Projection", 15) == 0 && record == 2112) {
        wkt.assign(static_cast<std::size_t>(length), '\0');
        f.read_exact(at + head_bytes, wkt.size(), wkt.data());
        wkt.resize(std::min(wkt.find('\0'), wkt.size()));
        return true;
      }
      at += head_bytes + length;
    }
    return false;
  };
  if (find("VLR", h.header_size, h.vlr_count, false)) return wkt;
  if (head.size() >= 247 && head[25] >= 4 &&
      find("EVLR", detail::load_le<std::uint64_t>(head.data() + 235),
           detail::load_le<std::uint32_t>(head.data() + 243), true))
    return wkt;
  return {};
}

}  // namespace pbr_lod
