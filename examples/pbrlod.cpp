// pbrlod — the command-line tool of pbr_lod (see DESIGN.md "The command-line tool").
//
//   pbrlod build  --method NAME [--param k=v]... INPUT -o OUT.lod
//   pbrlod render OUT.lod|INPUT [--view AZ,EL,DIST] [--size WxH] [--tolerance PX]
//                 [--effects LIST] [--up y|z] -o IMAGE.png [--json]
//   pbrlod stats  OUT.lod|INPUT [--json]
//   pbrlod compare A.png B.png [--json]
//   pbrlod demo   [INPUT] [-o DIR] [--json]
//
// Exit codes: 0 success, 1 bad input or failure (message on stderr), 2 usage error or a method
// that this version does not have.
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "pbr_lod/version.hpp"

namespace {
using namespace pbr_lod;
namespace fs = std::filesystem;

using clock_type = std::chrono::steady_clock;
double seconds_since(clock_type::time_point t0) {
  return std::chrono::duration<double>(clock_type::now() - t0).count();
}

// ---- a minimal JSON object writer (one object on one line; numbers, strings, nested objects)
class json {
 public:
  json& num(const std::string& k, double v) {
    key(k);
    if (std::isfinite(v)) {
      std::ostringstream o;
      o.precision(10);
      o << v;
      out_ += o.str();
    } else {
      out_ += "null";  // JSON has no inf/NaN (PSNR of identical images is +inf)
    }
    return *this;
  }
  json& integer(const std::string& k, long long v) {
    key(k);
    out_ += std::to_string(v);
    return *this;
  }
  json& str(const std::string& k, const std::string& v) {
    key(k);
    out_ += quote(v);
    return *this;
  }
  json& boolean(const std::string& k, bool v) {
    key(k);
    out_ += v ? "true" : "false";
    return *this;
  }
  json& object(const std::string& k, const json& v) {
    key(k);
    out_ += v.text();
    return *this;
  }
  [[nodiscard]] std::string text() const { return "{" + out_ + "}"; }

 private:
  void key(const std::string& k) {
    if (!out_.empty()) out_ += ",";
    out_ += quote(k) + ":";
  }
  static std::string quote(const std::string& s) {
    std::string q = "\"";
    for (const char c : s) {
      switch (c) {
        case '"':
          q += "\\\"";
          break;
        case '\\':
          q += "\\\\";
          break;
        case '\n':
          q += "\\n";
          break;
        case '\t':
          q += "\\t";
          break;
        default:
          if (static_cast<unsigned char>(c) < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", c);
            q += buf;
          } else {
            q += c;
          }
      }
    }
    return q + "\"";
  }
  std::string out_;
};

// ---- progress on a terminal only (stderr, so --json output on stdout stays one object)
class progress {
 public:
  explicit progress(bool json_mode)
      : enabled_(!json_mode && isatty(STDOUT_FILENO) && isatty(STDERR_FILENO)) {}
  void step(const std::string& what) {
    if (!enabled_) return;
    std::fprintf(stderr, "\r\033[K[%5.1fs] %s", seconds_since(t0_), what.c_str());
    std::fflush(stderr);
  }
  ~progress() {
    if (enabled_) std::fprintf(stderr, "\r\033[K");
  }
  progress(const progress&) = delete;
  progress& operator=(const progress&) = delete;

 private:
  bool enabled_;
  clock_type::time_point t0_ = clock_type::now();
};

// ---- inputs
bool is_hierarchy_file(const std::string& path) {
  return fs::path(path).extension() == ".lod";
}

/// Which builder wrote a .lod file, and with which attributes (from its header).
struct lod_header {
  std::string method;
  bool colour = false;
};

lod_header peek_lod(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError(path + ": cannot open");
  char magic[8] = {};
  std::uint32_t version = 0, flags = 0;
  f.read(magic, 8);
  f.read(reinterpret_cast<char*>(&version), 4);
  f.read(reinterpret_cast<char*>(&flags), 4);
  if (!f) throw FormatError(path + ": too short for a pbr_lod hierarchy file");
  if (std::string(magic, 8) == "PBRLODPO") return {"point-octree", (flags & 1u) != 0};
  throw FormatError(path +
                    ": not a hierarchy file written by this version of pbrlod (unknown magic)");
}

struct loaded_input {
  triangle_mesh mesh;  // faces empty for a point cloud
  read_report report;
  double read_seconds = 0;
  [[nodiscard]] bool is_mesh() const { return !mesh.faces.empty(); }
};

loaded_input load(const std::string& path) {
  loaded_input in;
  const auto t0 = clock_type::now();
  const auto ext = fs::path(path).extension().string();
  if (ext == ".ply" || ext == ".obj" || ext == ".off" || ext == ".PLY" || ext == ".OBJ" ||
      ext == ".OFF")
    in.mesh = read_mesh(path, &in.report);
  else
    in.mesh.vertices = read_points(path, &in.report);
  in.read_seconds = seconds_since(t0);
  if (in.mesh.vertices.empty()) throw InvalidArgument(path + ": the file holds no points");
  for (const auto& w : in.report.warnings) std::cerr << "warning: " << w << "\n";
  return in;
}

/// World-space bounding sphere (centre of the box, radius to the farthest point), in double.
std::pair<vec3d, double> world_bounds(const point_cloud& c) {
  const sphere s = bounding_sphere_about_box_centre(c.positions);
  return {c.origin + s.centre.cast<double>(), static_cast<double>(s.radius)};
}

struct view_args {
  std::string view = "30,20,3";
  std::string size = "512x512";
  std::string up = "y";
  std::string effects_list = "default";
};

void add_view_options(CLI::App* cmd, view_args& a) {
  cmd->add_option("--view", a.view,
                  "AZ,EL,DIST: azimuth and elevation in degrees around the "
                  "model's bounding-sphere centre, distance in radii")
      ->capture_default_str();
  cmd->add_option("--size", a.size, "WxH image size in pixels")->capture_default_str();
  cmd->add_option("--up", a.up, "up axis: y (scans) or z (LiDAR)")
      ->check(CLI::IsMember({"y", "z"}))
      ->capture_default_str();
  cmd->add_option("--effects", a.effects_list,
                  "comma list of shading, colour, backface_cull, shadows, hole_filling; 'none'; "
                  "'all'; 'default' = shading where the data has normals (or faces), colour where "
                  "it has colours");
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
  const auto v = parse_numbers(a.view, ',', 3, "--view");
  const auto sz = parse_numbers(a.size, 'x', 2, "--size");
  if (!(sz[0] >= 1 && sz[1] >= 1 && sz[0] <= 16384 && sz[1] <= 16384))
    throw InvalidArgument("--size: width and height must lie in 1..16384");
  if (!(v[2] > 0)) throw InvalidArgument("--view: the distance must be positive");
  const auto [centre, radius] = world_bounds(c);
  return camera::orbit(centre, radius > 0 ? radius : 1.0, v[0], v[1], v[2], a.up == "z" ? 2 : 1,
                       {static_cast<int>(sz[0]), static_cast<int>(sz[1])});
}

render_options make_render_options(const loaded_input& in, const view_args& a) {
  render_options o;
  if (a.effects_list == "default") {
    o.fx = no_effects;
    o.fx.shading = in.is_mesh() || !in.mesh.vertices.normals.empty();
    o.fx.colour = !in.mesh.vertices.colours.empty();
  } else {
    o.fx = parse_effects(a.effects_list);
  }
  return o;
}

image render_input(const loaded_input& in, const camera& cam, const render_options& o) {
  return in.is_mesh() ? render_reference(in.mesh, cam, o)
                      : render_reference(in.mesh.vertices, cam, o);
}

json error_json(const image_error& e) {
  json j;
  j.num("rmse", e.rmse).num("psnr", e.psnr).num("hole_fraction", e.hole_fraction);
  j.integer("covered_either", static_cast<long long>(e.covered_either));
  j.integer("reference_covered", static_cast<long long>(e.reference_covered));
  j.integer("holes", static_cast<long long>(e.holes));
  return j;
}

// ---- the point-octree (Pajarola 2003)
std::map<std::string, std::string> parse_params(const std::vector<std::string>& params) {
  std::map<std::string, std::string> m;
  for (const auto& p : params) {
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0)
      throw InvalidArgument("--param '" + p + "': expected key=value");
    m[p.substr(0, eq)] = p.substr(eq + 1);
  }
  return m;
}

long param_int(std::map<std::string, std::string>& m, const std::string& key, long fallback,
               long lo, long hi) {
  const auto it = m.find(key);
  if (it == m.end()) return fallback;
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
  m.erase(it);
  return v;
}

std::string param_choice(std::map<std::string, std::string>& m, const std::string& key,
                         const std::string& fallback, const std::vector<std::string>& choices) {
  const auto it = m.find(key);
  if (it == m.end()) return fallback;
  const std::string v = it->second;
  if (std::find(choices.begin(), choices.end(), v) == choices.end()) {
    std::string all;
    for (const auto& c : choices) all += (all.empty() ? "" : ", ") + c;
    throw InvalidArgument("--param " + key + "=" + v + ": expected one of " + all);
  }
  m.erase(it);
  return v;
}

point_octree_options octree_options(const std::vector<std::string>& params, bool interactive) {
  auto m = parse_params(params);
  point_octree_options o;
  o.leaf_size = static_cast<std::uint32_t>(param_int(m, "leaf_size", 8, 1, 1 << 20));
  o.max_depth = static_cast<std::uint32_t>(param_int(m, "max_depth", 48, 1, 250));
  o.normal_bits = static_cast<int>(param_int(m, "normal_bits", 16, 0, 24));
  o.knn = static_cast<int>(param_int(m, "knn", 16, 3, 256));
  o.knn_ellipses = static_cast<int>(param_int(m, "knn_ellipses", 12, 3, 256));
  o.threads = static_cast<unsigned>(param_int(m, "threads", 0, 0, 256));
  const auto cov =
      param_choice(m, "covariance", "stable", {"stable", "generic_double", "generic_float"});
  o.covariance = cov == "stable"           ? covariance_method::stable
                 : cov == "generic_double" ? covariance_method::generic_double
                                           : covariance_method::generic_float;
  o.axis_rule = param_choice(m, "axes", "sqrt", {"sqrt", "eigenvalue"}) == "sqrt"
                    ? ellipse_axis_rule::sqrt_eigenvalue
                    : ellipse_axis_rule::eigenvalue;
  if (!m.empty())
    throw InvalidArgument("point-octree: unknown parameter '" + m.begin()->first +
                          "' (expected leaf_size, max_depth, normal_bits, knn, knn_ellipses, "
                          "threads, covariance, axes)");
  if (interactive) {
    o.progress = [t0 = clock_type::now()](double f) {
      std::fprintf(stderr, "\r\033[K[%5.1fs] building point-octree %3.0f%%", seconds_since(t0),
                   100 * f);
      if (f >= 1) std::fprintf(stderr, "\r\033[K");
      std::fflush(stderr);
      return true;
    };
  }
  return o;
}

/// Calls f(point_set<A>) with A the attributes the cloud actually has (normals, colours,
/// ellipses: eight instantiations), so the builder is compiled for exactly what the scene has.
template <class F>
auto with_point_set(const point_cloud& c, const std::string& what, F&& f) {
  const attributes have = c.present();
  const auto go = [&]<attributes A>() { return f(point_set<A>::from(c, what)); };
  constexpr attributes N{.normal = true}, C{.colour = true}, E{.ellipse = true};
  const int key = (have.normal ? 1 : 0) | (have.colour ? 2 : 0) | (have.ellipse ? 4 : 0);
  switch (key) {
    case 1:
      return go.template operator()<N>();
    case 2:
      return go.template operator()<C>();
    case 3:
      return go.template operator()<N | C>();
    case 4:
      return go.template operator()<E>();
    case 5:
      return go.template operator()<N | E>();
    case 6:
      return go.template operator()<C | E>();
    case 7:
      return go.template operator()<N | C | E>();
    default:
      return go.template operator()<positions_only>();
  }
}

template <class Tree>
json octree_stats_json(const Tree& t, const std::string& path) {
  const auto& st = t.stats();
  const double n = static_cast<double>(t.samples().size());
  json j;
  j.str("file", path).str("method", "point-octree");
  j.integer("nodes", static_cast<long long>(t.nodes().size()));
  j.integer("leaves", static_cast<long long>(st.leaves));
  j.integer("samples", static_cast<long long>(t.samples().size()));
  j.integer("max_depth", static_cast<long long>(st.max_depth));
  j.num("nodes_per_point", static_cast<double>(t.nodes().size()) / n);
  j.integer("normal_bits", t.normal_bits());
  j.boolean("colour", Tree::attrs.colour);
  j.integer("file_bytes", static_cast<long long>(t.file_bytes()));
  j.num("bytes_per_point", static_cast<double>(t.file_bytes()) / n);
  j.num("bytes_per_point_file", static_cast<double>(t.file_bytes()) / n);
  j.num("bytes_per_point_memory", static_cast<double>(t.memory_bytes()) / n);
  j.num("bits_per_sample", 8.0 * static_cast<double>(t.file_bytes()) / n);
  j.num("build_seconds", st.seconds);
  j.num("estimation_seconds", st.estimation_seconds);
  j.num("tree_seconds", st.tree_seconds);
  return j;
}

template <class F>
auto with_octree(const std::string& path, F&& f) {
  const auto h = peek_lod(path);
  if (h.colour)
    return f(point_octree<point_octree_attributes(attributes{.colour = true})>::load(path));
  return f(point_octree<point_octree_attributes(positions_only)>::load(path));
}

// ---- subcommands
int cmd_render_lod(const std::string& input, const view_args& va, float tolerance,
                   const std::string& output, bool as_json) {
  return with_octree(input, [&](const auto& t) {
    using tree = std::decay_t<decltype(t)>;
    // Camera around the root's bounding sphere, in world coordinates.
    point_cloud bounds;
    bounds.origin = t.origin();
    bounds.positions = t.samples().positions;
    const camera cam = make_camera(bounds, va);
    const view v(cam, t.origin());
    render_options o;
    if (va.effects_list == "default") {
      o.fx = no_effects;
      o.fx.shading = true;
      o.fx.colour = tree::attrs.colour;
    } else {
      o.fx = parse_effects(va.effects_list);
    }
    const traverse_options topt{.tolerance_px = tolerance,
                                .backface_cull = o.fx.backface_cull,
                                .cull_volume = traverse_options::volume::view_cone};
    traverse_stats st;
    const auto t0 = clock_type::now();
    const image img = render<tree::attrs>(
        v, o, [&](auto& sink) { st = traverse(t, v, topt, sink, point_octree_policy{}); });
    const double frame_s = seconds_since(t0);  // LOD selection + rasterisation, one pass
    write_png(output, img);
    if (as_json) {
      json j;
      j.str("input", input).str("output", output).str("method", "point-octree");
      j.num("tolerance_px", tolerance).str("effects", o.fx.to_string());
      j.integer("width", img.width).integer("height", img.height);
      j.integer("nodes_visited", static_cast<long long>(st.visited));
      j.integer("culled_frustum", static_cast<long long>(st.culled_frustum));
      j.integer("culled_backface", static_cast<long long>(st.culled_backface));
      j.integer("splats", static_cast<long long>(st.splats));
      j.num("fraction_drawn",
            static_cast<double>(st.splats) / static_cast<double>(t.samples().size()));
      j.num("frame_seconds", frame_s);
      std::cout << j.text() << "\n";
    } else {
      std::cout << "wrote " << output << ": " << st.splats << " splats of " << t.samples().size()
                << " samples at tolerance " << tolerance << " px (" << frame_s << " s)\n";
    }
    return 0;
  });
}

int cmd_render(const std::string& input, const view_args& va, float tolerance,
               const std::string& output, bool as_json) {
  if (is_hierarchy_file(input)) return cmd_render_lod(input, va, tolerance, output, as_json);
  progress prog(as_json);
  prog.step("reading " + input);
  const auto in = load(input);
  const camera cam = make_camera(in.mesh.vertices, va);
  const render_options o = make_render_options(in, va);
  prog.step("rendering");
  const auto t0 = clock_type::now();
  const image img = render_input(in, cam, o);
  const double render_s = seconds_since(t0);
  write_png(output, img);
  std::size_t covered = 0;
  for (const float d : img.depth) covered += std::isfinite(d);
  if (as_json) {
    json j;
    j.str("input", input).str("output", output).str("kind", in.is_mesh() ? "mesh" : "points");
    j.num("tolerance_px", tolerance).str("effects", o.fx.to_string());
    j.integer("width", img.width).integer("height", img.height);
    j.integer("covered_pixels", static_cast<long long>(covered));
    j.integer("primitives",
              static_cast<long long>(in.is_mesh() ? in.mesh.num_faces() : in.mesh.num_vertices()));
    j.num("read_seconds", in.read_seconds).num("render_seconds", render_s);
    std::cout << j.text() << "\n";
  } else {
    std::cout << "wrote " << output << " (" << img.width << "x" << img.height << ", " << covered
              << " pixels covered, " << render_s << " s)\n";
  }
  return 0;
}

int cmd_stats(const std::string& input, bool as_json) {
  if (is_hierarchy_file(input)) {
    return with_octree(input, [&](const auto& t) {
      if (as_json) {
        std::cout << octree_stats_json(t, input).text() << "\n";
      } else {
        const double n = static_cast<double>(t.samples().size());
        std::cout << input << ": point-octree, " << t.nodes().size() << " nodes ("
                  << t.stats().leaves << " leaves) over " << t.samples().size() << " samples, "
                  << static_cast<double>(t.file_bytes()) / n << " bytes/point in the file, "
                  << static_cast<double>(t.memory_bytes()) / n << " in memory, built in "
                  << t.stats().seconds << " s\n";
      }
      return 0;
    });
  }
  const auto in = load(input);
  const auto& c = in.mesh.vertices;
  const auto [centre, radius] = world_bounds(c);
  const attributes a = c.present();
  // Bytes per point as pbr_lod stores the input (point_set with exactly these attributes).
  const std::size_t bpp = a.bytes_per_point();
  if (as_json) {
    json j;
    j.str("input", input).str("kind", in.is_mesh() ? "mesh" : "points");
    j.integer("points", static_cast<long long>(c.size()));
    j.integer("faces", static_cast<long long>(in.mesh.num_faces()));
    j.integer("points_in_file", static_cast<long long>(in.report.points_read));
    j.integer("dropped_non_finite", static_cast<long long>(in.report.dropped_non_finite));
    j.integer("faces_dropped", static_cast<long long>(in.report.faces_dropped));
    j.str("attributes", a.to_string());
    j.boolean("textured", !in.mesh.texture_path.empty());
    j.integer("bytes_per_point", static_cast<long long>(bpp));
    j.num("bits_per_point", 8.0 * static_cast<double>(bpp));
    json o;
    o.num("x", c.origin.x()).num("y", c.origin.y()).num("z", c.origin.z());
    j.object("origin", o);
    json s;
    s.num("x", centre.x()).num("y", centre.y()).num("z", centre.z()).num("radius", radius);
    j.object("bounding_sphere", s);
    j.num("read_seconds", in.read_seconds);
    std::cout << j.text() << "\n";
  } else {
    std::cout << input << ": " << (in.is_mesh() ? "mesh" : "point cloud") << ", " << c.size()
              << " points, " << in.mesh.num_faces() << " faces, attributes " << a.to_string()
              << ", " << bpp << " bytes/point, bounding sphere centre (" << centre.transpose()
              << ") radius " << radius << ", read in " << in.read_seconds << " s\n";
  }
  return 0;
}

int cmd_compare(const std::string& a, const std::string& b, bool as_json) {
  const image ia = read_png(a), ib = read_png(b);
  if (ia.width != ib.width || ia.height != ib.height)
    throw InvalidArgument("compare: " + a + " is " + std::to_string(ia.width) + "x" +
                          std::to_string(ia.height) + " but " + b + " is " +
                          std::to_string(ib.width) + "x" + std::to_string(ib.height));
  const image_error e = compare_images(ia, ib);
  if (as_json) {
    json j = error_json(e);
    j.str("reference", a).str("test", b);
    std::cout << j.text() << "\n";
  } else {
    std::cout << "RMSE " << e.rmse << ", PSNR " << e.psnr << " dB, hole fraction "
              << e.hole_fraction << " (" << e.holes << " of " << e.reference_covered
              << " reference pixels)\n";
  }
  return 0;
}

const std::map<std::string, std::string>& methods() {
  static const std::map<std::string, std::string> m = {
      {"point-octree", "Pajarola 2003"},
      {"rho-grid", "Duguet & Drettakis 2004 (issue #4)"},
      {"pop", "Chen & Nguyen 2001 (issue #5)"},
      {"pca-octree", "Kalaiah & Varshney 2003"},
      {"pmr", "Dey & Hudson 2002"},
  };
  return m;
}

int cmd_build_octree(const std::string& input, const std::string& output,
                     const std::vector<std::string>& params, bool as_json) {
  const bool interactive = !as_json && isatty(STDOUT_FILENO) && isatty(STDERR_FILENO);
  const auto opt = octree_options(params, interactive);
  read_report report;
  const point_cloud cloud = read_points(input, &report);
  for (const auto& w : report.warnings) std::cerr << "warning: " << w << "\n";
  return with_point_set(cloud, input, [&](const auto& pts) {
    const auto t = build_point_octree(pts, opt);
    t.save(output);
    const json j = octree_stats_json(t, output);
    if (as_json)
      std::cout << j.text() << "\n";
    else
      std::cout << "wrote " << output << ": " << j.text() << "\n";
    return 0;
  });
}

int cmd_build(const std::string& method, const std::string& input, const std::string& output,
              const std::vector<std::string>& params, bool as_json) {
  if (method == "point-octree") return cmd_build_octree(input, output, params, as_json);
  const auto it = methods().find(method);
  if (it == methods().end()) {
    std::string names;
    for (const auto& [k, _] : methods()) names += (names.empty() ? "" : ", ") + k;
    std::cerr << "pbrlod build: unknown method '" << method << "' (expected one of " << names
              << ")\n";
    return 2;
  }
  std::cerr << "pbrlod build: method '" << method << "' (" << it->second
            << ") is not available in pbr_lod " << version()
            << " yet; this version renders and measures inputs at full detail only\n";
  return 2;
}

int cmd_demo(const std::string& input, const std::string& dir, bool as_json) {
  progress prog(as_json);
  fs::create_directories(dir);
  loaded_input in;
  std::string name = input;
  if (input.empty()) {
    prog.step("generating the demo scene");
    in.mesh = make_demo_scene(64);
    name = "generated demo scene";
  } else {
    prog.step("reading " + input);
    in = load(input);
  }
  json report;
  report.str("input", name).integer("points", static_cast<long long>(in.mesh.num_vertices()));
  report.integer("faces", static_cast<long long>(in.mesh.num_faces()));
  view_args va;
  va.size = "768x768";
  const camera cam = make_camera(in.mesh.vertices, va);
  render_options o = make_render_options(in, va);
  o.fx.shading = true;  // a mesh has face normals; a cloud without normals falls back to flat
  o.fx.colour = !in.mesh.vertices.colours.empty();

  // 1. The full-detail reference: the mesh's triangles, or every point as its own splat.
  prog.step("rendering the full-detail reference");
  auto t0 = clock_type::now();
  const image ref = render_input(in, cam, o);
  report.num("reference_seconds", seconds_since(t0));
  const std::string ref_png = (fs::path(dir) / "reference.png").string();
  write_png(ref_png, ref);
  report.str("reference_png", ref_png);

  // 2. For a mesh: the same surface as a point cloud (one sample per vertex-area), rendered as
  //    splats with and without hole filling, and compared with the mesh reference.
  if (in.is_mesh()) {
    prog.step("sampling the surface into points");
    const std::size_t n = std::max<std::size_t>(in.mesh.num_vertices(), 20000);
    loaded_input pts;
    pts.mesh.vertices = sample_surface(in.mesh, n, 1);
    report.integer("samples", static_cast<long long>(n));
    for (const bool holes : {false, true}) {
      render_options po = o;
      po.fx.hole_filling = holes;
      prog.step(holes ? "rendering splats with hole filling" : "rendering splats");
      t0 = clock_type::now();
      const image img = render_input(pts, cam, po);
      const double secs = seconds_since(t0);
      const std::string png =
          (fs::path(dir) / (holes ? "points_hole_filled.png" : "points.png")).string();
      write_png(png, img);
      json j = error_json(compare_images(ref, img));
      j.str("png", png).num("seconds", secs);
      report.object(holes ? "points_hole_filled" : "points", j);
    }
    // Shadows and shading cost: one more image with the shadow pass.
    render_options so = o;
    so.fx.shadows = true;
    prog.step("rendering with shadows");
    t0 = clock_type::now();
    const image shadowed = render_input(in, cam, so);
    const std::string png = (fs::path(dir) / "reference_shadows.png").string();
    write_png(png, shadowed);
    json j;
    j.str("png", png).num("seconds", seconds_since(t0));
    report.object("shadows", j);
  }
  // 3. The point-octree (Pajarola 2003) over the points, drawn at τ = 1, 4, 16 px.
  {
    prog.step("building the point-octree");
    const point_cloud cloud =
        in.is_mesh()
            ? sample_surface(in.mesh, std::max<std::size_t>(in.mesh.num_vertices(), 20000), 1)
            : in.mesh.vertices;
    json oj;
    with_point_set(cloud, name, [&](const auto& pts) {
      const auto t = build_point_octree(pts);
      using tree = std::decay_t<decltype(t)>;
      oj.integer("nodes", static_cast<long long>(t.nodes().size()));
      oj.num("build_seconds", t.stats().seconds);
      oj.num("bytes_per_point_file",
             static_cast<double>(t.file_bytes()) / static_cast<double>(t.samples().size()));
      const view v(cam, t.origin());
      render_options lo = o;
      lo.fx.colour = tree::attrs.colour && o.fx.colour;
      for (const float tol : {1.0f, 4.0f, 16.0f}) {
        prog.step("rendering the point-octree at " + std::to_string(static_cast<int>(tol)) + " px");
        const traverse_options topt{.tolerance_px = tol,
                                    .backface_cull = true,
                                    .cull_volume = traverse_options::volume::view_cone};
        traverse_stats st;
        const auto start = clock_type::now();
        const image img = render<tree::attrs>(
            v, lo, [&](auto& sink) { st = traverse(t, v, topt, sink, point_octree_policy{}); });
        const double secs = seconds_since(start);
        const std::string png =
            (fs::path(dir) / ("point_octree_tau" + std::to_string(static_cast<int>(tol)) + ".png"))
                .string();
        write_png(png, img);
        json j = error_json(compare_images(ref, img));
        j.str("png", png).num("seconds", secs).integer("splats", static_cast<long long>(st.splats));
        oj.object("tau_" + std::to_string(static_cast<int>(tol)), j);
      }
      return 0;
    });
    report.object("point_octree", oj);
  }
  if (as_json) {
    std::cout << report.text() << "\n";
  } else {
    std::cout << "pbrlod demo: " << name << " (" << in.mesh.num_vertices() << " points, "
              << in.mesh.num_faces() << " faces) -> " << dir << "/\n"
              << report.text() << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pbrlod: level-of-detail hierarchies for point-based rendering (pbr_lod " +
               std::string(version()) + ")"};
  app.require_subcommand(1);
  bool as_json = false;

  std::string method, build_input, build_output;
  std::vector<std::string> params;
  auto* build = app.add_subcommand("build", "build a LOD hierarchy from a mesh or point cloud");
  build->add_option("--method", method, "point-octree, rho-grid, pop, pca-octree or pmr")
      ->required();
  build->add_option("--param", params, "k=v builder parameter (repeatable)")
      ->allow_extra_args(false)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  build->add_option("input", build_input, "mesh or point cloud file")->required();
  build->add_option("-o,--output", build_output, "hierarchy file to write (.lod)")->required();
  build->add_flag("--json", as_json, "print one JSON object");

  std::string render_input_path, render_output = "render.png";
  float tolerance = 1;
  view_args va;
  auto* render = app.add_subcommand("render", "render a hierarchy or an input file (full detail)");
  render->add_option("input", render_input_path, "OUT.lod or a mesh/point cloud file")->required();
  render->add_option("-o,--output", render_output, "PNG to write")->capture_default_str();
  render->add_option("--tolerance", tolerance, "screen-space tolerance in pixels")
      ->capture_default_str();
  add_view_options(render, va);
  render->add_flag("--json", as_json, "print one JSON object");

  std::string stats_input;
  auto* stats = app.add_subcommand("stats", "statistics of a hierarchy or an input file");
  stats->add_option("input", stats_input, "OUT.lod or a mesh/point cloud file")->required();
  stats->add_flag("--json", as_json, "print one JSON object");

  std::string cmp_a, cmp_b;
  auto* compare = app.add_subcommand("compare", "image error of B against reference A");
  compare->add_option("reference", cmp_a, "reference PNG")->required();
  compare->add_option("test", cmp_b, "PNG to compare")->required();
  compare->add_flag("--json", as_json, "print one JSON object");

  std::string demo_input, demo_dir = "pbrlod-demo";
  auto* demo = app.add_subcommand("demo", "render a generated scene (or INPUT) and report");
  demo->add_option("input", demo_input, "optional mesh or point cloud file");
  demo->add_option("-o,--output", demo_dir, "folder for the images")->capture_default_str();
  demo->add_flag("--json", as_json, "print one JSON object");

  CLI11_PARSE(app, argc, argv);
  try {
    if (*build) return cmd_build(method, build_input, build_output, params, as_json);
    if (*render) return cmd_render(render_input_path, va, tolerance, render_output, as_json);
    if (*stats) return cmd_stats(stats_input, as_json);
    if (*compare) return cmd_compare(cmp_a, cmp_b, as_json);
    if (*demo) return cmd_demo(demo_input, demo_dir, as_json);
  } catch (const pbr_lod::Error& e) {
    std::cerr << "pbrlod: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "pbrlod: unexpected error: " << e.what() << "\n";
    return 1;
  }
  return 2;
}
