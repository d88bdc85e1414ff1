// Temporary files of the chunked (out-of-core) builds: the records the distribution and halo
// passes append to every chunk's file, an index file of one vec3f per input point, the
// temporary folder, and the staging folder the output is built in. Internal to src/builders (no
// public header includes it).
#pragma once

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "pbr_lod/builders/chunked.hpp"
#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/normal_repair.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/point_source.hpp"

namespace pbr_lod::detail {

/// A point as the distribution and halo passes store it in a chunk's temporary file.
struct point_record {
  std::uint64_t index;
  vec3f position, normal;
  rgb8 colour;
};
constexpr std::size_t record_bytes = 8 + 12 + 12 + 3;

/// A file appended to through a buffer: the passes write to every chunk's file at once.
class append_file {
 public:
  /// `buffer`: bytes held before a write; the passes share ≈ 64 MiB among all their files.
  append_file(std::string path, std::size_t buffer) : path_(std::move(path)), limit_(buffer) {
    std::ofstream f(path_, std::ios::binary | std::ios::trunc);
    if (!f) throw IoError(path_ + ": cannot open for writing");
  }
  void put(const point_record& r) {
    unsigned char* p = grow(record_bytes);
    std::memcpy(p, &r.index, 8);
    std::memcpy(p + 8, r.position.data(), 12);
    std::memcpy(p + 20, r.normal.data(), 12);
    std::memcpy(p + 32, &r.colour, 3);
    done();
  }
  /// One record of another layout (the Gaussian build's): n bytes at p.
  void put_bytes(const void* p, std::size_t n) {
    std::memcpy(grow(n), p, n);
    done();
  }
  void flush() {
    if (buf_.empty()) return;
    std::ofstream f(path_, std::ios::binary | std::ios::app);
    errno = 0;
    f.write(reinterpret_cast<const char*>(buf_.data()), static_cast<std::streamsize>(buf_.size()));
    f.flush();
    if (!f)
      throw IoError(path_ + ": write failed" +
                    (errno ? std::string(": ") + std::strerror(errno) : ""));
    buf_.clear();
  }
  [[nodiscard]] std::uint64_t count() const { return count_; }
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
  unsigned char* grow(std::size_t n) {
    const std::size_t at = buf_.size();
    buf_.resize(at + n);
    return buf_.data() + at;
  }
  void done() {
    ++count_;
    if (buf_.size() >= limit_) flush();
  }

  std::string path_;
  std::size_t limit_;
  std::vector<unsigned char> buf_;
  std::uint64_t count_ = 0;
};

inline std::vector<point_record> read_records(const std::string& path) {
  const std::vector<unsigned char> bytes = load_file_bytes(path);
  if (bytes.size() % record_bytes != 0) throw IoError(path + ": temporary file cut short");
  std::vector<point_record> out(bytes.size() / record_bytes);
  for (std::size_t i = 0; i < out.size(); ++i) {
    const unsigned char* p = bytes.data() + i * record_bytes;
    std::memcpy(&out[i].index, p, 8);
    std::memcpy(out[i].position.data(), p + 8, 12);
    std::memcpy(out[i].normal.data(), p + 20, 12);
    std::memcpy(&out[i].colour, p + 32, 3);
  }
  return out;
}

/// One vec3f per input point, written scattered (a chunk's points, ascending indices) through a
/// mapping of the range they span, read back in input order.
class index_file {
 public:
  /// create: make the file (one process); else open the one another process made.
  index_file(std::string path, std::uint64_t n, bool create) : path_(std::move(path)) {
    fd_ = create ? ::open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC, 0644)
                 : ::open(path_.c_str(), O_RDONLY);
    if (fd_ < 0 || (create && ::ftruncate(fd_, static_cast<off_t>(n * 12)) != 0))
      throw IoError(path_ + ": cannot open: " + std::strerror(errno));
  }
  ~index_file() {
    if (fd_ >= 0) ::close(fd_);
  }
  index_file(const index_file&) = delete;
  index_file& operator=(const index_file&) = delete;

  void scatter(const std::vector<point_record>& at, const std::vector<vec3f>& v) {
    if (at.empty()) return;
    const auto page = static_cast<std::uint64_t>(::sysconf(_SC_PAGESIZE));
    const std::uint64_t lo = at.front().index * 12 / page * page, hi = (at.back().index + 1) * 12;
    void* m =
        ::mmap(nullptr, hi - lo, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, static_cast<off_t>(lo));
    if (m == MAP_FAILED) throw IoError(path_ + ": cannot map: " + std::strerror(errno));
    auto* base = static_cast<unsigned char*>(m);
    for (std::size_t i = 0; i < at.size(); ++i)
      std::memcpy(base + (at[i].index * 12 - lo), v[i].data(), 12);
    // Written through to the file before another process (on another machine, through a
    // shared file system) reads it.
    const int synced = ::msync(m, hi - lo, MS_SYNC);
    ::munmap(m, hi - lo);
    if (synced != 0) throw IoError(path_ + ": cannot write: " + std::strerror(errno));
  }
  void read(std::uint64_t first, std::size_t count, std::vector<vec3f>& out) const {
    out.resize(count);
    auto* dst = reinterpret_cast<char*>(out.data());
    std::size_t done = 0;
    const std::size_t want = count * 12;
    while (done < want) {
      const ssize_t got =
          ::pread(fd_, dst + done, want - done, static_cast<off_t>(first * 12 + done));
      if (got <= 0) throw IoError(path_ + ": read failed");
      done += static_cast<std::size_t>(got);
    }
  }

 private:
  std::string path_;
  int fd_ = -1;
};

/// Items by the cells of a 32³ grid over the box [lo, lo + ext] that their boxes touch (a box may
/// reach beyond the grid, to infinity): a point then tests only the items of its cell.
class box_grid {
 public:
  static constexpr int g = 32;
  box_grid(const vec3d& lo, const vec3d& ext)
      : lo_(lo), ext_(ext.cwiseMax(vec3d::Constant(1e-30))), lists_(g * g * g) {}
  void add(std::uint32_t item, const vec3d& lo, const vec3d& hi) {
    std::array<int, 3> a{}, b{};
    for (int ax = 0; ax < 3; ++ax) {
      a[ax] = index(lo[ax], ax);
      b[ax] = index(hi[ax], ax);
    }
    for (int z = a[2]; z <= b[2]; ++z)
      for (int y = a[1]; y <= b[1]; ++y)
        for (int x = a[0]; x <= b[0]; ++x) lists_[(z * g + y) * g + x].push_back(item);
  }
  [[nodiscard]] const std::vector<std::uint32_t>& at(const vec3d& p) const {
    return lists_[(index(p.z(), 2) * g + index(p.y(), 1)) * g + index(p.x(), 0)];
  }

 private:
  [[nodiscard]] int index(double v, int axis) const {
    const double t = (v - lo_[axis]) / ext_[axis] * g;
    return std::clamp(static_cast<int>(std::floor(std::clamp(t, -1.0, double(g)))), 0, g - 1);
  }
  vec3d lo_, ext_;
  std::vector<std::vector<std::uint32_t>> lists_;
};

/// The tree above the chunks, which the structure passes find one level per pass over the source:
/// a node is a chunk until it is split. `Cell` is what the builder keeps per node (its cell or its
/// split point, the sums a pass gathers for it); a node is a Cell with the tree's bookkeeping.
template <class Cell>
struct top_tree {
  static constexpr std::uint32_t none = 0xffffffffu;
  enum class state : std::uint8_t { chunk, pending, split };
  struct node : Cell {
    using state = top_tree::state;
    std::uint64_t count = 0;
    state st = state::chunk;
    bool whole = false;  // the builder's split left it one cell (its points at one position)
    std::array<std::uint32_t, 8> child{none, none, none, none, none, none, none, none};
    std::array<std::uint64_t, 8> octant_count{};
    std::uint32_t first_child = 0, children = 0, chunk = none;
  };
  std::vector<node> nodes;
  std::vector<std::uint32_t> chunk_top;  // per chunk: its node

  /// The node holding p (a chunk, or one pending its split): octant(node, p) picks the child.
  template <class Octant>
  [[nodiscard]] std::uint32_t descend(const vec3d& p, Octant&& octant) const {
    std::uint32_t x = 0;
    while (nodes[x].st == state::split)
      x = nodes[x].child[static_cast<std::size_t>(octant(nodes[x], p))];
    return x;
  }

  /// The structure passes from a root of n points: while any chunk is to be split, one pass over
  /// `pass`'s source counts its points by octant and gathers what the split needs; then its
  /// children in octant order, empty octants skipped. Chunks are numbered in node order. The
  /// rule (the builder's split):
  ///   vec3d local(const vec3f&)                a position as the split sees it
  ///   bool split(const node&)                  a chunk to split (more than a chunk's points)
  ///   int octant(const node&, const vec3d&)    the child a point goes to
  ///   void add(node&, int octant, const vec3d&)  what the pass gathers (besides the counts)
  ///   bool keep_whole(node&)                   after the pass: the node stays one chunk
  ///   Cell child(const node&, int octant)      a child's cell
  template <class Pass, class Rule>
  void grow(Pass& pass, const Cell& root, std::uint64_t n, Rule& rule) {
    nodes.assign(1, node{});
    static_cast<Cell&>(nodes[0]) = root;
    nodes[0].count = n;
    for (;;) {
      bool any = false;
      for (auto& x : nodes)
        if (x.st == state::chunk && !x.whole && rule.split(x)) {
          x.st = state::pending;
          any = true;
        }
      if (!any) break;
      const auto octant = [&](const node& x, const vec3d& p) { return rule.octant(x, p); };
      pass.stream([&](std::uint64_t, const point_block& b) {
        for (const vec3f& pf : b.positions) {
          const vec3d p = rule.local(pf);
          node& x = nodes[descend(p, octant)];
          if (x.st != state::pending) continue;
          const int o = rule.octant(x, p);
          ++x.octant_count[static_cast<std::size_t>(o)];
          rule.add(x, o, p);
        }
      });
      split_pending(rule);
    }
    for (std::uint32_t i = 0; i < nodes.size(); ++i)
      if (nodes[i].st == state::chunk) {
        nodes[i].chunk = static_cast<std::uint32_t>(chunk_top.size());
        chunk_top.push_back(i);
      }
  }

  /// The chunks in octree order (depth first, octants in order): neighbours follow each other.
  [[nodiscard]] std::vector<std::uint32_t> chunks_in_order() const {
    std::vector<std::uint32_t> out, stack{0};
    while (!stack.empty()) {
      const std::uint32_t x = stack.back();
      stack.pop_back();
      if (nodes[x].st != state::split) {
        out.push_back(nodes[x].chunk);
        continue;
      }
      for (std::uint32_t k = nodes[x].children; k-- > 0;) stack.push_back(nodes[x].first_child + k);
    }
    return out;
  }

 private:
  template <class Rule>
  void split_pending(Rule& rule) {
    const std::size_t end = nodes.size();
    for (std::size_t i = 0; i < end; ++i) {
      if (nodes[i].st != state::pending) continue;
      if (rule.keep_whole(nodes[i])) {
        nodes[i].st = state::chunk;
        nodes[i].whole = true;
        continue;
      }
      nodes[i].st = state::split;
      nodes[i].first_child = static_cast<std::uint32_t>(nodes.size());
      for (std::size_t o = 0; o < 8; ++o) {
        if (nodes[i].octant_count[o] == 0) continue;
        node c;
        static_cast<Cell&>(c) = rule.child(nodes[i], static_cast<int>(o));
        c.count = nodes[i].octant_count[o];
        nodes[i].child[o] = static_cast<std::uint32_t>(nodes.size());
        nodes.push_back(c);
      }
      nodes[i].children = static_cast<std::uint32_t>(nodes.size()) - nodes[i].first_child;
    }
  }
};

/// What every chunked build does with its ranks and its folders, whatever it reads. The output is
/// built in a staging folder beside it (atomic_directory) and renamed onto it by finish(): every
/// rank writes into the staging folder (`dir`), rank 0 creates it, writes the top file last, and
/// commits it; a build that fails or is killed leaves the previous output as it was.
struct chunked_folder_build {
  atomic_directory output;
  std::filesystem::path dir;  // where the build writes: the staging folder
  std::size_t block_points;
  int rank = 0, ranks = 1;
  std::function<void()> barrier_fn;
  /// The passes' temporary files, in the staging folder (removed with it should the build fail).
  struct {
    std::filesystem::path path;
  } tmp;
  int passes = 0;
  const char* who;  // the build's name in messages

  chunked_folder_build(const std::string& d, std::size_t block, const distributed_build& dist,
                       const char* name)
      : output(d, dist.rank == 0),
        dir(output.staging_path()),
        block_points(block),
        rank(dist.rank),
        ranks(dist.ranks),
        barrier_fn(dist.barrier),
        who(name) {
    if (ranks < 1 || rank < 0 || rank >= ranks || (ranks > 1 && !barrier_fn))
      throw InvalidArgument(std::string(who) + ": rank " + std::to_string(rank) + " of " +
                            std::to_string(ranks) + " (and a barrier when more than one)");
    if (block_points == 0) throw InvalidArgument(std::string(who) + ": block_points is 0");
  }

  void barrier() const {
    if (ranks > 1) barrier_fn();
  }
  /// The chunks this process builds: every ranks-th from its rank.
  [[nodiscard]] bool mine(std::size_t c) const {
    return c % static_cast<std::size_t>(ranks) == static_cast<std::size_t>(rank);
  }
  [[nodiscard]] std::string temp_path(const char* kind, std::size_t c) const {
    return (tmp.path / (std::string(kind) + std::to_string(c))).string();
  }
  /// Opens the file of every input point's normal (n of them, in input order) that all ranks
  /// read: rank 0 creates it and `fill`s it, the others open it behind a barrier.
  template <class Fill>
  void share_normals(std::optional<index_file>& normals, std::uint64_t n, Fill&& fill) const {
    const std::string path = (tmp.path / "normals").string();
    if (rank == 0) {
      normals.emplace(path, n, true);
      fill(*normals);
    }
    barrier();
    if (rank != 0) normals.emplace(path, n, false);
  }
  /// Each file's write buffer when a pass appends to `files` files at once: 64 MiB shared
  /// among them, between 4 KiB and 256 KiB each.
  [[nodiscard]] static std::size_t buffer_bytes(std::size_t files) {
    return std::clamp<std::size_t>((std::size_t{64} << 20) / std::max<std::size_t>(1, files), 4096,
                                   256 * 1024);
  }

  /// Checks the input (`name`: its size and origin; `what` it holds) and the output, and (rank 0)
  /// creates the staging folder and the temporary folder in it.
  void start(const std::string& name, std::uint64_t size, const vec3d& origin, const char* what) {
    if (size == 0) throw InvalidArgument(std::string(who) + ": " + name + " has no " + what);
    if (!all_finite(origin))
      throw InvalidArgument(std::string(who) + ": " + name + ": origin not finite");
    check_chunked_output(output.target());
    tmp.path = dir / "tmp-build";
    if (rank == 0) {
      output.create();
      std::error_code ec;
      std::filesystem::create_directories(tmp.path, ec);
      if (ec) throw IoError(tmp.path.string() + ": cannot create: " + ec.message());
    }
    barrier();
  }

  /// Once every rank has written its files and rank 0 the top file: rank 0 removes the temporary
  /// folder and renames the staging folder onto the output. The output is whole when any rank
  /// returns.
  void finish() {
    barrier();
    if (rank == 0) {
      std::error_code ec;
      std::filesystem::remove_all(tmp.path, ec);
      if (ec) throw IoError(tmp.path.string() + ": cannot remove: " + ec.message());
      output.commit();
    }
    barrier();
    std::error_code ec;
    if (!std::filesystem::exists(std::filesystem::path(output.target()) / chunked_top_file, ec))
      throw IoError(output.target() + ": rank 0 did not finish the build (no " + chunked_top_file +
                    ")");
  }

  /// The chunk builds of this rank, f(chunk, threads) for each: side by side, one thread each,
  /// when there are at least `workers` of them, else one at a time on every thread (the output
  /// does not depend on it). done(fraction of them done) on the calling thread.
  template <class F, class Done>
  void over_my_chunks(std::size_t chunks, unsigned workers, F&& f, Done&& done) const {
    std::vector<std::size_t> list;
    for (std::size_t c = 0; c < chunks; ++c)
      if (mine(c)) list.push_back(c);
    const bool side_by_side = list.size() >= workers;
    std::atomic<std::size_t> finished{0};
    const auto caller = std::this_thread::get_id();
    parallel_tasks(list.size(), side_by_side ? workers : 1, [&](std::size_t k, unsigned) {
      f(list[k], side_by_side ? 1u : workers);
      const std::size_t d = ++finished;
      if (std::this_thread::get_id() == caller)
        done(static_cast<double>(d) / static_cast<double>(list.size()));
    });
  }
};

/// The passes every chunked build of a point_source shares: the streaming, the distribution of
/// the points to their chunks' files, the halos and the normals they fill.
struct chunked_pass_base : chunked_folder_build {
  const point_source& src;

  chunked_pass_base(const point_source& s, const std::string& d, std::size_t block,
                    const distributed_build& dist, const char* name)
      : chunked_folder_build(d, block, dist, name), src(s) {}

  /// Checks the source and the output, and (rank 0) creates the staging folder and the
  /// temporary folder in it.
  void start() { chunked_folder_build::start(src.name(), src.size(), src.origin(), "points"); }

  /// A chunk's box and size, which its halo starts from.
  struct chunk_extent {
    vec3f lo = vec3f::Constant(std::numeric_limits<float>::infinity());
    vec3f hi = vec3f::Constant(-std::numeric_limits<float>::infinity());
    std::uint64_t count = 0;
  };

  /// The distribution pass: rank 0 appends every point to the temporary file "chunk<c>" of its
  /// chunk c = chunk_of(block, k), input order kept, and calls also(record, c) for what the
  /// builder writes in the same pass (its halos), then done() (to flush those); `files` is how
  /// many files the pass writes at once (for their buffers). Then every rank learns the chunks'
  /// sizes from the files. Returns every chunk's size and its box (the box: rank 0 only).
  template <class ChunkOf, class Also, class Done>
  std::vector<chunk_extent> distribute(std::size_t chunks, std::size_t files, ChunkOf&& chunk_of,
                                       Also&& also, Done&& done) {
    std::vector<chunk_extent> ext(chunks);
    if (rank == 0) {
      std::vector<append_file> out;
      out.reserve(chunks);
      for (std::size_t c = 0; c < chunks; ++c)
        out.emplace_back(temp_path("chunk", c), buffer_bytes(files));
      const attributes a = src.attrs();
      stream([&](std::uint64_t first, const point_block& b) {
        for (std::size_t k = 0; k < b.size(); ++k) {
          const std::uint32_t c = chunk_of(b, k);
          ext[c].lo = ext[c].lo.cwiseMin(b.positions[k]);
          ext[c].hi = ext[c].hi.cwiseMax(b.positions[k]);
          const point_record r{first + k, b.positions[k],
                               a.normal ? b.normals[k] : vec3f(vec3f::Zero()),
                               a.colour ? b.colours[k] : rgb8{}};
          out[c].put(r);
          also(r, c);
        }
      });
      for (auto& f : out) f.flush();
      done();
    }
    barrier();
    for (std::size_t c = 0; c < chunks; ++c)
      ext[c].count = std::filesystem::file_size(temp_path("chunk", c)) / record_bytes;
    return ext;
  }

  /// Part of a chunk for its halo: the box of some of its points and how far from that box the
  /// halo must reach for them.
  struct halo_cell {
    vec3f lo, hi;
    double reach;
  };
  static constexpr int cells_per_axis = 8;

  static double box_distance2(const vec3f& p, const vec3f& lo, const vec3f& hi) {
    const vec3d q = p.cast<double>();
    const vec3d d = (lo.cast<double>() - q).cwiseMax(q - hi.cast<double>()).cwiseMax(vec3d::Zero());
    return d.squaredNorm();
  }

  /// Chunk c's halo cells. A chunk point p has its k neighbours within its k-th neighbour
  /// distance d_k(p), and its splat is also bounded by its neighbours' own neighbourhood radii
  /// (ellipse_rule::local_spacing): a neighbour q has d_k(q) ≤ |q − p| + d_k(p) ≤ 2·d_k(p) (p's
  /// ball holds k points), so everything p's estimate reads lies within 3·d_k(p) of p. d_k over
  /// the chunk alone bounds the true one from above. Per cell of an 8³ grid over the chunk's box
  /// the largest 3·d_k — so that one isolated point (a bird above a LiDAR tile) widens the halo
  /// around itself only — a hair wider than the float distances. A chunk of fewer than k points
  /// cannot bound its neighbours by its own: one cell that takes every point.
  [[nodiscard]] std::vector<halo_cell> halo_cells(std::size_t c, const chunk_extent& ci, int k,
                                                  unsigned threads) const {
    const auto recs = read_records(temp_path("chunk", c));
    if (recs.size() != ci.count) throw IoError(temp_path("chunk", c) + ": cut short");
    std::vector<vec3f> pts(recs.size());
    vec3f lo = recs[0].position, hi = lo;
    for (std::size_t i = 0; i < recs.size(); ++i) {
      pts[i] = recs[i].position;
      lo = lo.cwiseMin(pts[i]);
      hi = hi.cwiseMax(pts[i]);
    }
    // The box from the records, not from ci: only rank 0 has the chunks' boxes.
    if (ci.count < static_cast<std::uint64_t>(k))
      return {{lo, hi, std::numeric_limits<double>::infinity()}};
    const knn_graph g = nearest_neighbour_graph(pts, k, threads);
    constexpr int m = cells_per_axis;
    const vec3f ext = (hi - lo).cwiseMax(vec3f::Constant(1e-30f));
    std::vector<halo_cell> cells(
        m * m * m, halo_cell{vec3f::Constant(INFINITY), vec3f::Constant(-INFINITY), 0.0});
    for (std::size_t i = 0; i < pts.size(); ++i) {
      int at = 0;
      for (int ax = 2; ax >= 0; --ax)
        at = at * m + std::clamp(static_cast<int>((pts[i][ax] - lo[ax]) / ext[ax] * m), 0, m - 1);
      halo_cell& h = cells[static_cast<std::size_t>(at)];
      h.lo = h.lo.cwiseMin(pts[i]);
      h.hi = h.hi.cwiseMax(pts[i]);
      const double dk = std::sqrt(static_cast<double>(g.dist2[i * g.k + g.k - 1]));
      h.reach = std::max(h.reach, 3 * dk * (1 + 1e-5) + 1e-30);
    }
    std::erase_if(cells, [](const halo_cell& h) { return h.lo.x() > h.hi.x(); });
    return cells;
  }

  /// The halo step: each chunk's halo cells for k neighbours (by the rank that owns the chunk,
  /// into a file), then one pass (rank 0) appending to the temporary file "halo<c>" every point
  /// of another chunk within reach of c's cells. `chunks`: every chunk's extent (rank 0 needs the
  /// boxes); chunk_of(position) → the chunk a point belongs to. Returns the halo points (rank 0).
  template <class ChunkOf>
  std::uint64_t halos(const std::vector<chunk_extent>& chunks, int k, unsigned threads,
                      ChunkOf&& chunk_of) {
    if (chunks.size() < 2) return 0;
    for (std::size_t c = 0; c < chunks.size(); ++c) {
      if (!mine(c)) continue;
      const std::vector<halo_cell> cells = halo_cells(c, chunks[c], k, threads);
      byte_writer w;
      w.put(static_cast<std::uint64_t>(cells.size()));
      for (const halo_cell& h : cells) {
        w.put_vec(h.lo);
        w.put_vec(h.hi);
        w.put(h.reach);
      }
      save_file_bytes(temp_path("cells", c), w.bytes);
    }
    barrier();
    std::uint64_t points = 0;
    if (rank == 0) points = collect_halos(chunks, chunk_of);
    barrier();
    return points;
  }

  /// One pass: every point into the halo of each other chunk that has a cell within its reach.
  template <class ChunkOf>
  std::uint64_t collect_halos(const std::vector<chunk_extent>& chunks, ChunkOf&& chunk_of) {
    struct entry {
      std::uint32_t chunk;
      halo_cell cell;
    };
    std::vector<entry> all;
    for (std::uint32_t c = 0; c < chunks.size(); ++c) {
      const std::string path = temp_path("cells", c);
      const std::vector<unsigned char> bytes = load_file_bytes(path);
      byte_reader r{bytes, 0, path};
      const auto m = r.get<std::uint64_t>("cells");
      for (std::uint64_t i = 0; i < m; ++i) {
        entry e{c, {}};
        e.cell.lo = r.get_vec("cell", i);
        e.cell.hi = r.get_vec("cell", i);
        e.cell.reach = r.get<double>("cell");
        all.push_back(e);
      }
    }
    std::vector<append_file> files;
    files.reserve(chunks.size());
    for (std::size_t c = 0; c < chunks.size(); ++c)
      files.emplace_back(temp_path("halo", c), buffer_bytes(chunks.size()));
    // Cells listed by the cells of a coarse grid over the data their reach touches.
    vec3f lo = chunks[0].lo, hi = chunks[0].hi;
    for (const auto& c : chunks) {
      lo = lo.cwiseMin(c.lo);
      hi = hi.cwiseMax(c.hi);
    }
    box_grid grid(lo.cast<double>(), (hi - lo).cast<double>());
    for (std::uint32_t e = 0; e < all.size(); ++e) {
      const halo_cell& h = all[e].cell;  // an infinite reach lists it everywhere
      grid.add(e, h.lo.template cast<double>() - vec3d::Constant(h.reach),
               h.hi.template cast<double>() + vec3d::Constant(h.reach));
    }
    const attributes a = src.attrs();
    std::vector<std::uint32_t> taken;  // chunks this point already went to
    stream([&](std::uint64_t first, const point_block& b) {
      for (std::size_t k = 0; k < b.size(); ++k) {
        const vec3f& p = b.positions[k];
        const std::uint32_t own = chunk_of(p);
        taken.clear();
        for (const std::uint32_t e : grid.at(p.cast<double>())) {
          const std::uint32_t c = all[e].chunk;
          const halo_cell& h = all[e].cell;
          if (c == own || std::find(taken.begin(), taken.end(), c) != taken.end()) continue;
          if (std::isfinite(h.reach) && box_distance2(p, h.lo, h.hi) > h.reach * h.reach) continue;
          taken.push_back(c);
          files[c].put({first + k, p, a.normal ? b.normals[k] : vec3f(vec3f::Zero()),
                        a.colour ? b.colours[k] : rgb8{}});
        }
      }
    });
    std::uint64_t points = 0;
    for (auto& f : files) {
      f.flush();
      points += f.count();
    }
    return points;
  }

  /// The missing normals (zero or not finite) of every chunk's file, estimated chunk after chunk
  /// in `order` (rank 0, after halos()): fill_missing_normals over the chunk and its halo, the
  /// halo's points of chunks already done carrying their estimates. Those orient the chunk's, so
  /// that one orientation spreads from chunk to chunk as the in-memory builds' spreads over the
  /// whole input's k-NN graph. Each chunk's file is rewritten with its normals.
  template <class ChunkOf>
  void fill_normals_in_turn(const std::vector<std::uint32_t>& order, std::size_t chunks, int k,
                            unsigned threads, ChunkOf&& chunk_of) {
    index_file filled((tmp.path / "filled").string(), src.size(), true);
    std::vector<char> done(chunks, 0);
    std::vector<vec3f> one;
    const auto given = [](const vec3f& v) {
      return missing_normal(v) ? vec3f(vec3f::Zero()) : vec3f(v.normalized());
    };
    for (const std::uint32_t c : order) {
      std::vector<point_record> recs = read_records(temp_path("chunk", c));
      const std::vector<point_record> halo =
          chunks > 1 ? read_records(temp_path("halo", c)) : std::vector<point_record>{};
      std::vector<vec3f> pos, nrm;
      pos.reserve(recs.size() + halo.size());
      nrm.reserve(recs.size() + halo.size());
      for (const point_record& r : recs) {
        pos.push_back(r.position);
        nrm.push_back(given(r.normal));
      }
      for (const point_record& r : halo) {
        pos.push_back(r.position);
        if (done[chunk_of(r.position)]) {
          filled.read(r.index, 1, one);
          nrm.push_back(one[0]);
        } else {
          nrm.push_back(given(r.normal));
        }
      }
      (void)fill_missing_normals(pos, nrm, k, threads);
      nrm.resize(recs.size());
      filled.scatter(recs, nrm);
      append_file out(temp_path("chunk", c), buffer_bytes(1));
      for (std::size_t i = 0; i < recs.size(); ++i) {
        recs[i].normal = nrm[i];
        out.put(recs[i]);
      }
      out.flush();
      done[c] = 1;
    }
  }

  /// f(first index, block) over the whole source, block by block; one full pass.
  template <class F>
  void stream(F&& f) {
    ++passes;
    const attributes a = src.attrs();
    const std::uint64_t n = src.size();
    point_block b;
    for (std::uint64_t first = 0; first < n; first += block_points) {
      const auto count = static_cast<std::size_t>(std::min<std::uint64_t>(block_points, n - first));
      src.read(first, count, b);
      if (b.size() != count || (a.normal && b.normals.size() != count) ||
          (a.colour && b.colours.size() != count))
        throw IoError(src.name() + ": a block came back with the wrong number of points");
      f(first, b);
    }
  }
};

/// run() of a chunked build into `target`; an IoError on the way (a full disk, a file-size limit)
/// comes out naming the build and the output, and saying that what was there is kept.
template <class Run>
chunked_build_report build_or_keep(const std::string& target, const char* who, Run&& run) {
  std::error_code ec;
  const bool existed = std::filesystem::exists(target, ec);
  try {
    return run();
  } catch (const IoError& e) {
    throw IoError(std::string(who) + ": " + target + " not written" +
                  (existed ? " (what was there is kept)" : "") + ": " + e.what());
  }
}

/// Chunks and top nodes refer to each other one to one; an inner top node's children come
/// after it and each is reached once; the chunks' samples add up to the input.
template <class Node>
void validate_chunked_top(const std::string& path, const std::vector<Node>& top_nodes,
                          const std::vector<std::uint32_t>& frontier,
                          const std::vector<std::uint32_t>& chunk_top,
                          const std::vector<std::uint64_t>& chunk_samples,
                          const std::vector<std::uint64_t>& chunk_nodes,
                          std::uint64_t input_points) {
  constexpr std::uint32_t top = 0xffffffffu;
  const std::size_t n = top_nodes.size();
  std::uint64_t samples = 0;
  for (std::size_t c = 0; c < chunk_top.size(); ++c) {
    if (chunk_top[c] >= n || frontier[chunk_top[c]] != c || chunk_samples[c] == 0 ||
        chunk_nodes[c] == 0)
      throw FormatError(path + ": chunk " + std::to_string(c) + " and its top node disagree");
    samples += chunk_samples[c];
  }
  if (samples != input_points)
    throw FormatError(path + ": the chunks hold " + std::to_string(samples) +
                      " samples, the input " + std::to_string(input_points));
  std::vector<char> reached(n, 0);
  reached[0] = 1;
  for (std::size_t i = 0; i < n; ++i) {
    if (!reached[i])
      throw FormatError(path + ": top node " + std::to_string(i) + " is unreachable");
    if (frontier[i] != top) {
      if (frontier[i] >= chunk_top.size() || chunk_top[frontier[i]] != i)
        throw FormatError(path + ": top node " + std::to_string(i) + " names a bad chunk");
      continue;
    }
    const Node& nd = top_nodes[i];
    const std::uint64_t end = std::uint64_t{nd.first} + nd.count;
    if (nd.leaf || nd.count == 0 || nd.count > 8 || nd.first <= i || end > n)
      throw FormatError(path + ": top node " + std::to_string(i) +
                        " is not an inner node with 1..8 children after it");
    for (std::uint64_t k = nd.first; k < end; ++k) {
      if (reached[k])
        throw FormatError(path + ": top node " + std::to_string(k) + " has two parents");
      reached[k] = 1;
    }
  }
}

}  // namespace pbr_lod::detail
