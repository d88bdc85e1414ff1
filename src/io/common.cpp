// pbr_lod — what every reader shares: loading a file, messages, and finish_mesh, the one place
// where non-finite points are dropped, the origin is chosen and positions become float.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include "io_internal.hpp"

namespace pbr_lod::detail {

std::string read_file_bytes(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) throw IoError(path + ": cannot open: no such file");
  if (fs::is_directory(st)) throw IoError(path + ": cannot open: it is a directory");
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

triangle_mesh finish_mesh(raw_geometry&& g, const std::string& path, read_report& report) {
  const std::string name = std::filesystem::path(path).filename().string();
  const std::size_t n = g.positions.size();
  report.points_read = n;

  // Bounding box of the finite points, in double.
  constexpr double inf = std::numeric_limits<double>::infinity();
  vec3d lo(inf, inf, inf), hi(-inf, -inf, -inf);
  std::size_t finite = 0;
  for (const vec3d& p : g.positions)
    if (all_finite(p)) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
      ++finite;
    }
  const std::size_t dropped = n - finite;
  report.dropped_non_finite = dropped;
  if (dropped > 0)
    report.warnings.push_back(cat(name, ": dropped ", dropped, " non-finite points"));

  vec3d origin = vec3d::Zero();
  if (finite > 0) {
    // Halve before adding: (lo + hi) / 2 overflows for coordinates near DBL_MAX.
    origin = 0.5 * lo + 0.5 * hi;
    // Float positions relative to the centre must stay finite: a span beyond FLT_MAX cannot be
    // stored (and no real scan has one).
    if (!all_finite(vec3d(0.5 * hi - 0.5 * lo)) ||
        (0.5 * hi - 0.5 * lo).maxCoeff() > 0.5 * std::numeric_limits<float>::max())
      format_error(path, "", "coordinates span more than a float can hold");
    if (g.origin_hint) {
      const vec3d& h = *g.origin_hint;
      // Honoured when it is no farther from the box centre than the box is wide: an origin
      // write_ply stored always is; a far-off one (an edited file) would cost precision.
      if (all_finite(h) && ((h - origin).cwiseAbs().array() <= (hi - lo).array()).all())
        origin = h;
      else
        report.warnings.push_back(cat(name,
                                      ": the stored origin is far from the data; using the "
                                      "centre of the bounding box instead"));
    }
  }

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

  std::size_t bad_normals = 0, renormalised = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const vec3d& p = g.positions[i];
    if (!all_finite(p)) continue;
    if (!remap.empty()) remap[i] = static_cast<std::uint32_t>(c.positions.size());
    c.positions.push_back((p - origin).cast<float>());
    if (has_normals) {
      vec3f nrm = g.normals[i];
      if (!all_finite(nrm)) {
        nrm.setZero();
        ++bad_normals;
      } else {
        // Renormalise only normals that are clearly not unit, so unit normals written by
        // write_ply come back bit-identical.
        const float len = nrm.norm();
        if (len > 0.0f && std::abs(len - 1.0f) > 1e-3f) {
          nrm /= len;
          ++renormalised;
        }
      }
      c.normals.push_back(nrm);
    }
    if (has_colours) c.colours.push_back(g.colours[i]);
  }
  if (bad_normals > 0)
    report.warnings.push_back(
        cat(name, ": ", bad_normals, " normals were not finite and were set to zero"));
  if (renormalised > 0)
    report.warnings.push_back(
        cat(name, ": ", renormalised, " normals were not of unit length and were normalised"));

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
