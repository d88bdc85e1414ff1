// gl_viewer — the OpenGL 3.3 core renderer (gl_renderer.hpp). GL entry points come from
// libOpenGL (glvnd), which dispatches to whichever context is current: a GLFW/GLX window or the
// headless EGL context, with no loader library.
#define GL_GLEXT_PROTOTYPES 1
#include "gl_renderer.hpp"

#include <GL/glcorearb.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "pbr_lod/raster/gaussians.hpp"

namespace gl_viewer {
namespace {

// Every shader projects with the CPU's camera: eye-space (x, y, z) along the view's right, up
// and forward axes, clip = (f·x / (W/2), f·y / (H/2), a·z + b, z) with f the focal length in
// pixels. Window y grows up (the CPU's image grows down); read_image() flips the rows.
constexpr const char* kCommon = R"(#version 330 core
uniform vec3 eye, right_axis, up_axis, forward_axis;
uniform vec4 proj;  // f / (W/2), f / (H/2), a, b
uniform vec3 light_dir;
uniform float ambient;
uniform int shading, colouring, cull;
uniform vec3 flat_colour;  // 0..255
// Blending (rasterizer.hpp, Botsch et al. 2005): 0 = off; 1 = the visibility pass (points and
// splats pushed back along their view rays by epsilon times their radius); 2 = the
// accumulation pass (weighted colour, normal and weight summed into four float targets: the
// fragments facing the eye in 0 and 1, those facing away in 2 and 3).
uniform int blend_pass;
uniform float blend_epsilon;
)";

// Fragment shaders only: the outputs.
constexpr const char* kFragmentCommon = R"(
// The accumulation pass's outputs for one fragment of weight w, albedo (0..255) and unit
// normal turned towards the eye.
layout(location = 0) out vec4 out_colour;
layout(location = 1) out vec4 out_normal;
layout(location = 2) out vec4 out_away_colour;
layout(location = 3) out vec4 out_away_normal;
void accumulate(float w, vec3 albedo, vec3 n, bool away) {
  vec4 c = vec4(w * albedo, w), m = vec4(w * n, 0.0);
  out_colour = away ? vec4(0.0) : c;
  out_normal = away ? vec4(0.0) : m;
  out_away_colour = away ? c : vec4(0.0);
  out_away_normal = away ? m : vec4(0.0);
}
)";

constexpr const char* kCommonFunctions = R"(
vec3 to_eye(vec3 p) {
  vec3 d = p - eye;
  return vec3(dot(d, right_axis), dot(d, up_axis), dot(d, forward_axis));
}
vec4 project(vec3 p) {
  vec3 e = to_eye(p);
  return vec4(proj.x * e.x, proj.y * e.y, proj.z * e.z + proj.w, e.z);
}
// raster/detail/raster_core.hpp lambert(): ambient + (1 - ambient) max(0, n.l), in [0, 1].
float lambert(vec3 n) {
  return clamp(ambient + (1.0 - ambient) * max(0.0, dot(n, light_dir)), 0.0, 1.0);
}
// The colour of a point or splat (rasterizer::shade): albedo, lit two-sided; rounded as
// scale_colour() rounds; 0..255.
vec3 shade_flat(vec3 colour, vec3 n, vec3 to_prim) {
  vec3 albedo = colouring != 0 ? colour : flat_colour;
  if (shading == 0) return albedo;
  float lit = lambert(dot(n, to_prim) > 0.0 ? -n : n);
  return floor(albedo * lit + 0.5);
}
)";

constexpr const char* kPointVs = R"(
layout(location = 0) in vec3 position;
layout(location = 1) in float size_px;
layout(location = 2) in vec3 normal;
layout(location = 3) in vec3 colour;
uniform vec2 viewport;
uniform float focal_px;
flat out vec3 frag_colour;
flat out vec2 centre_px;  // window coordinates of the projected centre
flat out float half_side;
flat out vec3 frag_albedo;  // accumulation: albedo and the normal turned to the eye
flat out vec3 frag_normal;
flat out float frag_away;
void main() {
  vec3 d = position - eye;
  if (cull != 0 && dot(normal, d) > 0.0) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // outside the clip volume: dropped
    return;
  }
  vec3 p = position;
  // A square is at one depth: the visibility pass pushes it back by epsilon times half its
  // side in the world, keeping its pixels (rasterizer::blended_point).
  if (blend_pass == 1) p = eye + d * (1.0 + blend_epsilon * 0.5 * max(size_px, 1.0) / focal_px);
  gl_Position = project(p);
  centre_px = (gl_Position.xy / gl_Position.w * 0.5 + 0.5) * viewport;
  half_side = 0.5 * max(size_px, 1.0);
  gl_PointSize = size_px > 1.0 ? ceil(size_px) + 2.0 : 3.0;  // the shader trims it
  frag_colour = shade_flat(colour, normal, d);
  frag_albedo = colouring != 0 ? colour : flat_colour;
  frag_away = dot(normal, d) > 0.0 ? 1.0 : 0.0;
  float len = length(normal);
  frag_normal = len > 0.0 ? normal / (frag_away > 0.5 ? -len : len) : vec3(0.0);
}
)";

// raster_square: side ≤ 1 is the pixel containing the centre (x in [i, i + 1)); a larger side
// the pixels whose centres lie in [sx − h, sx + h) × [sy − h, sy + h) in image coordinates
// (y down), i.e. (sy_gl − h, sy_gl + h] in window coordinates (y up).
constexpr const char* kPointFs = R"(
flat in vec3 frag_colour;
flat in vec2 centre_px;
flat in float half_side;
flat in vec3 frag_albedo;
flat in vec3 frag_normal;
flat in float frag_away;
void main() {
  vec2 p = gl_FragCoord.xy;
  bool inside;
  if (half_side <= 0.5)
    inside = floor(centre_px.x) == floor(p.x) && ceil(centre_px.y) == ceil(p.y);
  else
    inside = p.x >= centre_px.x - half_side && p.x < centre_px.x + half_side &&
             p.y > centre_px.y - half_side && p.y <= centre_px.y + half_side;
  if (!inside) discard;
  if (blend_pass == 2) {
    // Weight 1 − r², r² the squared distance to the centre over the half-diagonal's; 1 for a
    // one-pixel point.
    vec2 q = p - centre_px;
    float w = half_side <= 0.5 ? 1.0 : 1.0 - dot(q, q) / (2.0 * half_side * half_side);
    if (!(w > 0.0)) discard;
    accumulate(w, frag_albedo, frag_normal, frag_away > 0.5);
    return;
  }
  out_colour = vec4(frag_colour / 255.0, 1.0);
}
)";

constexpr const char* kSplatVs = R"(
layout(location = 0) in vec3 centre;
layout(location = 1) in vec3 axis_u;
layout(location = 2) in vec3 axis_v;
layout(location = 3) in vec3 normal;
layout(location = 4) in vec3 colour;
out vec2 st;
flat out vec3 frag_colour;
flat out vec3 frag_albedo;  // accumulation: albedo and the normal turned to the eye
flat out vec3 frag_normal;
flat out float frag_away;
void main() {
  vec2 corner = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
  vec3 d = centre - eye;
  if (cull != 0 && dot(normal, d) > 0.0) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  st = corner;
  vec3 p = centre + corner.x * axis_u + corner.y * axis_v;
  // The visibility pass scales the splat about the eye by 1 + epsilon r / |c − eye|: the same
  // pixels, pushed back along the view rays by about epsilon r (rasterizer::blended_splat).
  if (blend_pass == 1) {
    float f = 1.0 + blend_epsilon * sqrt(max(dot(axis_u, axis_u), dot(axis_v, axis_v))) / length(d);
    p = eye + (p - eye) * f;
  }
  gl_Position = project(p);
  frag_colour = shade_flat(colour, normal, d);
  frag_albedo = colouring != 0 ? colour : flat_colour;
  frag_away = dot(normal, d) > 0.0 ? 1.0 : 0.0;
  float len = length(normal);
  frag_normal = len > 0.0 ? normal / (frag_away > 0.5 ? -len : len) : vec3(0.0);
}
)";

// Perspective-correct (s, t): the splat-plane point each pixel centre sees, exactly.
constexpr const char* kSplatFs = R"(
in vec2 st;
flat in vec3 frag_colour;
flat in vec3 frag_albedo;
flat in vec3 frag_normal;
flat in float frag_away;
void main() {
  if (dot(st, st) > 1.0) discard;
  if (blend_pass == 2) {
    float w = 1.0 - dot(st, st);  // 1 − s² − t²: 0 on the ellipse
    if (!(w > 0.0)) discard;
    accumulate(w, frag_albedo, frag_normal, frag_away > 0.5);
    return;
  }
  out_colour = vec4(frag_colour / 255.0, 1.0);
}
)";

constexpr const char* kTriangleVs = R"(
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(location = 2) in vec3 colour;
layout(location = 3) in vec3 texcoord;  // s, t, textured (1) or not (0)
out vec3 frag_normal;
out vec3 frag_albedo;
out vec2 frag_st;
flat out float frag_textured;
void main() {
  gl_Position = project(position);
  frag_normal = normal;
  frag_albedo = colour;
  frag_st = texcoord.xy;
  frag_textured = texcoord.z;
}
)";

// rasterizer::triangle: the interpolated normal normalised and flipped on the back face, the
// interpolated colour rounded to a byte (to_channel), then lit and rounded (scale_colour).
// rasterizer::textured_triangle: the texture sampled bilinearly with wrapping (GL_LINEAR,
// GL_REPEAT) in place of the colour.
constexpr const char* kTriangleFs = R"(
in vec3 frag_normal;
in vec3 frag_albedo;
in vec2 frag_st;
flat in float frag_textured;
uniform sampler2D tex;
void main() {
  bool textured = colouring != 0 && frag_textured > 0.5;
  vec3 texel = clamp(floor(texture(tex, frag_st).rgb * 255.0 + 0.5), 0.0, 255.0);
  if (blend_pass == 2) {
    // An exact surface: weight 1, its interpolated colour (not rounded; a texel is) and normal.
    float len = length(frag_normal);
    vec3 n = len > 0.0 ? frag_normal / (gl_FrontFacing ? len : -len) : vec3(0.0);
    vec3 a = textured ? texel : colouring != 0 ? frag_albedo : flat_colour;
    accumulate(1.0, a, n, !gl_FrontFacing);
    return;
  }
  vec3 albedo = colouring != 0 ? clamp(floor(frag_albedo + 0.5), 0.0, 255.0) : flat_colour;
  if (textured) albedo = texel;
  vec3 c = albedo;
  if (shading != 0) {
    float len = length(frag_normal);
    vec3 n = len > 0.0 ? frag_normal / (gl_FrontFacing ? len : -len) : vec3(0.0);
    c = floor(albedo * lambert(n) + 0.5);
  }
  out_colour = vec4(c / 255.0, 1.0);
}
)";

// The normalisation pass (rasterizer::normalise_blend): one triangle over the viewport; per
// pixel the facing sums where they have weight, else those facing away; colour = Σw·c / Σw
// rounded, the summed normal normalised and shaded (deferred shading); pixels no weighted
// fragment reached keep the visibility pass's colour and depth.
constexpr const char* kNormaliseVs = R"(
void main() {
  vec2 p = vec2((gl_VertexID & 1) != 0 ? 3.0 : -1.0, (gl_VertexID & 2) != 0 ? 3.0 : -1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}
)";
constexpr const char* kNormaliseFs = R"(
uniform sampler2D vis_colour, vis_depth, sum_colour, sum_normal, sum_away_colour, sum_away_normal;
void main() {
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec4 c = texelFetch(sum_colour, p, 0);
  vec3 n = texelFetch(sum_normal, p, 0).xyz;
  if (!(c.w > 0.0)) {
    c = texelFetch(sum_away_colour, p, 0);
    n = texelFetch(sum_away_normal, p, 0).xyz;
  }
  float depth = texelFetch(vis_depth, p, 0).r;
  if (!(c.w > 0.0)) {
    if (!(depth < 1.0)) discard;  // background
    out_colour = texelFetch(vis_colour, p, 0);
    gl_FragDepth = depth;
    return;
  }
  vec3 albedo = colouring != 0 ? clamp(floor(c.xyz * (1.0 / c.w) + 0.5), 0.0, 255.0) : flat_colour;
  vec3 colour = albedo;
  if (shading != 0) {
    float len = length(n);
    colour = floor(albedo * lambert(len > 0.0 ? n / len : vec3(0.0)) + 0.5);
  }
  out_colour = vec4(colour / 255.0, 1.0);
  // Covered in the accumulation pass only (a rim pixel): in front of the far plane.
  gl_FragDepth = depth < 1.0 ? depth : 0.99999994;
}
)";

// Gaussians (raster/gaussians.hpp): each projected on the CPU by the rasteriser's own
// project_gaussian() (EWA with 3DGS's low-pass; SH colour for the view), drawn as one instanced
// quad over the pixel box outside which α < 1/255, sorted back to front and blended "over":
// colour = α·c + (1 − α)·dst, which composites the CPU's front-to-back sum in reverse order;
// the alpha channel accumulates 1 − T (the pixel's coverage: T ≤ ½). Depth-tested against the
// frame's opaque primitives, never written.
constexpr const char* kGaussianVs = R"(
layout(location = 0) in vec2 g_centre_in;  // image pixels, y down
layout(location = 1) in vec3 g_conic_in;
layout(location = 2) in float g_opacity_in;
layout(location = 3) in vec3 g_rgb_in;
layout(location = 4) in vec4 g_box;  // x0, y0, x1, y1: image pixels, y down
layout(location = 5) in float g_depth;
uniform vec2 viewport;
flat out vec2 g_centre;
flat out vec3 g_conic;
flat out float g_opacity;
flat out vec3 g_rgb;
void main() {
  vec2 corner = vec2((gl_VertexID & 1) != 0 ? g_box.z : g_box.x,
                     (gl_VertexID & 2) != 0 ? g_box.w : g_box.y);
  float z = clamp(proj.z + proj.w / g_depth, -1.0, 1.0);
  gl_Position = vec4(2.0 * corner.x / viewport.x - 1.0, 1.0 - 2.0 * corner.y / viewport.y, z, 1.0);
  g_centre = g_centre_in;
  g_conic = g_conic_in;
  g_opacity = g_opacity_in;
  g_rgb = g_rgb_in;
}
)";
// gaussian_alpha() and the 1/255 skip, at the pixel centre in image coordinates.
constexpr const char* kGaussianFs = R"(
uniform vec2 viewport;
flat in vec2 g_centre;
flat in vec3 g_conic;
flat in float g_opacity;
flat in vec3 g_rgb;
void main() {
  vec2 d = g_centre - vec2(gl_FragCoord.x, viewport.y - gl_FragCoord.y);
  float power = -0.5 * (g_conic.x * d.x * d.x + g_conic.z * d.y * d.y) - g_conic.y * d.x * d.y;
  if (power > 0.0) discard;
  float alpha = min(0.99, g_opacity * exp(power));
  if (alpha < 1.0 / 255.0) discard;
  out_colour = vec4(g_rgb, alpha);
}
)";

struct gaussian_instance {
  float centre[2];
  float conic[3];
  float opacity;
  float rgb[3];
  float box[4];
  float depth;
};

struct point_vertex {
  float position[3];
  float size_px;
  float normal[3];
  std::uint8_t colour[4];
};
struct splat_instance {
  float centre[3], u[3], v[3], normal[3];
  std::uint8_t colour[4];
};
struct triangle_vertex {
  float position[3];
  float normal[3];
  std::uint8_t colour[4];
  float texcoord[3];  // s, t (GL's: t = 1 − v, row 0 on top), 1 when textured
};

void copy3(float* out, const pbr_lod::vec3f& v) {
  out[0] = v.x();
  out[1] = v.y();
  out[2] = v.z();
}
void copy_colour(std::uint8_t* out, const pbr_lod::rgb8& c) {
  out[0] = c.r;
  out[1] = c.g;
  out[2] = c.b;
  out[3] = 255;
}

GLuint compile(GLenum kind, const char* body) {
  const GLuint s = glCreateShader(kind);
  const bool fragment = kind == GL_FRAGMENT_SHADER;
  const char* parts[4] = {kCommon, fragment ? kFragmentCommon : "", kCommonFunctions, body};
  glShaderSource(s, 4, parts, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[4096] = {};
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    glDeleteShader(s);
    throw std::runtime_error(std::string("gl_viewer: shader does not compile: ") + log);
  }
  return s;
}

GLuint link(const char* vs, const char* fs) {
  const GLuint v = compile(GL_VERTEX_SHADER, vs), f = compile(GL_FRAGMENT_SHADER, fs);
  const GLuint p = glCreateProgram();
  glAttachShader(p, v);
  glAttachShader(p, f);
  glLinkProgram(p);
  glDeleteShader(v);
  glDeleteShader(f);
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[4096] = {};
    glGetProgramInfoLog(p, sizeof log, nullptr, log);
    glDeleteProgram(p);
    throw std::runtime_error(std::string("gl_viewer: program does not link: ") + log);
  }
  return p;
}

/// A float attribute (normalised bytes when `type` is GL_UNSIGNED_BYTE: 0..255 as floats).
void attribute(GLuint index, GLint size, GLenum type, GLsizei stride, std::size_t offset,
               GLuint divisor = 0) {
  glEnableVertexAttribArray(index);
  glVertexAttribPointer(index, size, type, GL_FALSE, stride,
                        reinterpret_cast<const void*>(offset));  // NOLINT: GL's offset idiom
  glVertexAttribDivisor(index, divisor);
}

}  // namespace

struct gl_renderer::impl {
  GLuint programs[5] = {};  // points, splats, triangles, blend normalisation, Gaussians
  GLuint vao[5] = {}, vbo[4] = {};
  /// Blending's offscreen targets, made at the first blended frame and remade when the size
  /// changes: the visibility pass's colour (RGBA8) and depth (32-bit float), and the four
  /// accumulation sums (RGBA32F, summed by additive blending).
  GLuint vis_fbo = 0, sum_fbo = 0;
  GLuint vis_colour = 0, vis_depth = 0, sums[4] = {};
  int target_w = 0, target_h = 0;
  std::vector<point_vertex> points;
  std::vector<splat_instance> splats;
  std::vector<triangle_vertex> triangles;
  std::vector<gaussian_instance> gaussians;  // in arrival order; drawn sorted
  /// The frame's texture (one per frame: a triangle with another is drawn untextured) and the
  /// GL texture holding the image last uploaded.
  const pbr_lod::texture_image* frame_texture = nullptr;
  const pbr_lod::texture_image* uploaded = nullptr;
  GLuint gl_texture = 0;
  pbr_lod::view v{pbr_lod::camera{}, pbr_lod::vec3d::Zero()};
  pbr_lod::render_options o;
  float depth_a = 0, depth_b = 0;  // z_ndc = a + b / z_eye

  void uniforms(GLuint p) const {
    glUseProgram(p);
    const auto set3 = [&](const char* name, const pbr_lod::vec3f& x) {
      glUniform3f(glGetUniformLocation(p, name), x.x(), x.y(), x.z());
    };
    set3("eye", v.eye);
    set3("right_axis", v.right);
    set3("up_axis", v.up);
    set3("forward_axis", v.forward);
    const float w2 = 0.5f * static_cast<float>(v.width), h2 = 0.5f * static_cast<float>(v.height);
    // clip z = a·z + b with w = z: z_ndc = a + b/z, −1 at z_near and +1 at z_far.
    glUniform4f(glGetUniformLocation(p, "proj"), v.focal_px / w2, v.focal_px / h2, depth_a,
                depth_b);
    const pbr_lod::vec3f d = o.sun.direction;
    const pbr_lod::vec3f l = (pbr_lod::all_finite(d) && d.squaredNorm() > 0)
                                 ? pbr_lod::vec3f(d.normalized())
                                 : pbr_lod::vec3f::Zero();
    set3("light_dir", l);
    const float amb = std::isfinite(o.sun.ambient) ? std::clamp(o.sun.ambient, 0.0f, 1.0f) : 0.0f;
    glUniform1f(glGetUniformLocation(p, "ambient"), amb);
    glUniform1i(glGetUniformLocation(p, "shading"), o.fx.shading ? 1 : 0);
    glUniform1i(glGetUniformLocation(p, "colouring"), o.fx.colour ? 1 : 0);
    glUniform1i(glGetUniformLocation(p, "cull"), o.fx.backface_cull ? 1 : 0);
    glUniform3f(glGetUniformLocation(p, "flat_colour"), o.flat_colour.r, o.flat_colour.g,
                o.flat_colour.b);
    glUniform2f(glGetUniformLocation(p, "viewport"), static_cast<float>(v.width),
                static_cast<float>(v.height));
    glUniform1f(glGetUniformLocation(p, "focal_px"), v.focal_px);
    glUniform1f(glGetUniformLocation(p, "blend_epsilon"), o.blend_depth_epsilon);
    glUniform1i(glGetUniformLocation(p, "blend_pass"), 0);
  }

  /// The blending targets at the view's size (see vis_fbo).
  void blend_targets() {
    if (vis_fbo != 0 && target_w == v.width && target_h == v.height) return;
    free_targets();
    target_w = v.width;
    target_h = v.height;
    const auto texture = [&](GLuint& t, GLint internal, GLenum format, GLenum type) {
      glGenTextures(1, &t);
      glBindTexture(GL_TEXTURE_2D, t);
      glTexImage2D(GL_TEXTURE_2D, 0, internal, v.width, v.height, 0, format, type, nullptr);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    };
    texture(vis_colour, GL_RGBA8, GL_RGBA, GL_UNSIGNED_BYTE);
    texture(vis_depth, GL_DEPTH_COMPONENT32F, GL_DEPTH_COMPONENT, GL_FLOAT);
    for (GLuint& t : sums) texture(t, GL_RGBA32F, GL_RGBA, GL_FLOAT);
    glGenFramebuffers(1, &vis_fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, vis_fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, vis_colour, 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, vis_depth, 0);
    const bool vis_ok = glCheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    glGenFramebuffers(1, &sum_fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, sum_fbo);
    const GLenum bufs[4] = {GL_COLOR_ATTACHMENT0, GL_COLOR_ATTACHMENT1, GL_COLOR_ATTACHMENT2,
                            GL_COLOR_ATTACHMENT3};
    for (int i = 0; i < 4; ++i)
      glFramebufferTexture2D(GL_FRAMEBUFFER, bufs[i], GL_TEXTURE_2D, sums[i], 0);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, vis_depth, 0);
    glDrawBuffers(4, bufs);
    const bool sum_ok = glCheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    if (!vis_ok || !sum_ok)
      throw std::runtime_error("gl_viewer: the blending framebuffers are incomplete");
  }
  void free_targets() {
    glDeleteFramebuffers(1, &vis_fbo);
    glDeleteFramebuffers(1, &sum_fbo);
    glDeleteTextures(1, &vis_colour);
    glDeleteTextures(1, &vis_depth);
    glDeleteTextures(4, sums);
    vis_fbo = sum_fbo = vis_colour = vis_depth = 0;
    for (GLuint& t : sums) t = 0;
  }
};

gl_renderer::gl_renderer() : d_(std::make_unique<impl>()) {
  d_->programs[0] = link(kPointVs, kPointFs);
  d_->programs[1] = link(kSplatVs, kSplatFs);
  d_->programs[2] = link(kTriangleVs, kTriangleFs);
  d_->programs[3] = link(kNormaliseVs, kNormaliseFs);
  d_->programs[4] = link(kGaussianVs, kGaussianFs);
  glGenVertexArrays(5, d_->vao);
  glGenBuffers(4, d_->vbo);
  constexpr GLenum F = GL_FLOAT, B = GL_UNSIGNED_BYTE;

  glBindVertexArray(d_->vao[0]);
  glBindBuffer(GL_ARRAY_BUFFER, d_->vbo[0]);
  constexpr auto ps = static_cast<GLsizei>(sizeof(point_vertex));
  attribute(0, 3, F, ps, offsetof(point_vertex, position));
  attribute(1, 1, F, ps, offsetof(point_vertex, size_px));
  attribute(2, 3, F, ps, offsetof(point_vertex, normal));
  attribute(3, 3, B, ps, offsetof(point_vertex, colour));

  glBindVertexArray(d_->vao[1]);
  glBindBuffer(GL_ARRAY_BUFFER, d_->vbo[1]);
  constexpr auto ss = static_cast<GLsizei>(sizeof(splat_instance));
  attribute(0, 3, F, ss, offsetof(splat_instance, centre), 1);
  attribute(1, 3, F, ss, offsetof(splat_instance, u), 1);
  attribute(2, 3, F, ss, offsetof(splat_instance, v), 1);
  attribute(3, 3, F, ss, offsetof(splat_instance, normal), 1);
  attribute(4, 3, B, ss, offsetof(splat_instance, colour), 1);

  glBindVertexArray(d_->vao[2]);
  glBindBuffer(GL_ARRAY_BUFFER, d_->vbo[2]);
  constexpr auto ts = static_cast<GLsizei>(sizeof(triangle_vertex));
  attribute(0, 3, F, ts, offsetof(triangle_vertex, position));
  attribute(1, 3, F, ts, offsetof(triangle_vertex, normal));
  attribute(2, 3, B, ts, offsetof(triangle_vertex, colour));
  attribute(3, 3, F, ts, offsetof(triangle_vertex, texcoord));

  glBindVertexArray(d_->vao[4]);
  glBindBuffer(GL_ARRAY_BUFFER, d_->vbo[3]);
  constexpr auto gs = static_cast<GLsizei>(sizeof(gaussian_instance));
  attribute(0, 2, F, gs, offsetof(gaussian_instance, centre), 1);
  attribute(1, 3, F, gs, offsetof(gaussian_instance, conic), 1);
  attribute(2, 1, F, gs, offsetof(gaussian_instance, opacity), 1);
  attribute(3, 3, F, gs, offsetof(gaussian_instance, rgb), 1);
  attribute(4, 4, F, gs, offsetof(gaussian_instance, box), 1);
  attribute(5, 1, F, gs, offsetof(gaussian_instance, depth), 1);
  glBindVertexArray(0);
  glGenTextures(1, &d_->gl_texture);
}

gl_renderer::~gl_renderer() {
  glDeleteTextures(1, &d_->gl_texture);
  d_->free_targets();
  glDeleteBuffers(4, d_->vbo);
  glDeleteVertexArrays(5, d_->vao);
  for (const GLuint p : d_->programs) glDeleteProgram(p);
}

void gl_renderer::begin(const pbr_lod::view& v, const pbr_lod::render_options& o,
                        pbr_lod::attributes carried) {
  d_->v = v;
  d_->o = o;
  d_->o.fx.shading = o.fx.shading && carried.normal;
  d_->o.fx.colour = o.fx.colour && carried.colour;
  const float n = v.z_near, f = v.z_far;
  d_->depth_a = (f + n) / (f - n);
  d_->depth_b = -2 * f * n / (f - n);
  d_->points.clear();
  d_->splats.clear();
  d_->triangles.clear();
  d_->gaussians.clear();
  d_->frame_texture = nullptr;
  counts_ = {};
}

void gl_renderer::point(const pbr_lod::point_prim<host_attributes>& p) {
  point_vertex q{};
  copy3(q.position, p.position);
  q.size_px = p.size_px;
  copy3(q.normal, p.normal);
  copy_colour(q.colour, p.colour);
  d_->points.push_back(q);
}

void gl_renderer::splat(const pbr_lod::splat_prim<host_attributes>& s) {
  splat_instance q{};
  copy3(q.centre, s.centre);
  copy3(q.u, s.u);
  copy3(q.v, s.v);
  copy3(q.normal, s.normal);
  copy_colour(q.colour, s.colour);
  d_->splats.push_back(q);
}

void gl_renderer::triangle(const pbr_lod::triangle_prim<host_attributes>& t) {
  for (std::size_t k = 0; k < 3; ++k) {
    triangle_vertex q{};
    copy3(q.position, t.p[k]);
    copy3(q.normal, t.normal[k]);
    copy_colour(q.colour, t.colour[k]);
    d_->triangles.push_back(q);
  }
}

void gl_renderer::gaussian(const pbr_lod::gaussian_prim& g) {
  const pbr_lod::detail::gaussian_2d s = pbr_lod::detail::project_gaussian(d_->v, g);
  ++counts_.gaussians;
  if (s.status != pbr_lod::detail::gaussian_2d::fate::drawn) return;
  gaussian_instance q{};
  q.centre[0] = s.x;
  q.centre[1] = s.y;
  q.conic[0] = s.a;
  q.conic[1] = s.b;
  q.conic[2] = s.c;
  q.opacity = s.opacity;
  for (int c = 0; c < 3; ++c) q.rgb[c] = s.rgb[static_cast<std::size_t>(c)];
  // The pixels [px0, px1] × [py0, py1]: the quad from the first one's corner to past the last.
  q.box[0] = static_cast<float>(s.px0);
  q.box[1] = static_cast<float>(s.py0);
  q.box[2] = static_cast<float>(s.px1 + 1);
  q.box[3] = static_cast<float>(s.py1 + 1);
  q.depth = s.depth;
  d_->gaussians.push_back(q);
}

void gl_renderer::textured_triangle(const pbr_lod::textured_triangle_prim<host_attributes>& t) {
  const pbr_lod::texture_image* tex = t.texture;
  if (tex == nullptr || tex->width <= 0 || tex->height <= 0 ||
      tex->texels.size() !=
          static_cast<std::size_t>(tex->width) * static_cast<std::size_t>(tex->height) ||
      (d_->frame_texture != nullptr && d_->frame_texture != tex)) {
    triangle(t.triangle);
    return;
  }
  d_->frame_texture = tex;
  for (std::size_t k = 0; k < 3; ++k) {
    triangle_vertex q{};
    copy3(q.position, t.triangle.p[k]);
    copy3(q.normal, t.triangle.normal[k]);
    copy_colour(q.colour, t.triangle.colour[k]);
    q.texcoord[0] = t.uv[k].x();
    q.texcoord[1] = 1 - t.uv[k].y();
    q.texcoord[2] = 1;
    d_->triangles.push_back(q);
  }
}

double gl_renderer::draw() {
  const auto t0 = std::chrono::steady_clock::now();
  impl& d = *d_;
  counts_ = {d.points.size(), d.splats.size(), d.triangles.size() / 3, counts_.gaussians};
  // Blending as the CPU rasteriser applies it: with shading or colour to average, and only
  // when there are splats or points (triangles alone draw the unblended image).
  const bool blend = d.o.fx.blending && (d.o.fx.shading || d.o.fx.colour) &&
                     (!d.points.empty() || !d.splats.empty());
  GLint target = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &target);
  glViewport(0, 0, d.v.width, d.v.height);
  const pbr_lod::rgb8 bg = d.o.background;
  glClearColor(bg.r / 255.0f, bg.g / 255.0f, bg.b / 255.0f, 0.0f);
  glClearDepth(1.0);
  if (blend) {
    d.blend_targets();
    glBindFramebuffer(GL_FRAMEBUFFER, d.vis_fbo);
  }
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);  // ties keep the first primitive drawn, as the CPU rasteriser does
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  glEnable(GL_PROGRAM_POINT_SIZE);
  glFrontFace(GL_CCW);
  glCullFace(GL_BACK);

  const auto upload = [](GLuint vao, GLuint vbo, const auto& data) {
    glBindVertexArray(vao);
    glBindBuffer(GL_ARRAY_BUFFER, vbo);
    glBufferData(GL_ARRAY_BUFFER,
                 static_cast<GLsizeiptr>(data.size() *
                                         sizeof(typename std::decay_t<decltype(data)>::value_type)),
                 data.data(), GL_STREAM_DRAW);
  };
  if (!d.triangles.empty()) {
    d.uniforms(d.programs[2]);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, d.gl_texture);
    if (d.frame_texture != nullptr && d.frame_texture != d.uploaded) {
      const pbr_lod::texture_image& t = *d.frame_texture;
      glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGB8, t.width, t.height, 0, GL_RGB, GL_UNSIGNED_BYTE,
                   t.texels.data());
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_REPEAT);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_REPEAT);
      d.uploaded = d.frame_texture;
    }
    glUniform1i(glGetUniformLocation(d.programs[2], "tex"), 0);
    upload(d.vao[2], d.vbo[2], d.triangles);
  }
  if (!d.splats.empty()) upload(d.vao[1], d.vbo[1], d.splats);
  if (!d.points.empty()) upload(d.vao[0], d.vbo[0], d.points);
  // One pass over the frame's primitives (pass: blending's, 0 without).
  const auto draw_all = [&](int pass) {
    if (!d.triangles.empty()) {
      d.uniforms(d.programs[2]);
      glUniform1i(glGetUniformLocation(d.programs[2], "tex"), 0);
      glUniform1i(glGetUniformLocation(d.programs[2], "blend_pass"), pass);
      if (d.o.fx.backface_cull)
        glEnable(GL_CULL_FACE);
      else
        glDisable(GL_CULL_FACE);
      glBindVertexArray(d.vao[2]);
      glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(d.triangles.size()));
      glDisable(GL_CULL_FACE);
    }
    if (!d.splats.empty()) {
      d.uniforms(d.programs[1]);
      glUniform1i(glGetUniformLocation(d.programs[1], "blend_pass"), pass);
      glBindVertexArray(d.vao[1]);
      glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, static_cast<GLsizei>(d.splats.size()));
    }
    if (!d.points.empty()) {
      d.uniforms(d.programs[0]);
      glUniform1i(glGetUniformLocation(d.programs[0], "blend_pass"), pass);
      glBindVertexArray(d.vao[0]);
      glDrawArrays(GL_POINTS, 0, static_cast<GLsizei>(d.points.size()));
    }
  };
  if (!blend) {
    draw_all(0);
  } else {
    // 1. Visibility: depth (points and splats pushed back) and the unblended colour.
    draw_all(1);
    // 2. Accumulation: every fragment not behind the visibility depth adds its weighted
    //    colour, normal and weight; nothing is depth-written.
    glBindFramebuffer(GL_FRAMEBUFFER, d.sum_fbo);
    const float zero[4] = {0, 0, 0, 0};
    for (GLint i = 0; i < 4; ++i) glClearBufferfv(GL_COLOR, i, zero);
    glDepthFunc(GL_LEQUAL);
    glDepthMask(GL_FALSE);
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFunc(GL_ONE, GL_ONE);
    draw_all(2);
    glDisable(GL_BLEND);
    // 3. Normalisation into the caller's framebuffer, with the depth of the visibility pass.
    glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(target));
    glDepthMask(GL_TRUE);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glDepthFunc(GL_ALWAYS);
    const GLuint np = d.programs[3];
    d.uniforms(np);
    const GLuint inputs[6] = {d.vis_colour, d.vis_depth, d.sums[0],
                              d.sums[1],    d.sums[2],   d.sums[3]};
    const char* names[6] = {"vis_colour", "vis_depth",       "sum_colour",
                            "sum_normal", "sum_away_colour", "sum_away_normal"};
    for (int i = 0; i < 6; ++i) {
      glActiveTexture(static_cast<GLenum>(GL_TEXTURE1 + i));
      glBindTexture(GL_TEXTURE_2D, inputs[i]);
      glUniform1i(glGetUniformLocation(np, names[i]), 1 + i);
    }
    glBindVertexArray(d.vao[3]);
    glDrawArrays(GL_TRIANGLE_STRIP, 0, 4);
    glActiveTexture(GL_TEXTURE0);
    glDepthFunc(GL_LESS);
  }
  if (!d.gaussians.empty()) draw_gaussians();
  glBindVertexArray(0);
  glFinish();
  if (const GLenum e = glGetError(); e != GL_NO_ERROR)
    throw std::runtime_error("gl_viewer: OpenGL error " + std::to_string(e) + " while drawing");
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void gl_renderer::draw_gaussians() {
  impl& d = *d_;
  // Back to front: the reverse of the CPU's order (view depth, then arrival), whose keys are
  // the depth's bits (depths are > 0) and the index.
  std::vector<std::uint64_t> keys(d.gaussians.size());
  for (std::size_t i = 0; i < keys.size(); ++i)
    keys[i] = std::uint64_t{std::bit_cast<std::uint32_t>(d.gaussians[i].depth)} << 32 | i;
  std::sort(keys.begin(), keys.end(), std::greater<>());
  std::vector<gaussian_instance> sorted(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i) sorted[i] = d.gaussians[keys[i] & 0xffffffffu];
  glBindVertexArray(d.vao[4]);
  glBindBuffer(GL_ARRAY_BUFFER, d.vbo[3]);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(sorted.size() * sizeof(gaussian_instance)),
               sorted.data(), GL_STREAM_DRAW);
  d.uniforms(d.programs[4]);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_FALSE);
  glEnable(GL_BLEND);
  glBlendEquation(GL_FUNC_ADD);
  glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
  glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, static_cast<GLsizei>(sorted.size()));
  glDisable(GL_BLEND);
  glDepthMask(GL_TRUE);
}

pbr_lod::image gl_renderer::read_image() const {
  const int w = d_->v.width, h = d_->v.height;
  std::vector<std::uint8_t> rgba(static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 4);
  std::vector<float> depth(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  glReadPixels(0, 0, w, h, GL_DEPTH_COMPONENT, GL_FLOAT, depth.data());
  pbr_lod::image img(w, h, d_->o.background);
  for (int y = 0; y < h; ++y) {
    const std::size_t row = static_cast<std::size_t>(h - 1 - y) * static_cast<std::size_t>(w);
    for (int x = 0; x < w; ++x) {
      const std::size_t s = row + static_cast<std::size_t>(x), i = img.index(x, y);
      const float dw = depth[s];
      if (!(dw < 1.0f)) {
        // No opaque primitive: background, or Gaussians. Their coverage is the CPU's (T ≤ ½:
        // alpha ≥ ½); the depth of a Gaussian-only pixel is not computed here (the CPU's is the
        // median's), so it reads as the far plane.
        if (d_->gaussians.empty() || rgba[4 * s + 3] < 128) continue;
        img.colour[i] = {rgba[4 * s], rgba[4 * s + 1], rgba[4 * s + 2]};
        img.depth[i] = d_->v.z_far;
        continue;
      }
      img.colour[i] = {rgba[4 * s], rgba[4 * s + 1], rgba[4 * s + 2]};
      // window depth → z_ndc = a + b / z_eye
      const float ndc = 2 * dw - 1;
      img.depth[i] = d_->depth_b / (ndc - d_->depth_a);
    }
  }
  return img;
}

}  // namespace gl_viewer
