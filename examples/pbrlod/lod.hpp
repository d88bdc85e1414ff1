// pbrlod — every method's hierarchy behind one interface, so that `build`, `render`, `stats`
// and `demo` are written once. A method contributes only what is its own (one
// <method>_method.cpp each): its build parameters, how one frame traverses it (tolerance
// metric, culling, policy) and its stats fields.
#pragma once

#include <algorithm>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/traverse/sink.hpp"
#include "pbr_lod/traverse/traverse.hpp"
#include "pbr_lod/traverse/widening_sink.hpp"
#include "tool.hpp"

namespace pbrlod_tool {

/// One frame of a hierarchy: the image, the traversal's counts, the time of LOD selection and
/// rasterisation together (one pass), the effects drawn, and the method's own `render --json`
/// fields.
struct frame {
  image img;
  traverse_stats st;
  double seconds = 0;
  /// LOD selection alone (a traversal into a counting sink), when the request asked for it.
  double traverse_seconds = std::numeric_limits<double>::quiet_NaN();
  effects fx;
  json extra;
  /// When the request asked for them: the positions of the samples of this view's cut with
  /// nothing culled (splat and point centres, triangles' vertices), relative to `origin`.
  std::vector<vec3f> samples;
  vec3d origin = vec3d::Zero();
  std::size_t sample_nodes = 0;  ///< nodes (inner and leaves) that cut emitted
};

/// The attribute set every hierarchy's primitives reach a host renderer in (host_sink).
inline constexpr attributes host_attributes = with_normals_colours;

/// A host renderer behind one type for every method (examples/gl_viewer): instead of the CPU
/// rasteriser, draw_frame() sends it the frame's cut, widened to host_attributes. A Sink of
/// host_attributes through virtual calls: one call per primitive, while the traversal itself
/// stays the one the CPU frame compiles (into a buffer_sink of the hierarchy's own attributes).
class host_sink {
 public:
  virtual ~host_sink() = default;
  /// Called once per frame before its primitives: the view they are relative to (the
  /// hierarchy's origin), the render options with the effects the hierarchy can apply (as the
  /// CPU frame would), and the attributes that are real (others are zero).
  virtual void begin(const view& v, const render_options& o, attributes carried) = 0;
  virtual void point(const point_prim<host_attributes>& p) = 0;
  virtual void splat(const splat_prim<host_attributes>& s) = 0;
  virtual void triangle(const triangle_prim<host_attributes>& t) = 0;
  /// A texture-mapped triangle (POP's leaves from a textured mesh); a host that does not
  /// texture draws the triangle_prim inside.
  virtual void textured_triangle(const textured_triangle_prim<host_attributes>& t) {
    triangle(t.triangle);
  }
  /// A 3-D Gaussian (a Gaussian hierarchy's cut: the primitives of that frame); a host that does
  /// not draw Gaussians gets its ellipse splat (as_splat_prim, as the z-buffer rasteriser does).
  virtual void gaussian(const gaussian_prim& g) { splat(as_splat_prim<host_attributes>(g)); }
};

/// What one frame is drawn from.
struct frame_request {
  camera cam;
  view_args view;  ///< its effects list; the camera is already made
  /// Pixels for most methods; PMR's factor; the PCA octree's point size.
  float tolerance = 1;
  std::uint64_t seed = 1;  ///< methods that generate points
  /// Also time LOD selection alone (one more traversal, into a counting sink).
  bool time_traversal = false;
  /// When set, the cut goes to this host renderer and the frame's image stays empty; its
  /// seconds are LOD selection plus the hand-over. Effects a host does not draw (shadows, hole
  /// filling, blending) are its own business.
  host_sink* host = nullptr;
  /// Also collect frame::samples (one more traversal, culling nothing): the sweep's
  /// object-space error.
  bool collect_samples = false;
  /// > 0: the samples also hold points on each triangle at about this spacing (world units).
  float sample_spacing = 0;
};

/// Times a traversal of h into a counting sink: LOD selection without rasterisation.
template <class H, class Policy>
double traversal_seconds(const H& h, const view& v, const traverse_options& t,
                         const Policy& policy) {
  counting_sink<H::attrs> counts;
  const auto t0 = clock_type::now();
  (void)traverse(h, v, t, counts, policy);
  return seconds_since(t0);
}

/// The cut of h sent to r.host (see frame_request::host).
template <effects Compiled, class H, class Policy>
frame host_frame(const H& h, const view& v, const render_options& o, const traverse_options& t,
                 const Policy& policy, host_sink& host) {
  frame f;
  render_options ho = o;
  ho.fx = o.fx & applicable_effects(Compiled, H::attrs);
  f.fx = ho.fx;
  const auto t0 = clock_type::now();
  host.begin(v, ho, H::attrs);
  thread_local buffer_sink<H::attrs> cut;  // kept from frame to frame, as render() keeps its own
  cut.clear();
  f.st = traverse(h, v, t, cut, policy);
  struct forward {
    host_sink& out;
    void point(const point_prim<host_attributes>& p) { out.point(p); }
    void splat(const splat_prim<host_attributes>& s) { out.splat(s); }
    void triangle(const triangle_prim<host_attributes>& q) { out.triangle(q); }
    void textured_triangle(const textured_triangle_prim<host_attributes>& q) {
      out.textured_triangle(q);
    }
  } fw{host};
  widening_sink<H::attrs, host_attributes, forward> widen{fw};
  cut.replay(widen);
  f.seconds = seconds_since(t0);
  return f;
}

/// Appends points on triangle abc other than its corners: a barycentric grid of
/// ⌈longest edge / spacing⌉ steps (none when the triangle is smaller than the spacing).
inline void append_triangle_samples(std::vector<vec3f>& out, const vec3f& a, const vec3f& b,
                                    const vec3f& c, double spacing) {
  const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
  const int n = spacing > 0 ? static_cast<int>(std::ceil(longest / spacing)) : 0;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j) {
      if ((i == 0 && j == 0) || (i == n && j == 0) || (i == 0 && j == n)) continue;  // corners
      const float u = static_cast<float>(i) / static_cast<float>(n),
                  w = static_cast<float>(j) / static_cast<float>(n);
      out.push_back(a + u * (b - a) + w * (c - a));
    }
}

/// Positions of the primitives a traversal emits: point and splat centres, and each triangle's
/// vertices and, when spacing > 0, points on it (append_triangle_samples).
template <attributes A>
struct sample_sink {
  std::vector<vec3f>* out;
  float spacing = 0;
  void point(const point_prim<A>& p) { out->push_back(p.position); }
  void splat(const splat_prim<A>& s) { out->push_back(s.centre); }
  void triangle(const triangle_prim<A>& t) {
    out->insert(out->end(), t.p.begin(), t.p.end());
    append_triangle_samples(*out, t.p[0], t.p[1], t.p[2], spacing);
  }
};

/// f.samples and f.origin when r asks for them: the cut this view and tolerance select, with
/// frustum and back-face culling off (an object-space error over the whole model, at the level
/// each part gets from this view). Vertices shared by triangles are counted once.
template <class H, class Policy>
void collect_samples(frame& f, const H& h, const view& v, traverse_options t, const Policy& policy,
                     const frame_request& r, const vec3d& origin) {
  if (!r.collect_samples) return;
  t.frustum_cull = false;
  t.backface_cull = false;
  sample_sink<H::attrs> sink{&f.samples, r.sample_spacing};
  const traverse_stats st = traverse(h, v, t, sink, policy);
  f.sample_nodes = st.emitted_nodes + st.emitted_leaves;
  if (st.triangles > 0) {
    const auto less = [](const vec3f& a, const vec3f& b) {
      return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
    };
    std::sort(f.samples.begin(), f.samples.end(), less);
    f.samples.erase(std::unique(f.samples.begin(), f.samples.end()), f.samples.end());
  }
  f.origin = origin;
}

/// A method's policy for view v: the policy itself, or, for a policy built for one view (the
/// ρ-grid's tables), what a callable `policy(v)` makes of it.
template <class Policy>
decltype(auto) policy_for(const Policy& policy, const view& v) {
  if constexpr (std::is_invocable_v<const Policy&, const view&>)
    return policy(v);
  else
    return (policy);
}

/// The frame of h through traverse() with the method's options and policy, timed as one pass
/// (and its samples when r asks: collect_samples), or, with r.host, the cut handed to that host
/// renderer. `Compiled` narrows the effects compiled in (a method that never shadows, say).
/// `policy` may be a callable view → policy (policy_for). With o.supersample = k the frame is
/// drawn through the k× view with k × the tolerance — the cut of v — and samples are collected
/// from that cut.
/// `origin`: what h's coordinates are relative to.
template <effects Compiled = all_effects, class H, class Policy>
frame draw_frame(const H& h, const view& v, const render_options& o, const traverse_options& t,
                 const Policy& policy, const frame_request& r, const vec3d& origin) {
  if (r.host) return host_frame<Compiled>(h, v, o, t, policy_for(policy, v), *r.host);
  frame f;
  f.fx = o.fx;
  const supersampled_cut cut(v, t, o.supersample);  // supersampled, still v's cut
  const view& dv = cut.drawn;
  const traverse_options& tk = cut.options;
  decltype(auto) pd = policy_for(policy, dv);
  const auto t0 = clock_type::now();
  f.img = render<H::attrs, Compiled>(
      v, o, [&](auto& sink, const view& drawn) { f.st = traverse(h, drawn, tk, sink, pd); });
  f.seconds = seconds_since(t0);
  if (r.time_traversal) f.traverse_seconds = traversal_seconds(h, dv, tk, pd);
  collect_samples(f, h, dv, tk, pd, r, origin);
  return f;
}

/// Every point a hierarchy's nodes hold, each with its node's depth (an inner node's
/// representative at its depth, a leaf's samples at the leaf's): `export --format copc`.
struct levelled_points {
  point_cloud cloud;                 ///< world = origin + position; normals, colours if it has them
  std::vector<std::uint8_t> levels;  ///< per point (depths beyond 255 are 255)
  std::size_t nodes = 0;
  std::size_t leaf_samples = 0;  ///< points the leaves emit (the rest are inner nodes')
  bool snapped = false;          ///< inner nodes' points replaced by samples of their subtree
};

/// Collects what each node of h emits (point and splat centres, with the normal and colour its
/// attributes carry) by a walk over every node. `framing` gives the view emit() is called with
/// (a view matters only to screen-space emitters, which send a point_prim to this sink). With
/// `snap`, each point of an inner node is replaced by the leaf sample of its subtree nearest to
/// it: a node's representative sits at its samples' mean, which on a curved part (an ear) lies
/// off the surface, and a COPC reader draws coarse levels together with the fine ones. Throws
/// InvalidArgument when a node emits triangles: their vertices are no point set of a level.
template <class H>
levelled_points collect_levelled_points(const H& h, std::pair<vec3d, double> framing,
                                        const std::string& name, bool snap) {
  static constexpr attributes A = H::attrs;
  levelled_points inner, leaf;  // apart: in preorder, a subtree's samples are one run of `leaf`
  inner.cloud.origin = leaf.cloud.origin = h.origin();
  inner.snapped = snap;
  if (h.empty()) return inner;
  const view v(make_camera(framing.first, framing.second, view_args{}), h.origin());
  levelled_points* to = &leaf;
  std::uint8_t depth = 0;
  std::size_t triangles = 0;
  const auto add = [&](const vec3f& p, const auto& prim) {
    to->cloud.positions.push_back(p);
    if constexpr (A.normal) to->cloud.normals.push_back(prim.normal);
    if constexpr (A.colour) to->cloud.colours.push_back(prim.colour);
    to->levels.push_back(depth);
  };
  struct collect {
    decltype(add)& put;
    std::size_t& triangles;
    void point(const point_prim<A>& p) { put(p.position, p); }
    void splat(const splat_prim<A>& q) { put(q.centre, q); }
    void triangle(const triangle_prim<A>&) { ++triangles; }
  } sink{add, triangles};
  struct item {
    typename H::node_id n;
    unsigned depth;
    bool exit = false;
    std::size_t inner0 = 0, inner1 = 0, leaf0 = 0;
  };
  std::vector<std::pair<std::size_t, std::size_t>> runs;  // per inner point: its subtree's samples
  std::vector<item> stack{{h.root(), 0u}};
  while (!stack.empty()) {
    const item it = stack.back();
    stack.pop_back();
    if (it.exit) {
      for (std::size_t i = it.inner0; i < it.inner1; ++i) runs[i] = {it.leaf0, leaf.levels.size()};
      continue;
    }
    depth = static_cast<std::uint8_t>(std::min(it.depth, 255u));
    to = h.is_leaf(it.n) ? &leaf : &inner;
    const std::size_t first = inner.levels.size();
    h.emit(it.n, v, sink);
    ++inner.nodes;
    if (triangles > 0)
      throw InvalidArgument(name + ": its nodes hold triangles; COPC holds points");
    if (h.is_leaf(it.n)) continue;
    runs.resize(inner.levels.size());
    stack.push_back({it.n, it.depth, true, first, inner.levels.size(), leaf.levels.size()});
    for (const auto c : h.children(it.n)) stack.push_back({c, it.depth + 1});
  }
  if (snap)  // each inner point against its subtree's samples: N × depth distances in all
    pbr_lod::detail::parallel_chunks(
        runs.size(), pbr_lod::resolve_threads(0), 256, [&](std::size_t lo, std::size_t hi) {
          for (std::size_t i = lo; i < hi; ++i) {
            const auto [b, e] = runs[i];
            std::size_t best = e;
            float best_d = std::numeric_limits<float>::infinity();
            for (std::size_t j = b; j < e; ++j)
              if (const float d =
                      (leaf.cloud.positions[j] - inner.cloud.positions[i]).squaredNorm();
                  d < best_d) {
                best_d = d;
                best = j;
              }
            if (best == e) continue;  // a subtree without samples keeps its own point
            inner.cloud.positions[i] = leaf.cloud.positions[best];
            if constexpr (A.normal) inner.cloud.normals[i] = leaf.cloud.normals[best];
            if constexpr (A.colour) inner.cloud.colours[i] = leaf.cloud.colours[best];
          }
        });
  inner.leaf_samples = leaf.levels.size();
  const auto append = [](auto& a, const auto& b) { a.insert(a.end(), b.begin(), b.end()); };
  append(inner.cloud.positions, leaf.cloud.positions);
  append(inner.cloud.normals, leaf.cloud.normals);
  append(inner.cloud.colours, leaf.cloud.colours);
  append(inner.levels, leaf.levels);
  return inner;
}

/// A built or loaded hierarchy as the tool sees it.
class lod {
 public:
  virtual ~lod() = default;
  /// The world-space bounding sphere of the input it was built from: `render` frames it as it
  /// frames the input itself, so an input and its hierarchy share a camera.
  [[nodiscard]] virtual std::pair<vec3d, double> input_bounds() const = 0;
  /// One frame, with the effects of `r.view.effects_list`.
  [[nodiscard]] virtual frame draw(const frame_request& r) const = 0;
  /// `stats --json` and `build --json` fields.
  [[nodiscard]] virtual json stats(const std::string& path) const = 0;
  virtual void save(const std::string& path) const = 0;
  [[nodiscard]] virtual std::size_t file_bytes() const = 0;
  /// Samples at full detail (input points, mesh vertices, ρ-grid cells): bytes per sample.
  [[nodiscard]] virtual std::size_t samples() const = 0;
  /// Its nodes' points by level (collect_levelled_points); `name` for messages.
  [[nodiscard]] virtual levelled_points points_by_level(const std::string& name,
                                                        bool snap) const = 0;
};

/// lod over a hierarchy H and a method M that knows how to frame, draw and describe it (and to
/// save it and count its file bytes, where H's own save() / file_bytes() do not do). M may hold
/// state of its own (the ρ-grid's file layout, PMR's build time).
template <class M, class H>
class lod_of final : public lod {
 public:
  lod_of(M m, H h) : m_(std::move(m)), h_(std::move(h)) {}
  [[nodiscard]] std::pair<vec3d, double> input_bounds() const override {
    return m_.input_bounds(h_);
  }
  [[nodiscard]] frame draw(const frame_request& r) const override { return m_.draw(h_, r); }
  [[nodiscard]] json stats(const std::string& path) const override { return m_.stats(h_, path); }
  void save(const std::string& path) const override {
    if constexpr (requires { m_.save(h_, path); })
      m_.save(h_, path);
    else
      h_.save(path);
  }
  [[nodiscard]] std::size_t file_bytes() const override {
    if constexpr (requires { m_.file_bytes(h_); })
      return m_.file_bytes(h_);
    else
      return h_.file_bytes();
  }
  [[nodiscard]] std::size_t samples() const override { return m_.samples(h_); }
  [[nodiscard]] levelled_points points_by_level(const std::string& name, bool snap) const override {
    if constexpr (requires { m_.points_by_level(h_, name, snap); })
      return m_.points_by_level(h_, name, snap);
    else if constexpr (Hierarchy<H>)
      return collect_levelled_points(h_, m_.input_bounds(h_), name, snap);
    else
      throw InvalidArgument(name + ": this method's hierarchy has no points by level to export");
  }

 private:
  M m_;
  H h_;
};

/// What the methods of chunked folders share: the samples are the input's points, the bytes the
/// folder's files, and the folder is written by the build (save() does not copy it elsewhere).
struct chunked_folder {
  template <class H>
  std::size_t samples(const H& h) const {
    return static_cast<std::size_t>(h.input_points());
  }
  template <class H>
  std::size_t file_bytes(const H& h) const {
    return static_cast<std::size_t>(h.file_bytes());
  }
  template <class H>
  void save(const H&, const std::string&) const {}
};

template <class M, class H>
std::unique_ptr<lod> make_lod(M m, H&& h) {
  return std::make_unique<lod_of<M, std::decay_t<H>>>(std::move(m), std::forward<H>(h));
}

/// The object-space error of a cut: `fwd` from its samples to the input's surface (a cloud's
/// points; a mesh's vertices and points on its triangles), `bwd` from the input's points to
/// the samples (how well the cut covers them).
struct object_error {
  one_sided_distance fwd, bwd;
  [[nodiscard]] double symmetric() const { return std::max(fwd.max, bwd.max); }
};

/// object_error of a cut (frame::samples, relative to `origin`): `surface` indexed by
/// `surface_index`, and `points`, both relative to `ref_origin`. The samples are rebased into
/// that frame in double; distances are exact nearest neighbours (raster/metrics.hpp).
inline object_error cut_error(const knn_index& surface_index, std::span<const vec3f> points,
                              const vec3d& ref_origin, std::span<const vec3f> samples,
                              const vec3d& origin) {
  const vec3d shift = origin - ref_origin;
  std::vector<vec3f> cut(samples.size());
  for (std::size_t i = 0; i < cut.size(); ++i)
    cut[i] = (samples[i].cast<double>() + shift).cast<float>();
  return {distance_to(cut, surface_index), distance_to(points, knn_index(cut))};
}

/// The bounding sphere of world-space positions stored relative to `origin`.
inline std::pair<vec3d, double> bounds_of(const vec3d& origin, std::span<const vec3f> p) {
  const sphere s = bounding_sphere_about_box_centre(p);
  return {origin + s.centre.cast<double>(), static_cast<double>(s.radius)};
}

}  // namespace pbrlod_tool
