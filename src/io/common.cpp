// pbr_lod — what every reader shares: loading a file, messages, and finish_mesh, the one place
// where non-finite points are dropped, the origin is chosen and positions become float.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <algorithm>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "io_internal.hpp"

namespace pbr_lod::detail {

namespace {

// The IoErrors every reader gives for a path that is not a readable file.
void check_openable(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw IoError(path + ": cannot open: no such file");
  if (fs::is_directory(st)) throw IoError(path + ": cannot open: it is a directory");
}

}  // namespace

std::string read_file_bytes(const std::string& path) {
  check_openable(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path + ": cannot open: " + std::strerror(errno));
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw IoError(path + ": cannot read: size unknown (not a regular file?)");
  in.seekg(0, std::ios::beg);
  std::string bytes(static_cast<std::size_t>(size), '\0');
  if (size > 0 && !in.read(bytes.data(), size))
    throw IoError(cat(path, ": cannot read: got ", in.gcount(), " of ", size, " bytes"));
  return bytes;
}

posix_file::posix_file(const std::string& path) : path_(path) {
  check_openable(path);
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw IoError(path + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    throw IoError(path + ": cannot read: size unknown (not a regular file?)");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
}

posix_file::~posix_file() {
  if (fd_ >= 0) ::close(fd_);
}

std::size_t posix_file::read_some(std::uint64_t offset, std::size_t n, void* out) const {
  std::size_t got = 0;
  auto* p = static_cast<char*>(out);
  while (got < n) {
    const ::ssize_t r = ::pread(fd_, p + got, n - got, static_cast<::off_t>(offset + got));
    if (r < 0) {
      if (errno == EINTR) continue;
      throw IoError(cat(path_, ": cannot read at byte ", offset + got, ": ", std::strerror(errno)));
    }
    if (r == 0) break;
    got += static_cast<std::size_t>(r);
  }
  return got;
}

void posix_file::read_exact(std::uint64_t offset, std::size_t n, void* out) const {
  const std::size_t got = read_some(offset, n, out);
  if (got != n)
    throw IoError(cat(path_, ": cannot read: got ", got, " of ", n, " bytes at byte ", offset,
                      " (the file is shorter than when it was opened)"));
}

std::string read_header_lines(const posix_file& f, std::string_view last_key) {
  constexpr std::size_t cap = std::size_t{64} << 20;
  std::string bytes;
  std::size_t scanned = 0;  // bytes[0, scanned) are complete lines without last_key
  std::vector<std::string_view> tok;
  for (std::size_t want = std::size_t{64} << 10;; want *= 2) {
    const std::size_t have = bytes.size();
    const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(want, f.size()) - have);
    bytes.resize(have + n);
    const std::size_t got = f.read_some(have, n, bytes.data() + have);
    bytes.resize(have + got);
    const bool whole = bytes.size() >= f.size() || got < n;
    while (scanned < bytes.size()) {
      const std::size_t nl = bytes.find('\n', scanned);
      if (nl == std::string::npos && !whole) break;  // an incomplete line: read more
      const std::size_t end = nl == std::string::npos ? bytes.size() : nl;
      split_ws(std::string_view(bytes).substr(scanned, end - scanned), tok);
      scanned = end + 1;
      if (!tok.empty() && tok[0] == last_key) return bytes;
    }
    if (whole) return bytes;
    if (bytes.size() >= cap)
      format_error(f.path(), "header",
                   cat("no '", last_key, "' line in the first ", cap, " bytes"));
  }
}

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

void format_error(const std::string& path, const std::string& where, const std::string& what) {
  throw FormatError(where.empty() ? path + ": " + what : path + ": " + where + ": " + what);
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r'))
    s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

std::size_t split_ws(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  std::size_t i = 0;
  const std::size_t n = line.size();
  while (i < n) {
    while (i < n && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const std::size_t b = i;
    while (i < n && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > b) out.push_back(line.substr(b, i - b));
  }
  return out.size();
}

vec3d choose_origin(const finite_box& box, const std::optional<vec3d>& hint,
                    const std::string& path, read_report& report) {
  const std::string name = std::filesystem::path(path).filename().string();
  report.points_read = box.total;
  const std::uint64_t dropped = box.total - box.finite;
  report.dropped_non_finite = dropped;
  if (dropped > 0)
    report.warnings.push_back(cat(name, ": dropped ", dropped, " non-finite points"));
  if (box.finite == 0) return vec3d::Zero();
  const vec3d &lo = box.lo, &hi = box.hi;
  // Halve before adding: (lo + hi) / 2 overflows for coordinates near DBL_MAX.
  vec3d origin = 0.5 * lo + 0.5 * hi;
  // Float positions relative to the centre must stay finite: a span beyond FLT_MAX cannot be
  // stored (and no real scan has one).
  if (!all_finite(vec3d(0.5 * hi - 0.5 * lo)) ||
      (0.5 * hi - 0.5 * lo).maxCoeff() > 0.5 * std::numeric_limits<float>::max())
    format_error(path, "", "coordinates span more than a float can hold");
  if (hint) {
    const vec3d& h = *hint;
    // Honoured when it is no farther from the box centre than the box is wide: an origin
    // write_ply stored always is; a far-off one (an edited file) would cost precision.
    if (all_finite(h) && ((h - origin).cwiseAbs().array() <= (hi - lo).array()).all())
      origin = h;
    else
      report.warnings.push_back(cat(name,
                                    ": the stored origin is far from the data; using the "
                                    "centre of the bounding box instead"));
  }
  return origin;
}

vec3f normal_rule::operator()(vec3f n) {
  if (!all_finite(n)) {
    ++bad;
    return vec3f::Zero();
  }
  // Renormalise only normals that are clearly not unit, so unit normals written by write_ply
  // come back bit-identical.
  const float len = n.norm();
  if (len > 0.0f && std::abs(len - 1.0f) > 1e-3f) {
    n /= len;
    ++renormalised;
  }
  return n;
}

void normal_rule::report_to(const std::string& path, read_report& report) const {
  const std::string name = std::filesystem::path(path).filename().string();
  if (bad > 0)
    report.warnings.push_back(
        cat(name, ": ", bad, " normals were not finite and were set to zero"));
  if (renormalised > 0)
    report.warnings.push_back(
        cat(name, ": ", renormalised, " normals were not of unit length and were normalised"));
}

triangle_mesh finish_mesh(raw_geometry&& g, const std::string& path, read_report& report) {
  const std::string name = std::filesystem::path(path).filename().string();
  const std::size_t n = g.positions.size();
  finite_box box;
  for (const vec3d& p : g.positions) box.add(p);
  const std::size_t finite = box.finite, dropped = n - finite;
  const vec3d origin = choose_origin(box, g.origin_hint, path, report);

  triangle_mesh m;
  point_cloud& c = m.vertices;
  c.origin = origin;
  const bool has_normals = !g.normals.empty();
  const bool has_colours = !g.colours.empty();
  c.positions.reserve(finite);
  if (has_normals) c.normals.reserve(finite);
  if (has_colours) c.colours.reserve(finite);

  // New index of each kept vertex; only needed when faces must be re-indexed.
  constexpr std::uint32_t gone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> remap;
  if (dropped > 0 && !g.faces.empty()) remap.assign(n, gone);

  normal_rule normal;
  for (std::size_t i = 0; i < n; ++i) {
    const vec3d& p = g.positions[i];
    if (!all_finite(p)) continue;
    if (!remap.empty()) remap[i] = static_cast<std::uint32_t>(c.positions.size());
    c.positions.push_back((p - origin).cast<float>());
    if (has_normals) c.normals.push_back(normal(g.normals[i]));
    if (has_colours) c.colours.push_back(g.colours[i]);
  }
  normal.report_to(path, report);

  const bool has_tc = !g.face_texcoords.empty();
  if (remap.empty()) {
    m.faces = std::move(g.faces);
    m.face_texcoords = std::move(g.face_texcoords);
  } else {
    m.faces.reserve(g.faces.size());
    if (has_tc) m.face_texcoords.reserve(g.faces.size());
    std::size_t lost = 0;
    for (std::size_t f = 0; f < g.faces.size(); ++f) {
      const auto& t = g.faces[f];
      const std::array<std::uint32_t, 3> r{remap[t[0]], remap[t[1]], remap[t[2]]};
      if (r[0] == gone || r[1] == gone || r[2] == gone) {
        ++lost;
        continue;
      }
      m.faces.push_back(r);
      if (has_tc) m.face_texcoords.push_back(g.face_texcoords[f]);
    }
    if (lost > 0) {
      report.faces_dropped += lost;
      report.warnings.push_back(
          cat(name, ": dropped ", lost, " faces that used a non-finite vertex"));
    }
  }
  m.texture_path = std::move(g.texture_path);
  m.vertices.sensor = g.sensor;
  return m;
}

}  // namespace pbr_lod::detail
