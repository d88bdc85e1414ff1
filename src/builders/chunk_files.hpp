// Temporary files of the chunked (out-of-core) builds: the records the distribution and halo
// passes append to every chunk's file, an index file of one vec3f per input point, and the
// temporary folder. Internal to src/builders (no public header includes it).
#pragma once

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
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
    const std::size_t at = buf_.size();
    buf_.resize(at + record_bytes);
    unsigned char* p = buf_.data() + at;
    std::memcpy(p, &r.index, 8);
    std::memcpy(p + 8, r.position.data(), 12);
    std::memcpy(p + 20, r.normal.data(), 12);
    std::memcpy(p + 32, &r.colour, 3);
    ++count_;
    if (buf_.size() >= limit_) flush();
  }
  void flush() {
    if (buf_.empty()) return;
    std::ofstream f(path_, std::ios::binary | std::ios::app);
    f.write(reinterpret_cast<const char*>(buf_.data()), static_cast<std::streamsize>(buf_.size()));
    if (!f) throw IoError(path_ + ": write failed");
    buf_.clear();
  }
  [[nodiscard]] std::uint64_t count() const { return count_; }
  [[nodiscard]] const std::string& path() const { return path_; }

 private:
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

/// Removes the temporary folder however the build ends.
struct temp_dir {
  std::filesystem::path path;
  bool owner = false;  // rank 0 removes it (after the last barrier)
  ~temp_dir() {
    std::error_code ec;
    if (owner) std::filesystem::remove_all(path, ec);
  }
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

/// What every chunked build does with its source, its ranks and its temporary folder.
struct chunked_pass_base {
  const point_source& src;
  std::filesystem::path dir;
  std::size_t block_points;
  int rank = 0, ranks = 1;
  std::function<void()> barrier_fn;
  temp_dir tmp;
  int passes = 0;
  const char* who;  // the build's name in messages

  chunked_pass_base(const point_source& s, const std::string& d, std::size_t block,
                    const distributed_build& dist, const char* name)
      : src(s),
        dir(d),
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
  /// Each file's write buffer when a pass appends to `files` files at once: 64 MiB shared
  /// among them, between 4 KiB and 256 KiB each.
  [[nodiscard]] static std::size_t buffer_bytes(std::size_t files) {
    return std::clamp<std::size_t>((std::size_t{64} << 20) / std::max<std::size_t>(1, files), 4096,
                                   256 * 1024);
  }

  /// Checks the source, creates `dir` and (rank 0) the temporary folder in it.
  void start() {
    if (src.size() == 0)
      throw InvalidArgument(std::string(who) + ": " + src.name() + " has no points");
    if (!all_finite(src.origin()))
      throw InvalidArgument(std::string(who) + ": " + src.name() + ": origin not finite");
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec || !std::filesystem::is_directory(dir))
      throw IoError(dir.string() + ": cannot create the output folder");
    tmp.path = dir / "tmp-build";
    tmp.owner = rank == 0;
    if (rank == 0) {
      std::filesystem::remove_all(tmp.path, ec);
      std::filesystem::create_directories(tmp.path, ec);
      if (ec) throw IoError(tmp.path.string() + ": cannot create: " + ec.message());
    }
    barrier();
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
