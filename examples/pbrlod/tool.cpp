// pbrlod — the command-line tool's shared parts (tool.hpp).
#include "tool.hpp"

#include "pbr_lod/builders/chunked_point_octree.hpp"
#include "pbr_lod/core/gaussian_splats.hpp"
#include "pbr_lod/core/mesh_colours.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/gaussians.hpp"
#include "pbr_lod/io/point_source_file.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <stdexcept>

#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/error.hpp"

namespace pbrlod_tool {
namespace fs = std::filesystem;

bool is_hierarchy_file(const std::string& path) {
  if (fs::path(path).extension() == ".lod") return true;
  // A folder whose top file starts with a method's folder magic (a chunked build), or any other
  // file that starts with a method's magic (a chunk of a chunked folder, say).
  std::error_code ec;
  const bool folder = fs::is_directory(path, ec);
  // A folder is only ever a chunked build: one without its top file (an interrupted build, say)
  // is an error that says so, not an input with no file extension.
  if (folder) check_chunked_folder(path);
  const std::string file = folder ? (fs::path(path) / chunked_top_file).string() : path;
  if (!fs::is_regular_file(file, ec)) return false;
  const auto head = detail::load_file_prefix(file, 8);
  const std::string magic(head.begin(), head.end());
  for (const auto& m : methods())
    if (folder ? (!m.dir_magic.empty() && m.dir_magic == magic)
               : (!m.magic.empty() && m.magic == magic))
      return true;
  return false;
}

lod_header peek_lod(const std::string& path) {
  // The head every format shares (core/binary.hpp): magic, version, then (all but the ρ-grid)
  // the flags; the method's own load() validates the rest.
  std::error_code ec;
  const std::string file =
      fs::is_directory(path, ec) ? (fs::path(path) / chunked_top_file).string() : path;
  const auto bytes = detail::load_file_prefix(file, 16);
  if (bytes.size() < 16) throw FormatError(path + ": too short for a pbr_lod hierarchy file");
  detail::byte_reader r{bytes, 0, path};
  lod_header h;
  for (int i = 0; i < 8; ++i) h.magic.push_back(r.get<char>("magic"));
  h.version = r.get<std::uint32_t>("version");
  h.flags = r.get<std::uint32_t>("flags");
  return h;
}

std::unique_ptr<point_source> open_build_source(const std::string& input) {
  const std::string gen = "generated-points:", with_normals = ":normals";
  if (input.rfind(gen, 0) == 0) {
    const bool normals =
        input.size() > gen.size() + with_normals.size() &&
        input.compare(input.size() - with_normals.size(), with_normals.size(), with_normals) == 0;
    const std::string count =
        input.substr(gen.size(), input.size() - gen.size() - (normals ? with_normals.size() : 0));
    std::uint64_t n = 0;
    try {
      std::size_t used = 0;
      n = std::stoull(count, &used);
      if (used != count.size() || n == 0) throw std::invalid_argument(input);
    } catch (const std::exception&) {
      throw InvalidArgument(input +
                            ": expected generated-points:N or generated-points:N:normals, N > 0");
    }
    return std::make_unique<generated_point_source>(n, 1, normals, true);
  }
  return open_point_source(input);
}

namespace {

/// N of "PREFIXN" (1 ≤ N ≤ 4096), else InvalidArgument naming the form expected.
int generated_detail(const std::string& spec, const std::string& prefix) {
  const std::string count = spec.substr(prefix.size());
  try {
    std::size_t used = 0;
    const int n = std::stoi(count, &used);
    if (used == count.size() && n >= 1 && n <= 4096) return n;
  } catch (const std::exception&) {
  }
  throw InvalidArgument(spec + ": expected " + prefix + "N with 1 <= N <= 4096");
}

}  // namespace

std::size_t generated_count(const std::string& spec, const std::string& prefix) {
  const std::string count = spec.substr(prefix.size());
  try {
    std::size_t used = 0;
    const long long n = std::stoll(count, &used);
    if (used == count.size() && n >= 1 && n <= (1LL << 31)) return static_cast<std::size_t>(n);
  } catch (const std::exception&) {
  }
  throw InvalidArgument(spec + ": expected " + prefix + "N with 1 <= N <= 2^31");
}

namespace {
/// A Gaussian scene's means with their view-independent colours, as a point cloud.
point_cloud gaussian_means(const gaussian_cloud& g) {
  point_cloud c;
  c.origin = g.origin;
  c.positions = g.positions;
  c.colours.reserve(g.size());
  for (std::size_t i = 0; i < g.size(); ++i) {
    const vec3f rgb = g.base_colour(i).cwiseMax(0.0f).cwiseMin(1.0f) * 255.0f;
    c.colours.push_back({static_cast<std::uint8_t>(std::lround(rgb.x())),
                         static_cast<std::uint8_t>(std::lround(rgb.y())),
                         static_cast<std::uint8_t>(std::lround(rgb.z()))});
  }
  return c;
}
}  // namespace

loaded_input load(const std::string& path) {
  loaded_input in;
  const auto t0 = clock_type::now();
  const auto ext = fs::path(path).extension().string();
  if (path.rfind("generated:", 0) == 0)
    in.mesh = make_demo_scene(generated_detail(path, "generated:"));
  else if (path.rfind("generated-hard:", 0) == 0)
    in.mesh = make_hard_cases_scene(generated_detail(path, "generated-hard:"));
  else if (path.rfind("generated-gaussians:", 0) == 0)
    in.mesh.vertices = gaussian_means(
        in.gaussians = make_gaussian_scene(generated_count(path, "generated-gaussians:")));
  else if (path.rfind("generated-points:", 0) == 0)
    in.mesh.vertices = read_all(*open_build_source(path));  // the in-memory twin of a chunked build
  else if (is_gaussian_file(path))
    in.mesh.vertices = gaussian_means(in.gaussians = read_gaussians(path, &in.report));
  else if (ext == ".ply" || ext == ".obj" || ext == ".off" || ext == ".PLY" || ext == ".OBJ" ||
           ext == ".OFF")
    in.mesh = read_mesh(path, &in.report);
  else
    in.mesh.vertices = read_points(path, &in.report);
  // A textured mesh is seen textured: what draws it from its vertices (the point builders, the
  // ρ-grid) gets the texture's colour at each vertex (POP keeps the texture itself).
  if (in.mesh.vertices.colours.empty() && in.mesh.textured())
    in.mesh.vertices.colours = texture_vertex_colours(in.mesh);
  in.read_seconds = seconds_since(t0);
  if (in.mesh.vertices.empty()) throw InvalidArgument(path + ": the file holds no points");
  for (const auto& w : in.report.warnings) std::cerr << "warning: " << w << "\n";
  return in;
}

std::pair<vec3d, double> world_bounds(const point_cloud& c) {
  const sphere s = bounding_sphere_about_box_centre(c.positions);
  return {c.origin + s.centre.cast<double>(), static_cast<double>(s.radius)};
}

std::vector<double> parse_numbers(const std::string& s, char sep, std::size_t n, const char* what) {
  std::vector<double> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep)) {
    try {
      std::size_t used = 0;
      v.push_back(std::stod(item, &used));
      if (used != item.size()) throw std::invalid_argument(item);
    } catch (const std::exception&) {
      throw InvalidArgument(std::string(what) + ": '" + s + "' is not a list of " +
                            std::to_string(n) + " numbers separated by '" + sep + "'");
    }
  }
  if (v.size() != n)
    throw InvalidArgument(std::string(what) + ": '" + s + "' needs " + std::to_string(n) +
                          " numbers");
  return v;
}

camera make_camera(const point_cloud& c, const view_args& a) {
  const auto [centre, radius] = world_bounds(c);
  return make_camera(centre, radius, a);
}

camera make_camera(const vec3d& centre, double radius, const view_args& a) {
  const auto v = parse_numbers(a.view, ',', 3, "--view");
  const auto sz = parse_numbers(a.size, 'x', 2, "--size");
  if (!(sz[0] >= 1 && sz[1] >= 1 && sz[0] <= 16384 && sz[1] <= 16384))
    throw InvalidArgument("--size: width and height must lie in 1..16384");
  if (!(v[2] > 0)) throw InvalidArgument("--view: the distance must be positive");
  return camera::orbit(centre, radius > 0 ? radius : 1.0, v[0], v[1], v[2], a.up == "z" ? 2 : 1,
                       {static_cast<int>(sz[0]), static_cast<int>(sz[1])});
}

render_options lod_render_options(const view_args& a, bool has_colour) {
  render_options o;
  if (a.effects_list == "default") {
    o.fx = no_effects;
    o.fx.shading = true;
    o.fx.colour = has_colour;
    // Splats and points blended (Botsch et al. 2005): a frame without them (triangles only)
    // skips the accumulation pass and draws the unblended image (rasterizer.hpp).
    o.fx.blending = true;
  } else {
    o.fx = parse_effects(a.effects_list);
  }
  o.supersample = a.supersample;
  return o;
}

json error_json(const image_error& e) {
  json j;
  j.num("rmse", e.rmse).num("psnr", e.psnr).num("hole_fraction", e.hole_fraction);
  j.integer("covered_either", static_cast<long long>(e.covered_either));
  j.integer("reference_covered", static_cast<long long>(e.reference_covered));
  j.integer("holes", static_cast<long long>(e.holes));
  return j;
}

params::params(const std::vector<std::string>& items) {
  for (const auto& p : items) {
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InvalidArgument("--param '" + p + "': expected key=value");
    m_[p.substr(0, eq)] = p.substr(eq + 1);
  }
}

long params::integer(const std::string& key, long fallback, long lo, long hi) {
  const auto it = m_.find(key);
  if (it == m_.end()) return fallback;
  long v = 0;
  try {
    std::size_t used = 0;
    v = std::stol(it->second, &used);
    if (used != it->second.size()) throw std::invalid_argument(key);
  } catch (const std::exception&) {
    throw InvalidArgument("--param " + key + "=" + it->second + ": expected an integer");
  }
  if (v < lo || v > hi)
    throw InvalidArgument("--param " + key + "=" + it->second + ": expected " + std::to_string(lo) +
                          ".." + std::to_string(hi));
  m_.erase(it);
  return v;
}

double params::number(const std::string& key, double fallback, double lo, double hi) {
  const auto it = m_.find(key);
  if (it == m_.end()) return fallback;
  double v = 0;
  try {
    std::size_t used = 0;
    v = std::stod(it->second, &used);
    if (used != it->second.size()) throw std::invalid_argument(key);
  } catch (const std::exception&) {
    throw InvalidArgument("--param " + key + "=" + it->second + ": expected a number");
  }
  if (!(v >= lo && v <= hi))
    throw InvalidArgument("--param " + key + "=" + it->second + ": expected " + std::to_string(lo) +
                          ".." + std::to_string(hi));
  m_.erase(it);
  return v;
}

std::string params::choice(const std::string& key, const std::string& fallback,
                           const std::vector<std::string>& choices) {
  const auto it = m_.find(key);
  if (it == m_.end()) return fallback;
  const std::string v = it->second;
  if (std::find(choices.begin(), choices.end(), v) == choices.end()) {
    std::string all;
    for (const auto& c : choices) all += (all.empty() ? "" : ", ") + c;
    throw InvalidArgument("--param " + key + "=" + v + ": expected one of " + all);
  }
  m_.erase(it);
  return v;
}

std::optional<std::uint64_t> params::bytes(const std::string& key) {
  const auto it = m_.find(key);
  if (it == m_.end()) return std::nullopt;
  const std::string v = it->second;
  std::uint64_t n = 0;
  const char* end = v.data() + v.size();
  const auto [at, ec] = std::from_chars(v.data(), end, n);  // digits only: no sign, no space
  int shift = -1;
  if (ec == std::errc() && at == end) {
    shift = 0;
  } else if (ec == std::errc() && at + 1 == end) {
    const auto unit = std::string_view("KMGT").find(
        static_cast<char>(std::toupper(static_cast<unsigned char>(*at))));
    if (unit != std::string_view::npos) shift = 10 * static_cast<int>(unit + 1);
  }
  if (shift < 0 || (shift > 0 && n > (std::uint64_t{1} << (63 - shift))))
    throw InvalidArgument("--param " + key + "=" + v +
                          ": expected a size such as 4G, 512M or 1000000 (bytes)");
  m_.erase(it);
  return n << shift;
}

std::optional<std::array<double, 3>> params::point(const std::string& key) {
  const auto it = m_.find(key);
  if (it == m_.end()) return std::nullopt;
  std::array<double, 3> v{};
  std::size_t at = 0;
  for (std::size_t c = 0; c < 3; ++c) {
    const std::size_t end = c < 2 ? it->second.find(',', at) : it->second.size();
    try {
      if (end == std::string::npos) throw std::invalid_argument(key);
      const std::string part = it->second.substr(at, end - at);
      std::size_t used = 0;
      v[c] = std::stod(part, &used);
      if (used != part.size() || !std::isfinite(v[c])) throw std::invalid_argument(key);
    } catch (const std::exception&) {
      throw InvalidArgument("--param " + key + "=" + it->second +
                            ": expected three finite numbers x,y,z");
    }
    at = end + 1;
  }
  m_.erase(it);
  return v;
}

bool params::flag(const std::string& key, bool fallback) {
  const std::string v = choice(key, fallback ? "true" : "false", {"true", "false", "1", "0"});
  return v == "true" || v == "1";
}

void params::finish(const std::string& method, const std::string& expected) const {
  if (!m_.empty())
    throw InvalidArgument(method + ": unknown parameter '" + m_.begin()->first + "' (expected " +
                          expected + ")");
}

std::function<bool(double)> progress_callback(const std::string& what, bool on_terminal) {
  if (!on_terminal) return {};
  return [what, t0 = clock_type::now()](double f) {
    std::fprintf(stderr, "\r\033[K[%5.1fs] building %s %3.0f%%", seconds_since(t0), what.c_str(),
                 100 * f);
    if (f >= 1) std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
    return true;
  };
}

}  // namespace pbrlod_tool
