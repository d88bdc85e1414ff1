// gl_viewer — the OpenGL 3.3 core renderer (gl_renderer.hpp). GL entry points come from
// libOpenGL (glvnd), which dispatches to whichever context is current: a GLFW/GLX window or the
// headless EGL context, with no loader library.
#define GL_GLEXT_PROTOTYPES 1
#include "gl_renderer.hpp"

#include <GL/glcorearb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <string>

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
flat out vec3 frag_colour;
flat out vec2 centre_px;  // window coordinates of the projected centre
flat out float half_side;
void main() {
  vec3 d = position - eye;
  if (cull != 0 && dot(normal, d) > 0.0) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // outside the clip volume: dropped
    return;
  }
  gl_Position = project(position);
  centre_px = (gl_Position.xy / gl_Position.w * 0.5 + 0.5) * viewport;
  half_side = 0.5 * max(size_px, 1.0);
  gl_PointSize = size_px > 1.0 ? ceil(size_px) + 2.0 : 3.0;  // the shader trims it
  frag_colour = shade_flat(colour, normal, d);
}
)";

// raster_square: side ≤ 1 is the pixel containing the centre (x in [i, i + 1)); a larger side
// the pixels whose centres lie in [sx − h, sx + h) × [sy − h, sy + h) in image coordinates
// (y down), i.e. (sy_gl − h, sy_gl + h] in window coordinates (y up).
constexpr const char* kPointFs = R"(
flat in vec3 frag_colour;
flat in vec2 centre_px;
flat in float half_side;
out vec4 out_colour;
void main() {
  vec2 p = gl_FragCoord.xy;
  bool inside;
  if (half_side <= 0.5)
    inside = floor(centre_px.x) == floor(p.x) && ceil(centre_px.y) == ceil(p.y);
  else
    inside = p.x >= centre_px.x - half_side && p.x < centre_px.x + half_side &&
             p.y > centre_px.y - half_side && p.y <= centre_px.y + half_side;
  if (!inside) discard;
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
void main() {
  vec2 corner = vec2((gl_VertexID & 1) != 0 ? 1.0 : -1.0, (gl_VertexID & 2) != 0 ? 1.0 : -1.0);
  vec3 d = centre - eye;
  if (cull != 0 && dot(normal, d) > 0.0) {
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    return;
  }
  st = corner;
  gl_Position = project(centre + corner.x * axis_u + corner.y * axis_v);
  frag_colour = shade_flat(colour, normal, d);
}
)";

// Perspective-correct (s, t): the splat-plane point each pixel centre sees, exactly.
constexpr const char* kSplatFs = R"(
in vec2 st;
flat in vec3 frag_colour;
out vec4 out_colour;
void main() {
  if (dot(st, st) > 1.0) discard;
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
out vec4 out_colour;
void main() {
  vec3 albedo = colouring != 0 ? clamp(floor(frag_albedo + 0.5), 0.0, 255.0) : flat_colour;
  if (colouring != 0 && frag_textured > 0.5)
    albedo = clamp(floor(texture(tex, frag_st).rgb * 255.0 + 0.5), 0.0, 255.0);
  vec3 c = albedo;
  if (shading != 0) {
    float len = length(frag_normal);
    vec3 n = len > 0.0 ? frag_normal / (gl_FrontFacing ? len : -len) : vec3(0.0);
    c = floor(albedo * lambert(n) + 0.5);
  }
  out_colour = vec4(c / 255.0, 1.0);
}
)";

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
  const char* parts[2] = {kCommon, body};
  glShaderSource(s, 2, parts, nullptr);
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
  GLuint programs[3] = {};  // points, splats, triangles
  GLuint vao[3] = {}, vbo[3] = {};
  std::vector<point_vertex> points;
  std::vector<splat_instance> splats;
  std::vector<triangle_vertex> triangles;
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
  }
};

gl_renderer::gl_renderer() : d_(std::make_unique<impl>()) {
  d_->programs[0] = link(kPointVs, kPointFs);
  d_->programs[1] = link(kSplatVs, kSplatFs);
  d_->programs[2] = link(kTriangleVs, kTriangleFs);
  glGenVertexArrays(3, d_->vao);
  glGenBuffers(3, d_->vbo);
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
  glBindVertexArray(0);
  glGenTextures(1, &d_->gl_texture);
}

gl_renderer::~gl_renderer() {
  glDeleteTextures(1, &d_->gl_texture);
  glDeleteBuffers(3, d_->vbo);
  glDeleteVertexArrays(3, d_->vao);
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
  counts_ = {d.points.size(), d.splats.size(), d.triangles.size() / 3};
  glViewport(0, 0, d.v.width, d.v.height);
  const pbr_lod::rgb8 bg = d.o.background;
  glClearColor(bg.r / 255.0f, bg.g / 255.0f, bg.b / 255.0f, 0.0f);
  glClearDepth(1.0);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);  // ties keep the first primitive drawn, as the CPU rasteriser does
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
    if (d.o.fx.backface_cull)
      glEnable(GL_CULL_FACE);
    else
      glDisable(GL_CULL_FACE);
    upload(d.vao[2], d.vbo[2], d.triangles);
    glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(d.triangles.size()));
    glDisable(GL_CULL_FACE);
  }
  if (!d.splats.empty()) {
    d.uniforms(d.programs[1]);
    upload(d.vao[1], d.vbo[1], d.splats);
    glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 4, static_cast<GLsizei>(d.splats.size()));
  }
  if (!d.points.empty()) {
    d.uniforms(d.programs[0]);
    upload(d.vao[0], d.vbo[0], d.points);
    glDrawArrays(GL_POINTS, 0, static_cast<GLsizei>(d.points.size()));
  }
  glBindVertexArray(0);
  glFinish();
  if (const GLenum e = glGetError(); e != GL_NO_ERROR)
    throw std::runtime_error("gl_viewer: OpenGL error " + std::to_string(e) + " while drawing");
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
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
      if (!(dw < 1.0f)) continue;  // cleared: background
      img.colour[i] = {rgba[4 * s], rgba[4 * s + 1], rgba[4 * s + 2]};
      // window depth → z_ndc = a + b / z_eye
      const float ndc = 2 * dw - 1;
      img.depth[i] = d_->depth_b / (ndc - d_->depth_a);
    }
  }
  return img;
}

}  // namespace gl_viewer
