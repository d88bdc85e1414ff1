// pbrlod — every method's hierarchy behind one interface, so that `build`, `render`, `stats`
// and `demo` are written once. A method contributes only what is its own (one
// <method>_method.cpp each): its build parameters, how one frame traverses it (tolerance
// metric, culling, policy) and its stats fields.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/traverse/traverse.hpp"
#include "tool.hpp"

namespace pbrlod_tool {

/// One frame of a hierarchy: the image, the traversal's counts, the time of LOD selection and
/// rasterisation together (one pass), the effects drawn, and the method's own `render --json`
/// fields.
struct frame {
  image img;
  traverse_stats st;
  double seconds = 0;
  effects fx;
  json extra;
};

/// The frame of h through traverse() with the method's options and policy, timed as one pass.
/// `Compiled` narrows the effects compiled in (a method that never shadows, say).
template <effects Compiled = all_effects, class H, class Policy>
frame draw_frame(const H& h, const view& v, const render_options& o, const traverse_options& t,
                 const Policy& policy) {
  frame f;
  f.fx = o.fx;
  const auto t0 = clock_type::now();
  f.img =
      render<H::attrs, Compiled>(v, o, [&](auto& sink) { f.st = traverse(h, v, t, sink, policy); });
  f.seconds = seconds_since(t0);
  return f;
}

/// A built or loaded hierarchy as the tool sees it.
class lod {
 public:
  virtual ~lod() = default;
  /// The world-space bounding sphere of the input it was built from: `render` frames it as it
  /// frames the input itself, so an input and its hierarchy share a camera.
  [[nodiscard]] virtual std::pair<vec3d, double> input_bounds() const = 0;
  /// One frame at `tolerance` (pixels for most methods; PMR's factor, the PCA octree's point
  /// size), with the effects of `va.effects_list`. `seed`: methods that generate points.
  [[nodiscard]] virtual frame draw(const camera& cam, const view_args& va, float tolerance,
                                   std::uint64_t seed) const = 0;
  /// `stats --json` and `build --json` fields.
  [[nodiscard]] virtual json stats(const std::string& path) const = 0;
  virtual void save(const std::string& path) const = 0;
  [[nodiscard]] virtual std::size_t file_bytes() const = 0;
  /// Samples at full detail (input points, mesh vertices, ρ-grid cells): bytes per sample.
  [[nodiscard]] virtual std::size_t samples() const = 0;
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
  [[nodiscard]] frame draw(const camera& cam, const view_args& va, float tolerance,
                           std::uint64_t seed) const override {
    return m_.draw(h_, cam, va, tolerance, seed);
  }
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

 private:
  M m_;
  H h_;
};

template <class M, class H>
std::unique_ptr<lod> make_lod(M m, H&& h) {
  return std::make_unique<lod_of<M, std::decay_t<H>>>(std::move(m), std::forward<H>(h));
}

/// The bounding sphere of world-space positions stored relative to `origin`.
inline std::pair<vec3d, double> bounds_of(const vec3d& origin, std::span<const vec3f> p) {
  const sphere s = bounding_sphere_about_box_centre(p);
  return {origin + s.centre.cast<double>(), static_cast<double>(s.radius)};
}

}  // namespace pbrlod_tool
