// gl_viewer — an OpenGL 3.3 core host renderer: a Sink (through pbrlod's host_sink) that fills
// vertex buffers with one frame's cut and draws it with the CPU rasteriser's rules
// (raster/rasterizer.hpp), so that the two images of one cut can be compared pixel by pixel.
//
//   points     GL_POINTS, gl_PointSize = the square's side; the fragment shader keeps the
//              pixels whose centres lie in the CPU's half-open square (raster_square).
//   splats     one instanced quad per splat: the rectangle c ± u ± v in object space with
//              (s, t) = (±1, ±1) at its corners. Perspective-correct interpolation gives each
//              pixel centre the exact (s, t) of the splat-plane point it sees, and the fragment
//              shader keeps s² + t² ≤ 1: the exact perspective projection of the ellipse, as
//              raster_ellipse computes it, with the depth of the splat's plane.
//   triangles  GL_TRIANGLES with per-vertex normal and colour, shaded per fragment; textured
//              ones (POP leaves) sample their texture (GL_LINEAR, GL_REPEAT) for the colour.
//   Gaussians  one instanced quad each over the pixels where α ≥ 1/255, projected on the CPU by
//              raster/gaussians.hpp's project_gaussian (EWA, SH colour), sorted back to front
//              and blended "over": the CPU's front-to-back compositing in reverse order.
//
// Shading as the CPU rasteriser: Lambert with one directional light and ambient, two-sided
// (the normal turned towards the eye; for triangles, flipped on the back face), per primitive for
// points and splats, per pixel for triangles; colours rounded as it rounds them.
//
// Blending (render_options::fx.blending, the tool's default) as the CPU rasteriser does it,
// deferred (Botsch, Hornung, Zwicker & Kobbelt 2005): a visibility pass into an offscreen depth
// and colour target with points and splats pushed back by ε times their radius, an accumulation
// pass that sums w·colour, w·normal and w into four RGBA32F targets by additive blending (the
// fragments facing the eye and those facing away apart), and a normalisation pass that divides,
// shades the summed normal and writes colour and depth into the caller's framebuffer. Effects
// it does not draw: shadows, hole filling (see docs/gl_viewer.md).
//
// Needs a current OpenGL 3.3 core context (a GLFW window or the headless EGL context) for its
// whole life. No OpenGL type appears in this header.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "lod.hpp"

namespace gl_viewer {

using pbrlod_tool::host_attributes;

/// Primitives of the last frame, by kind.
struct frame_counts {
  std::size_t points = 0, splats = 0, triangles = 0, gaussians = 0;
  [[nodiscard]] std::size_t total() const { return points + splats + triangles + gaussians; }
};

class gl_renderer final : public pbrlod_tool::host_sink {
 public:
  /// Compiles the shaders and creates the buffers (throws std::runtime_error with the log).
  gl_renderer();
  ~gl_renderer() override;
  gl_renderer(const gl_renderer&) = delete;
  gl_renderer& operator=(const gl_renderer&) = delete;

  // host_sink: one frame's cut, appended to the vertex arrays.
  void begin(const pbr_lod::view& v, const pbr_lod::render_options& o,
             pbr_lod::attributes carried) override;
  void point(const pbr_lod::point_prim<host_attributes>& p) override;
  void splat(const pbr_lod::splat_prim<host_attributes>& s) override;
  void triangle(const pbr_lod::triangle_prim<host_attributes>& t) override;
  void textured_triangle(const pbr_lod::textured_triangle_prim<host_attributes>& t) override;
  void gaussian(const pbr_lod::gaussian_prim& g) override;

  /// Uploads the frame's arrays and draws them into the bound framebuffer, whose size must be
  /// the view's. Returns the GPU time (glFinish included) in seconds.
  double draw();
  /// The bound framebuffer as an image: colour, coverage and eye-space depth per pixel, top row
  /// first (the CPU image's convention).
  [[nodiscard]] pbr_lod::image read_image() const;
  [[nodiscard]] const frame_counts& counts() const { return counts_; }

 private:
  void draw_gaussians();
  struct impl;
  std::unique_ptr<impl> d_;
  frame_counts counts_;
};

}  // namespace gl_viewer
