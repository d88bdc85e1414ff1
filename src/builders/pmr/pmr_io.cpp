// pbr_lod — PMR (Dey & Hudson, IEEE Vis 2002) §2 Records and §3 (the file is mapped with
// mmap): the versioned file "PBRLODPM" v1.
//
// Layout (little-endian): magic "PBRLODPM", u32 version, u32 flags (bit 0: colours, bit 1: a
// chunk of a chunked build); f64×3 origin,
// input min, input max; u32 max_leaf_points, f32 neighbour_margin; u32 thresholds, f32 each; u64 ×
// 6 build counts (input points, duplicates, triangulated, removals, flat leaves, hull points); u32
// counts of samples, nodes, leaves, triangles, umbrellas, umbrella indices; with flag bit 1, u32
// foreign samples and u64 input size (pmr_data); then the arrays in
// that order of pmr_data (positions, normals, source, colours as RGB bytes when flag bit 0 is
// set, nodes, leaves, levels, triangles, umbrellas, umbrella indices); u64 FNV-1a of everything
// before. A file without colours is the same bytes as before colours existed. No timings: the same
// input and options give the same bytes.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pmr_internal.hpp"

namespace pbr_lod::detail {

bool operator==(const pmr_data& a, const pmr_data& b) {
  return a.origin == b.origin && a.input_min == b.input_min && a.input_max == b.input_max &&
         a.max_leaf_points == b.max_leaf_points && a.neighbour_margin == b.neighbour_margin &&
         a.rho == b.rho && a.positions == b.positions && a.normals == b.normals &&
         a.colours == b.colours && a.source == b.source && a.nodes == b.nodes &&
         a.leaf_list == b.leaf_list && a.levels == b.levels && a.triangles == b.triangles &&
         a.umbrellas == b.umbrellas && a.umbrella_index == b.umbrella_index &&
         a.foreign == b.foreign && a.input_total == b.input_total &&
         a.stats.input_points == b.stats.input_points && a.stats.duplicates == b.stats.duplicates &&
         a.stats.triangulated_points == b.stats.triangulated_points &&
         a.stats.removals == b.stats.removals && a.stats.flat_leaves == b.stats.flat_leaves &&
         a.stats.hull_points == b.stats.hull_points;
}

std::array<std::size_t, 6> stat_counts(const pmr_build_stats& s) {
  return {s.input_points, s.duplicates,  s.triangulated_points,
          s.removals,     s.flat_leaves, s.hull_points};
}
std::array<std::size_t*, 6> stat_fields(pmr_build_stats& s) {
  return {&s.input_points, &s.duplicates,  &s.triangulated_points,
          &s.removals,     &s.flat_leaves, &s.hull_points};
}

void put_node(byte_writer& w, const pmr_node& n) {
  w.put_vec(n.cell_min);
  w.put(n.cell_size);
  w.put_vec(n.centre);
  w.put(n.radius);
  w.put(n.first);
  w.put(n.count);
  w.put(n.leaf);
  w.put(n.depth);
}

pmr_node get_node(byte_reader& r, std::size_t k) {
  pmr_node n;
  n.cell_min = r.get_vec("node cell", k);
  n.cell_size = r.get_non_negative("node cell size", k);
  n.centre = r.get_vec("node centre", k);
  n.radius = r.get_non_negative("node radius", k);
  n.first = r.get<std::uint32_t>("node first");
  n.count = r.get<std::uint32_t>("node count");
  n.leaf = r.get<std::uint32_t>("node leaf flag");
  n.depth = r.get<std::uint32_t>("node depth");
  if (n.leaf > 1) r.fail("node " + std::to_string(k) + ": leaf flag is not 0 or 1");
  return n;
}

namespace {

constexpr file_format pmr_format{"PMR", {'P', 'B', 'R', 'L', 'O', 'D', 'P', 'M'}, 1};
constexpr std::uint32_t flag_colours = 1, flag_part = 2;
constexpr std::size_t node_bytes = 4 * 8 + 4 * 4, leaf_bytes = 12, level_bytes = 20, tri_bytes = 12,
                      umbrella_bytes = 12;

std::vector<unsigned char> encode(const pmr_data& d) {
  byte_writer w;
  write_head(w, pmr_format);
  const bool part = d.input_total != 0;
  w.put((d.colours.empty() ? std::uint32_t{0} : flag_colours) | (part ? flag_part : 0));
  for (const vec3d* v : {&d.origin, &d.input_min, &d.input_max})
    for (int k = 0; k < 3; ++k) w.put((*v)[k]);
  w.put(d.max_leaf_points);
  w.put(d.neighbour_margin);
  w.put(static_cast<std::uint32_t>(d.rho.size()));
  for (const float r : d.rho) w.put(r);
  for (const std::size_t s : stat_counts(d.stats)) w.put(static_cast<std::uint64_t>(s));
  for (const std::size_t s : {d.positions.size(), d.nodes.size(), d.leaf_list.size(),
                              d.triangles.size(), d.umbrellas.size(), d.umbrella_index.size()})
    w.put(static_cast<std::uint32_t>(s));
  if (part) {
    w.put(d.foreign);
    w.put(d.input_total);
  }
  for (const auto& p : d.positions) w.put_vec(p);
  for (const auto& n : d.normals) w.put_vec(n);
  for (const auto s : d.source) w.put(s);
  for (const rgb8& c : d.colours) {
    w.put(c.r);
    w.put(c.g);
    w.put(c.b);
  }
  for (const auto& n : d.nodes) put_node(w, n);
  for (const auto& l : d.leaf_list) {
    w.put(l.first_point);
    w.put(l.point_count);
    w.put(l.node);
  }
  for (const auto& l : d.levels) {
    w.put(l.points);
    w.put(l.mean_umbrella);
    w.put(l.first_tri);
    w.put(l.tris);
    w.put(l.first_entry);
  }
  for (const auto& t : d.triangles)
    for (const auto i : t) w.put(i);
  for (const auto& u : d.umbrellas) {
    w.put(u.first);
    w.put(u.count);
    w.put(u.radius);
  }
  for (const auto i : d.umbrella_index) w.put(i);
  append_checksum(w);
  return std::move(w.bytes);
}

/// A read-only private mapping of a whole file, unmapped on destruction.
class mapping {
 public:
  explicit mapping(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw IoError(path + ": cannot open: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) != 0) {
      ::close(fd);
      throw IoError(path + ": cannot stat");
    }
    size_ = static_cast<std::size_t>(st.st_size);
    if (size_ > 0) {
      void* m = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
      if (m == MAP_FAILED) {
        ::close(fd);
        throw IoError(path + ": cannot map: " + std::strerror(errno));
      }
      data_ = static_cast<const unsigned char*>(m);
    }
    ::close(fd);
  }
  ~mapping() {
    if (data_) ::munmap(const_cast<unsigned char*>(data_), size_);
  }
  mapping(const mapping&) = delete;
  mapping& operator=(const mapping&) = delete;
  [[nodiscard]] const unsigned char* data() const { return data_; }
  [[nodiscard]] std::size_t size() const { return size_; }

 private:
  const unsigned char* data_ = nullptr;
  std::size_t size_ = 0;
};

/// A whole hierarchy's sources are a permutation of its samples; a part's are distinct input
/// indices.
void check_sources(const byte_reader& r, const pmr_data& d) {
  const std::size_t n = d.source.size();
  if (d.input_total == 0) {
    std::vector<unsigned char> seen(n, 0);
    for (std::size_t i = 0; i < n; ++i)
      if (d.source[i] >= n || seen[d.source[i]]++)
        r.fail("source index of sample " + std::to_string(i) + " out of range or repeated");
    return;
  }
  std::vector<std::uint32_t> s = d.source;
  std::sort(s.begin(), s.end());
  if (s.back() >= d.input_total || std::adjacent_find(s.begin(), s.end()) != s.end())
    r.fail("source indices out of range or repeated");
}

/// The counts the header declares, which size and bound every table after it.
struct pmr_counts {
  std::uint32_t flags, levels, samples, nodes, leaves, triangles, umbrellas, umbrella_indices, own;
};

/// Flags, origin and bounds, options, thresholds, build counts and the table sizes.
pmr_counts decode_header(byte_reader& r, pmr_data& d) {
  const auto flags = r.get<std::uint32_t>("flags");
  if ((flags & ~(flag_colours | flag_part)) != 0) r.fail("unknown flags");
  for (vec3d* v : {&d.origin, &d.input_min, &d.input_max})
    for (int k = 0; k < 3; ++k) {
      (*v)[k] = r.get<double>("origin/bounds");
      if (!std::isfinite((*v)[k])) r.fail("origin or input bounds not finite");
    }
  d.max_leaf_points = r.get<std::uint32_t>("max_leaf_points");
  d.neighbour_margin = r.get_non_negative("neighbour_margin", 0);
  const auto nrho = r.get<std::uint32_t>("threshold count");
  if (nrho > 31) r.fail("threshold count " + std::to_string(nrho) + " exceeds 31");
  for (std::uint32_t i = 0; i < nrho; ++i) {
    d.rho.push_back(r.get_finite("rho", i));
    if (!(d.rho[i] > 0) || (i > 0 && !(d.rho[i] > d.rho[i - 1])))
      r.fail("rho[" + std::to_string(i) + "] is not positive and increasing");
  }
  const std::uint32_t levels = nrho + 1;
  for (std::size_t* c : stat_fields(d.stats))
    *c = static_cast<std::size_t>(r.get<std::uint64_t>("build counts"));
  const auto npts = r.get<std::uint32_t>("sample count");
  const auto nnodes = r.get<std::uint32_t>("node count");
  const auto nleaves = r.get<std::uint32_t>("leaf count");
  const auto ntris = r.get<std::uint32_t>("triangle count");
  const auto numb = r.get<std::uint32_t>("umbrella count");
  const auto nidx = r.get<std::uint32_t>("umbrella index count");
  if (flags & flag_part) {
    d.foreign = r.get<std::uint32_t>("foreign vertex count");
    d.input_total = r.get<std::uint64_t>("input size");
    if (d.foreign >= npts || d.input_total == 0)
      r.fail("foreign vertex count or input size out of range");
  }
  const std::uint32_t own = npts - d.foreign;
  if (d.stats.input_points != own) r.fail("sample count differs from the input count");
  if (npts == 0 || nnodes == 0 || nleaves == 0) r.fail("empty hierarchy");

  return {flags, levels, npts, nnodes, nleaves, ntris, numb, nidx, own};
}

/// Positions, normals and source indices (a permutation, or a part's distinct indices), colours.
void decode_samples(byte_reader& r, pmr_data& d, const pmr_counts& c) {
  const std::uint32_t npts = c.samples;
  r.need(npts, 28, "samples");
  d.positions.resize(npts);
  d.normals.resize(npts);
  d.source.resize(npts);
  for (std::uint32_t i = 0; i < npts; ++i) d.positions[i] = r.get_vec("position", i);
  for (std::uint32_t i = 0; i < npts; ++i) d.normals[i] = r.get_vec("normal", i);
  for (std::uint32_t i = 0; i < npts; ++i) d.source[i] = r.get<std::uint32_t>("source index");
  check_sources(r, d);
  if (c.flags & flag_colours) {
    r.need(npts, 3, "sample colours");
    d.colours.resize(npts);
    for (auto& k : d.colours) {
      k.r = r.get<std::uint8_t>("colour");
      k.g = r.get<std::uint8_t>("colour");
      k.b = r.get<std::uint8_t>("colour");
    }
  }
}

/// The octree's nodes, checked to form one tree in breadth-first order with each leaf once.
void decode_nodes(byte_reader& r, pmr_data& d, const pmr_counts& c) {
  const std::uint32_t nnodes = c.nodes, nleaves = c.leaves;
  r.need(nnodes, node_bytes, "nodes");
  d.nodes.resize(nnodes);
  for (std::uint32_t k = 0; k < nnodes; ++k) d.nodes[k] = get_node(r, k);
  // The tree: breadth-first, every inner node's children contiguous right after the previous
  // inner node's, so [1, nodes) is partitioned exactly once (a tree, no cycles).
  std::uint64_t next = 1;
  // The leaf table follows the nodes: its size is checked against the file before the leaf
  // count sizes anything (a lying count of 2³² leaves must not allocate 4 GB; found by fuzz_pmr).
  r.need(nleaves, leaf_bytes, "leaves");
  std::vector<unsigned char> leaf_used(nleaves, 0);
  for (std::uint32_t k = 0; k < nnodes; ++k) {
    const auto& n = d.nodes[k];
    if (n.leaf) {
      if (n.count != 0 || n.first >= nleaves || leaf_used[n.first]++)
        r.fail("node " + std::to_string(k) + ": leaf index out of range or repeated");
      continue;
    }
    if (n.count < 1 || n.count > 8 || n.first != next || n.first <= k)
      r.fail("node " + std::to_string(k) + ": children out of order or range");
    next += n.count;
  }
  if (next != nnodes) r.fail("nodes not reachable from the root");
}

/// The leaf table: contiguous sample ranges covering every own sample, each naming its node.
void decode_leaves(byte_reader& r, pmr_data& d, const pmr_counts& c) {
  const std::uint32_t nleaves = c.leaves, npts = c.samples, nnodes = c.nodes;
  d.leaf_list.resize(nleaves);
  std::uint64_t expect = 0;
  for (std::uint32_t l = 0; l < nleaves; ++l) {
    auto& L = d.leaf_list[l];
    L.first_point = r.get<std::uint32_t>("leaf first sample");
    L.point_count = r.get<std::uint32_t>("leaf sample count");
    L.node = r.get<std::uint32_t>("leaf node");
    if (L.first_point != expect || L.point_count == 0 ||
        static_cast<std::uint64_t>(L.first_point) + L.point_count > npts)
      r.fail("leaf " + std::to_string(l) + ": samples out of range or not contiguous");
    expect += L.point_count;
    if (L.node >= nnodes || !d.nodes[L.node].leaf || d.nodes[L.node].first != l)
      r.fail("leaf " + std::to_string(l) + ": node does not point back to it");
  }
  if (expect != c.own) r.fail("leaves do not cover every sample");
}

/// Per leaf and level: nested sample counts and the triangle and umbrella ranges.
void decode_levels(byte_reader& r, pmr_data& d, const pmr_counts& c) {
  const std::uint32_t nleaves = c.leaves, levels = c.levels, ntris = c.triangles,
                      numb = c.umbrellas;
  const std::uint64_t nlev = static_cast<std::uint64_t>(nleaves) * levels;
  r.need(nlev, level_bytes, "levels");
  d.levels.resize(nlev);
  for (std::uint64_t k = 0; k < nlev; ++k) {
    auto& L = d.levels[k];
    L.points = r.get<std::uint32_t>("level sample count");
    L.mean_umbrella = r.get_non_negative("level mean umbrella radius", k);
    L.first_tri = r.get<std::uint32_t>("level first triangle");
    L.tris = r.get<std::uint32_t>("level triangle count");
    L.first_entry = r.get<std::uint32_t>("level first umbrella");
    const auto& leaf = d.leaf_list[k / levels];
    const std::uint32_t prev = k % levels ? d.levels[k - 1].points : leaf.point_count;
    if (L.points > prev || (k % levels == 0 && L.points != leaf.point_count))
      r.fail("level " + std::to_string(k) + ": samples do not nest");
    if (static_cast<std::uint64_t>(L.first_tri) + L.tris > ntris ||
        static_cast<std::uint64_t>(L.first_entry) + L.points > numb)
      r.fail("level " + std::to_string(k) + ": triangle or umbrella range out of range");
  }
}

/// Triangles, umbrellas and their indices, each umbrella naming triangles of its own level.
void decode_umbrellas(byte_reader& r, pmr_data& d, const pmr_counts& c) {
  const std::uint32_t ntris = c.triangles, npts = c.samples, numb = c.umbrellas,
                      nidx = c.umbrella_indices;
  r.need(ntris, tri_bytes, "triangles");
  d.triangles.resize(ntris);
  for (std::uint32_t t = 0; t < ntris; ++t)
    for (auto& i : d.triangles[t]) {
      i = r.get<std::uint32_t>("triangle vertex");
      if (i >= npts) r.fail("triangle " + std::to_string(t) + ": vertex out of range");
    }
  r.need(numb, umbrella_bytes, "umbrellas");
  d.umbrellas.resize(numb);
  for (std::uint32_t u = 0; u < numb; ++u) {
    auto& U = d.umbrellas[u];
    U.first = r.get<std::uint32_t>("umbrella first");
    U.count = r.get<std::uint32_t>("umbrella count");
    U.radius = r.get_non_negative("umbrella radius", u);
    if (static_cast<std::uint64_t>(U.first) + U.count > nidx)
      r.fail("umbrella " + std::to_string(u) + ": index range out of range");
  }
  r.need(nidx, 4, "umbrella indices");
  d.umbrella_index.resize(nidx);
  for (auto& i : d.umbrella_index) i = r.get<std::uint32_t>("umbrella index");
  // Each umbrella's indices must name triangles of its own level.
  for (const auto& L : d.levels)
    for (std::uint32_t k = 0; k < L.points; ++k) {
      const auto& U = d.umbrellas[L.first_entry + k];
      for (std::uint32_t j = U.first; j < U.first + U.count; ++j)
        if (d.umbrella_index[j] >= L.tris)
          r.fail("umbrella index " + std::to_string(j) + " beyond its level's triangles");
    }
}

/// The file after its head (read_head() has checked it).
pmr_data decode(byte_reader& r, const unsigned char* bytes) {
  pmr_data d;
  const pmr_counts c = decode_header(r, d);
  decode_samples(r, d, c);
  decode_nodes(r, d, c);
  decode_leaves(r, d, c);
  decode_levels(r, d, c);
  decode_umbrellas(r, d, c);
  const std::size_t body = r.pos;
  const auto sum = r.get<std::uint64_t>("checksum");
  if (sum != fnv1a(bytes, body)) r.fail("checksum mismatch (the file is corrupted)");
  if (r.pos != r.bytes.size()) r.fail("trailing bytes after the checksum");
  return d;
}

}  // namespace

std::size_t pmr_file_bytes(const pmr_data& d) {
  const std::size_t header = 8 + 4 + 4 + 9 * 8 + 4 + 4 + 4 + 4 * d.rho.size() + 6 * 8 + 6 * 4;
  return header + d.positions.size() * 28 + d.colours.size() * 3 + d.nodes.size() * node_bytes +
         d.leaf_list.size() * leaf_bytes + d.levels.size() * level_bytes +
         d.triangles.size() * tri_bytes + d.umbrellas.size() * umbrella_bytes +
         d.umbrella_index.size() * 4 + 8 + (d.input_total != 0 ? 12 : 0);
}

void save_pmr_data(const pmr_data& d, const std::string& path) {
  save_file_bytes(path, encode(d));
}

pmr_data load_pmr_data(const std::string& path) {
  const mapping m(path);
  byte_reader r{std::span(m.data(), m.size()), 0, path};
  read_head(r, pmr_format);
  return decode(r, m.data());
}

}  // namespace pbr_lod::detail
