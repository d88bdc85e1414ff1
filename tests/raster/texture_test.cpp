// Texture-mapped triangles (textured_triangle_prim): bilinear sampling with wrapping at texel
// positions worked out by hand, perspective-correct texture coordinates against the exact
// ray–plane intersection, and sinks without the hook drawing the plain triangle.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdlib>

#include "pbr_lod/core/mesh_colours.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "support/cameras.hpp"

namespace pbr_lod {
namespace {

constexpr attributes colour_only{.colour = true};
using test::origin_camera;

/// The two counter-clockwise triangles of the quad with corners c (lower left, lower right,
/// upper right, upper left) and texture coordinates uv at those corners.
std::array<textured_triangle_prim<colour_only>, 2> quad(const std::array<vec3f, 4>& c,
                                                        const std::array<vec2f, 4>& uv,
                                                        const texture_image* tex) {
  std::array<textured_triangle_prim<colour_only>, 2> q;
  const std::array<std::array<std::size_t, 3>, 2> idx{{{0, 1, 2}, {0, 2, 3}}};
  for (std::size_t t = 0; t < 2; ++t) {
    for (std::size_t k = 0; k < 3; ++k) {
      q[t].triangle.p[k] = c[idx[t][k]];
      q[t].triangle.colour[k] = {10, 20, 30};
      q[t].uv[k] = uv[idx[t][k]];
    }
    q[t].texture = tex;
  }
  return q;
}

rgb8 at(const image& img, int i, int j) {
  return img.colour[static_cast<std::size_t>(j) * static_cast<std::size_t>(img.width) +
                    static_cast<std::size_t>(i)];
}

void expect_near(rgb8 got, rgb8 want, const char* where) {
  EXPECT_LE(std::abs(int(got.r) - int(want.r)), 1) << where;
  EXPECT_LE(std::abs(int(got.g) - int(want.g)), 1) << where;
  EXPECT_LE(std::abs(int(got.b) - int(want.b)), 1) << where;
}

// A 2×2 checker (red, green / blue, white) on a quad that fills a 64×64 screen, facing the eye,
// with texture coordinates chosen so that texel space is x = i/32 − ½, y = j/32 − ½ at the centre
// of pixel (i, j): u runs over [−1/128, 1 − 1/128] left to right, v over [1 + 1/128, 1/128] top
// to bottom (texel x = u·2 − ½ with centres on integers, y = (1 − v)·2 − ½). So pixel (16, 16)
// sits on texel (0, 0)'s centre, (48, 16) on (1, 0)'s, (16, 48) on (0, 1)'s, (48, 48) on
// (1, 1)'s: pure colours. Pixel (32, 16) is halfway between red and green: (127.5, 127.5, 0)
// rounds to 128. Pixel (0, 16) is at x = −½, halfway between texel 0 and texel −1, which
// wraps (GL_REPEAT) to texel 1: the same red–green mix (clamping would give pure red). Pixel
// (16, 0) mixes red with the wrapped row 1 (blue).
TEST(TexturedTriangle, CheckerAtHandCheckedPixels) {
  const view v(origin_camera(64, 64), vec3d::Zero());
  texture_image tex;
  tex.width = tex.height = 2;
  tex.texels = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {255, 255, 255}};
  const float s = 32.0f / v.focal_px;  // the quad's half side at z = −1 fills the screen
  const float e = 1.0f / 128;
  const auto q = quad({vec3f(-s, -s, -1), vec3f(s, -s, -1), vec3f(s, s, -1), vec3f(-s, s, -1)},
                      {vec2f(-e, e), vec2f(1 - e, e), vec2f(1 - e, 1 + e), vec2f(-e, 1 + e)}, &tex);
  render_options opt;
  opt.fx = effects{.colour = true};
  const image img = render<colour_only>(v, opt, [&](auto& sink) {
    for (const auto& t : q) sink.textured_triangle(t);
  });
  expect_near(at(img, 16, 16), {255, 0, 0}, "texel (0, 0)");
  expect_near(at(img, 48, 16), {0, 255, 0}, "texel (1, 0)");
  expect_near(at(img, 16, 48), {0, 0, 255}, "texel (0, 1)");
  expect_near(at(img, 48, 48), {255, 255, 255}, "texel (1, 1)");
  expect_near(at(img, 32, 16), {128, 128, 0}, "between red and green");
  expect_near(at(img, 0, 16), {128, 128, 0}, "left edge: wraps to green");
  expect_near(at(img, 16, 0), {128, 0, 128}, "top edge: wraps to blue");
  expect_near(at(img, 32, 32), {128, 128, 128}, "centre: the four texels equally");
  // Every pixel is covered (the quad fills the screen) and none keeps the vertex colour.
  for (const rgb8& c : img.colour) ASSERT_FALSE(c == (rgb8{10, 20, 30}));
}

// A quad receding from x = −1 at z = −2 to x = 1 at z = −4, u = 0 → 1 along it, textured with
// a 256-texel ramp (texel i has red = i) so that bilinear sampling returns red = u·256 − ½
// exactly. Along the middle row each pixel's expected u comes from intersecting its ray with the
// plane z = −3 − x: t = 3 / (1 − dx), x = t·dx, u = (x + 1)/2. Affine (screen-linear)
// interpolation is off by up to ~30 levels here; the test asserts it would be caught.
TEST(TexturedTriangle, TextureCoordinatesArePerspectiveCorrect) {
  const view v(origin_camera(64, 64), vec3d::Zero());
  texture_image ramp;
  ramp.width = 256;
  ramp.height = 1;
  for (int i = 0; i < 256; ++i) ramp.texels.push_back({static_cast<std::uint8_t>(i), 0, 0});
  const auto q =
      quad({vec3f(-1, -0.5f, -2), vec3f(1, -0.5f, -4), vec3f(1, 0.5f, -4), vec3f(-1, 0.5f, -2)},
           {vec2f(0, 0), vec2f(1, 0), vec2f(1, 1), vec2f(0, 1)}, &ramp);
  render_options opt;
  opt.fx = effects{.colour = true};
  const image img = render<colour_only>(v, opt, [&](auto& sink) {
    for (const auto& t : q) sink.textured_triangle(t);
  });
  const int j = 32;
  const double f = v.focal_px;
  // The screen x of the quad's left and right edges on this row (for the affine comparison).
  const double x_left = 32 + f * -1 / 2.0, x_right = 32 + f * 1 / 4.0;
  int checked = 0;
  double worst_affine = 0;
  for (int i = 0; i < 64; ++i) {
    const double dx = (i + 0.5 - 32) / f;
    const double t = 3 / (1 - dx);
    const double u = (t * dx + 1) / 2;
    if (u < 0.02 || u > 0.98) continue;  // away from the edges and the ramp's wrap
    const double want = u * 256 - 0.5;
    EXPECT_NEAR(at(img, i, j).r, want, 1.0) << "pixel " << i;
    const double affine = ((i + 0.5 - x_left) / (x_right - x_left)) * 256 - 0.5;
    worst_affine = std::max(worst_affine, std::abs(affine - want));
    ++checked;
  }
  EXPECT_GT(checked, 30);
  EXPECT_GT(worst_affine, 10.0);  // the test tells perspective-correct from affine
}

/// A sink that forwards only the three required primitives: it does not take textured ones.
template <attributes A>
struct without_hook {
  rasterizer<A, effects{.shading = true, .colour = true}>& r;
  void point(const point_prim<A>& p) { r.point(p); }
  void splat(const splat_prim<A>& s) { r.splat(s); }
  void triangle(const triangle_prim<A>& t) { r.triangle(t); }
};
static_assert(Sink<without_hook<with_normals_colours>, with_normals_colours>);
static_assert(!TexturedTriangleSink<without_hook<with_normals_colours>, with_normals_colours>);

// buffer_sink::replay sends a sink without the hook the triangle_prim inside each textured
// one: the image is byte-identical to drawing those triangles directly. And the textured path
// with the texture missing (null) is triangle() itself.
TEST(TexturedTriangle, SinksWithoutTheHookGetThePlainTriangle) {
  const view v(origin_camera(48, 40), vec3d::Zero());
  texture_image tex;
  tex.width = tex.height = 2;
  tex.texels = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {255, 255, 255}};
  buffer_sink<with_normals_colours> prims;
  textured_triangle_prim<with_normals_colours> t;
  t.triangle.p = {vec3f(-0.5f, -0.4f, -1.5f), vec3f(0.6f, -0.3f, -2), vec3f(0, 0.5f, -1.2f)};
  t.triangle.normal = {vec3f(0, 0, 1), vec3f(0.3f, 0, 1), vec3f(0, 0.3f, 1)};
  t.triangle.colour = {rgb8{200, 10, 10}, rgb8{10, 200, 10}, rgb8{10, 10, 200}};
  t.uv = {vec2f(0, 0), vec2f(3, 0), vec2f(0, 2)};
  t.texture = &tex;
  prims.textured_triangle(t);
  render_options opt;
  opt.fx = effects{.shading = true, .colour = true};
  constexpr effects E{.shading = true, .colour = true};
  rasterizer<with_normals_colours, E> a(v, opt);
  without_hook<with_normals_colours> plain{a};
  prims.replay(plain);
  const image via_replay = a.finish();
  rasterizer<with_normals_colours, E> b(v, opt);
  b.triangle(t.triangle);
  const image direct = b.finish();
  EXPECT_EQ(via_replay.colour, direct.colour);
  EXPECT_EQ(via_replay.depth, direct.depth);
  rasterizer<with_normals_colours, E> c(v, opt);
  auto untextured = t;
  untextured.texture = nullptr;
  c.textured_triangle(untextured);
  const image null_texture = c.finish();
  EXPECT_EQ(null_texture.colour, direct.colour);
  // With the texture the same pixels are covered at the same depths, in other colours.
  rasterizer<with_normals_colours, E> d(v, opt);
  d.textured_triangle(t);
  const image textured = d.finish();
  EXPECT_EQ(textured.depth, direct.depth);
  EXPECT_NE(textured.colour, direct.colour);
  counting_sink<with_normals_colours> count;
  prims.replay(count);
  EXPECT_EQ(count.triangles, 1u);
}

/// The checker quad of CheckerAtHandCheckedPixels as a textured mesh (4 vertices, 2 faces).
triangle_mesh checker_mesh(float s) {
  const float e = 1.0f / 128;
  triangle_mesh m;
  m.vertices.positions = {vec3f(-s, -s, -1), vec3f(s, -s, -1), vec3f(s, s, -1), vec3f(-s, s, -1)};
  m.vertices.normals.assign(4, vec3f(0, 0, 1));
  m.faces = {{0, 1, 2}, {0, 2, 3}};
  const std::array<vec2f, 4> uv{vec2f(-e, e), vec2f(1 - e, e), vec2f(1 - e, 1 + e),
                                vec2f(-e, 1 + e)};
  m.face_texcoords = {{uv[0], uv[1], uv[2]}, {uv[0], uv[2], uv[3]}};
  auto tex = std::make_shared<texture_image>();
  tex->width = tex->height = 2;
  tex->texels = {{255, 0, 0}, {0, 255, 0}, {0, 0, 255}, {255, 255, 255}};
  m.texture = tex;
  return m;
}

// A textured mesh's reference render (what `pbrlod render mesh.obj` and the accuracy report
// compare with) is texture-mapped: the same hand-checked texels as the quad above. It drew the
// mesh untextured (grey, or its vertex colours) while POP drew the texture: POP on the Spot cow
// scored 19 dB against it.
TEST(TexturedTriangle, ReferenceRenderOfATexturedMeshShowsTheTexture) {
  const camera cam = origin_camera(64, 64);
  const view v(cam, vec3d::Zero());
  const triangle_mesh m = checker_mesh(32.0f / v.focal_px);
  render_options opt;
  opt.fx = effects{.colour = true};
  const image img = render_reference(m, cam, opt);
  expect_near(at(img, 16, 16), {255, 0, 0}, "texel (0, 0)");
  expect_near(at(img, 48, 16), {0, 255, 0}, "texel (1, 0)");
  expect_near(at(img, 16, 48), {0, 0, 255}, "texel (0, 1)");
  expect_near(at(img, 48, 48), {255, 255, 255}, "texel (1, 1)");
  // Vertex colours, when the mesh has them too, do not replace the texture.
  triangle_mesh coloured = m;
  coloured.vertices.colours.assign(4, rgb8{10, 20, 30});
  const image again = render_reference(coloured, cam, opt);
  EXPECT_TRUE(again.colour == img.colour);
}

// texture_vertex_colours: each vertex the mean of the texture's samples at its corners. Every
// corner sits on a texel centre (uv = ((i + ½)/2, 1 − (j + ½)/2) is texel (i, j), where the
// bilinear sample is that texel exactly); vertex 0 is a seam, blue in face 0 and red in face 1.
TEST(TextureVertexColours, MeanOfTheCornersSamples) {
  triangle_mesh m = checker_mesh(1);
  const auto centre = [](int i, int j) { return vec2f((i + 0.5f) / 2, 1 - (j + 0.5f) / 2); };
  m.face_texcoords = {{centre(0, 1), centre(1, 1), centre(1, 0)},
                      {centre(0, 0), centre(1, 0), centre(0, 0)}};
  const std::vector<rgb8> c = texture_vertex_colours(m);
  ASSERT_EQ(c.size(), 4u);
  expect_near(c[0], {128, 0, 128}, "vertex 0: blue and red averaged");
  expect_near(c[1], {255, 255, 255}, "vertex 1: white");
  expect_near(c[2], {0, 255, 0}, "vertex 2: green twice");
  expect_near(c[3], {255, 0, 0}, "vertex 3: red");
  // No texture or no coordinates: no colours (the mesh keeps what it has).
  triangle_mesh plain = m;
  plain.texture.reset();
  EXPECT_TRUE(texture_vertex_colours(plain).empty());
  plain = m;
  plain.face_texcoords.clear();
  EXPECT_TRUE(texture_vertex_colours(plain).empty());
  // A vertex no face uses takes the texture's mean colour.
  m.vertices.positions.push_back(vec3f(5, 5, 5));
  m.vertices.normals.push_back(vec3f(0, 0, 1));
  const std::vector<rgb8> d = texture_vertex_colours(m);
  ASSERT_EQ(d.size(), 5u);
  expect_near(d[4], {128, 128, 128}, "unused vertex: mean of red, green, blue, white");
}

}  // namespace
}  // namespace pbr_lod
