// pbrlod — the command-line tool's shared parts: JSON output, progress, inputs, views, builder
// parameters, and the table of build methods (one source file per method under examples/pbrlod/).
#pragma once

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "pbr_lod/builders/chunked.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/gaussians.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/point_source.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/effects.hpp"
#include "pbr_lod/raster/image.hpp"
#include "pbr_lod/raster/metrics.hpp"

namespace pbrlod_tool {
using namespace pbr_lod;

using clock_type = std::chrono::steady_clock;
inline double seconds_since(clock_type::time_point t0) {
  return std::chrono::duration<double>(clock_type::now() - t0).count();
}

// ---- a minimal JSON object writer (one object on one line; numbers, strings, nested objects).
// A key written twice throws std::logic_error: a JSON reader keeps one of two equal keys at its
// own choice, so a repeated key is a bug of the report, not something to print.
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
  /// A value already written as JSON text (an array, say).
  json& raw(const std::string& k, const std::string& v) {
    key(k);
    out_ += v;
    return *this;
  }
  /// Appends the fields of another object (after this one's); throws as a repeated key does.
  json& merge(const json& other) {
    for (const auto& k : other.keys_) claim(k);
    if (!other.out_.empty()) out_ += (out_.empty() ? "" : ",") + other.out_;
    return *this;
  }
  [[nodiscard]] std::string text() const { return "{" + out_ + "}"; }

 private:
  void key(const std::string& k) {
    claim(k);
    if (!out_.empty()) out_ += ",";
    out_ += quote(k) + ":";
  }
  void claim(const std::string& k) {
    if (std::find(keys_.begin(), keys_.end(), k) != keys_.end())
      throw std::logic_error("json: the key \"" + k + "\" is written twice");
    keys_.push_back(k);
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
  std::vector<std::string> keys_;  ///< written so far, to refuse a repeated one
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

/// True on a terminal (progress lines are drawn only there, on stderr).
inline bool interactive(bool as_json) {
  return !as_json && isatty(STDOUT_FILENO) && isatty(STDERR_FILENO);
}

// ---- inputs
/// A .lod file or a chunked build's folder (a hierarchy written by `pbrlod build`). A folder that
/// is not a finished chunked build is a FormatError saying what it is (check_chunked_folder).
bool is_hierarchy_file(const std::string& path);

/// The first 8 bytes (the method's magic) and the u32 flags after the u32 version of a .lod
/// file. Throws IoError / FormatError.
struct lod_header {
  std::string magic;
  std::uint32_t version = 0, flags = 0;
};
lod_header peek_lod(const std::string& path);

struct loaded_input {
  triangle_mesh mesh;  // faces empty for a point cloud
  /// A Gaussian scene (io/gaussians.hpp): its Gaussians, and in `mesh` their means with their
  /// view-independent colours (what the point builders build from).
  gaussian_cloud gaussians;
  read_report report;
  double read_seconds = 0;
  [[nodiscard]] bool is_mesh() const { return !mesh.faces.empty(); }
  [[nodiscard]] bool is_gaussians() const { return !gaussians.empty(); }
};
/// Reads a mesh (.ply/.obj/.off), a Gaussian scene (a 3DGS .ply, .splat, .spz) or a point cloud
/// (.pcd/.las, or a PLY without faces); warnings
/// go to stderr. Throws on a file without points. Also the generated inputs: "generated:N" (the
/// demo scene, make_demo_scene(N)), "generated-hard:N" (make_hard_cases_scene(N)),
/// "generated-points:N[:normals]" and "generated-gaussians:N" (make_gaussian_scene(N), SH degree
/// 3).
loaded_input load(const std::string& path);

/// World-space bounding sphere (centre of the box, radius to the farthest point), in double.
std::pair<vec3d, double> world_bounds(const point_cloud& c);

// ---- views
struct view_args {
  std::string view = "30,20,3";
  std::string size = "512x512";
  std::string up = "y";
  std::string effects_list = "default";
  int supersample = 1;  ///< render_options::supersample
  /// Gaussian hierarchies: gaussian_policy::merged_lowpass_px2 (render, export).
  float merged_lowpass = pbr_lod::gaussian_policy{}.merged_lowpass_px2;
};
std::vector<double> parse_numbers(const std::string& s, char sep, std::size_t n, const char* what);
/// The orbit camera of --view/--size/--up around the bounding sphere of c.
camera make_camera(const point_cloud& c, const view_args& a);
/// The same around a world-space bounding sphere (a hierarchy's recorded input bounds).
camera make_camera(const vec3d& centre, double radius, const view_args& a);
/// --effects for an input file drawn at full detail: 'default' = shading where it has normals
/// (or faces), colour where it has colours, and a point cloud's splats blended.
render_options make_render_options(const loaded_input& in, const view_args& a);
/// --effects for a hierarchy: 'default' = shading, colour when the hierarchy has colours, and
/// blending (of splats and points; a frame of triangles only is drawn unblended).
render_options lod_render_options(const view_args& a, bool has_colour);
json error_json(const image_error& e);

// ---- builder parameters (--param key=value)
class params {
 public:
  /// Throws InvalidArgument on an item without '='.
  explicit params(const std::vector<std::string>& items);
  long integer(const std::string& key, long fallback, long lo, long hi);
  double number(const std::string& key, double fallback, double lo, double hi);
  std::string choice(const std::string& key, const std::string& fallback,
                     const std::vector<std::string>& choices);
  bool flag(const std::string& key, bool fallback);
  /// A size in bytes: a whole number with an optional K, M, G or T suffix (powers of 1024),
  /// e.g. memory=4G; nullopt when the key is absent.
  std::optional<std::uint64_t> bytes(const std::string& key);
  /// "x,y,z" (three finite numbers), or nullopt when the key is absent.
  std::optional<std::array<double, 3>> point(const std::string& key);
  /// Throws InvalidArgument naming the first parameter no getter asked for.
  void finish(const std::string& method, const std::string& expected) const;

 private:
  std::map<std::string, std::string> m_;
};

/// `--param memory=SIZE` and `chunk_points=N`, the knobs every chunked (out-of-core) build shares
/// (builders/chunked.hpp). memory is the whole build's budget: what one process may use with every
/// chunk it builds at once (each rank of `--distributed` is given the same), and the chunks are
/// made small enough to fit it; chunk_points sets the largest chunk instead.
template <class BuilderOptions>
void chunked_params(params& m, chunked_options<BuilderOptions>& o) {
  if (const auto b = m.bytes("memory")) o.memory_bytes = *b;
  o.chunk_points = static_cast<std::uint64_t>(m.integer("chunk_points", 0, 0, (1L << 31) - 1));
}

/// A "[ 12.3s] building <what> 45%" progress callback, or an empty one off a terminal.
std::function<bool(double)> progress_callback(const std::string& what, bool on_terminal);

// ---- build methods
class lod;  // lod.hpp: a built or loaded hierarchy behind one interface

/// The input of a build: a file, read on first use (after the method has checked its
/// parameters, so a bad --param fails before a long read), or a scene already in memory.
class build_input {
 public:
  explicit build_input(std::string path) : name_(std::move(path)) {}
  build_input(loaded_input in, std::string name) : name_(std::move(name)), in_(std::move(in)) {}
  [[nodiscard]] const std::string& name() const { return name_; }
  /// Reads the file once (throws as load()).
  [[nodiscard]] const loaded_input& get() const {
    if (!in_) in_ = load(name_);
    return *in_;
  }

 private:
  std::string name_;
  mutable std::optional<loaded_input> in_;
};

/// This process's part in a distributed build (chunked_options::distributed, builders/chunked.hpp).
struct distributed_rank {
  int rank = 0, ranks = 1;
  std::function<void()> barrier;
};

/// One builder as the tool sees it. A method without build is listed but not available.
struct method_entry {
  std::string name, paper;
  std::string magic;              ///< the 8 bytes its .lod files start with
  std::string dir_magic;          ///< its chunked folders' top file's, when it builds them
  bool builds_from_mesh = false;  ///< the demo gives it the mesh, not the sampled points
  /// Checks the --param items, then reads the input and builds. Throws InvalidArgument naming
  /// a bad parameter or an input the method cannot build from.
  std::unique_ptr<lod> (*build)(const std::vector<std::string>& params, const build_input& in,
                                bool on_terminal) = nullptr;
  /// Reads one of its .lod files or chunked folders (throws IoError / FormatError).
  std::unique_ptr<lod> (*load)(const std::string& path) = nullptr;
  /// Builds out of core into the folder `output` (`--param memory=SIZE` or `chunk_points=N`),
  /// its build figures added to `report`; shared among ranks when `part` is given. Null when
  /// the method has no chunked build.
  std::unique_ptr<lod> (*build_chunked)(const std::vector<std::string>& params,
                                        const std::string& input, const std::string& output,
                                        bool on_terminal, json& report,
                                        const distributed_rank* part) = nullptr;
  std::vector<float> demo_tolerances;          ///< what `demo` draws, coarse to fine
  std::string tolerance_key = "tolerance_px";  ///< the --tolerance field in `render --json`
  /// What --tolerance (traverse_options::tolerance_px) means for this method, in one line: the
  /// one place it is said (`pbrlod render --help`, docs/traversal.md's table).
  std::string tolerance_means;
  /// A point builder that, given a mesh, draws its vertices as splats from the faces around
  /// them (core/mesh_splats.hpp): the sweep and `papers` pass it the mesh, not the vertices.
  bool splats_from_mesh = false;
};
const std::vector<method_entry>& methods();
/// The method that wrote a .lod file, by its magic (throws FormatError for an unknown one).
const method_entry& lod_method(const std::string& path);

// One per builder of cmake/builders.cmake, each in its examples/pbrlod/ID_method.cpp.
#define PBRLOD_METHOD(id) method_entry id##_method();
#include "methods.inc"
#undef PBRLOD_METHOD

/// Whether the --param items ask for a chunked build (memory=SIZE or chunk_points=N).
bool wants_chunked_build(const std::vector<std::string>& params);
/// The entry of a method by name (throws InvalidArgument naming the methods).
const method_entry& method_named(const std::string& name);
/// A chunked build's report fields (chunked_build_report) into `report`.
void chunked_report_json(const chunked_build_report& r, json& report);
/// An input read block by block: `generated-points:N` (N points of a generated surface with
/// colours, made from their indices; `generated-points:N:normals` with its normals too), or a
/// point file.
std::unique_ptr<point_source> open_build_source(const std::string& input);
/// N of "PREFIXN" such as "generated-gaussians:N" (1 ≤ N ≤ 2³¹), else InvalidArgument.
std::size_t generated_count(const std::string& spec, const std::string& prefix);

/// Calls f(point_set<A>) with A the attributes the cloud actually has (normals, colours,
/// ellipses: eight instantiations), so a builder is compiled for exactly what the scene has.
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

}  // namespace pbrlod_tool
