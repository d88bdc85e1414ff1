// The hard-case ladder (issue 21): every builder over the same degenerate and hostile inputs.
//
// One test per (builder, case), generated from two tables: `builders()` (every ladder adapter of
// every registered builder) and `ladder()` (the cases). A builder joins by writing its adapter
// header, tests/builders/adapters/ID.hpp — build from a mesh, save, load, and hand its
// Hierarchy and traversal policy to a callback. For each case that must build, the test checks:
//   * hierarchy invariants, walking every node from the root: finite bounding spheres; each
//     child's sphere inside its parent's; everything the node's emit() sends inside its own
//     sphere (the Hierarchy contract, traverse/hierarchy.hpp); finite unit normal cones;
//   * what a traversal at 1 px emits: no NaN or Inf, normals unit length (| |n| − 1 | < 1e-3);
//   * a render through the CPU rasteriser: no NaN depth, and covered pixels whenever the input
//     has something drawable;
//   * save → load gives an equal hierarchy, and saving the loaded one gives the same bytes;
//   * two builds (1 thread and 2 threads) write the same bytes.
// Cases that must be rejected (empty input, NaN/Inf, a builder's documented refusals) must throw
// InvalidArgument whose message matches a stated pattern (it names the element).
//
// Containment tolerance: stored data are float relative to the hierarchy's double origin, so a
// sphere may miss by rounding. "Inside" allows 1e-5 × (radius + |centre|) — about 80 float ulps
// of the larger magnitude, far below any real escape (a sample outside its node by 1 % of the
// node, or a child sphere not merged into its parent, fails it).
#include <gtest/gtest.h>

#include <unistd.h>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <regex>
#include <string>
#include <thread>
#include <tuple>
#include <type_traits>
#include <vector>

#include "all_builder_tests.hpp"  // generated: tests/builders/CMakeLists.txt
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {
namespace {

// ---- the cases ------------------------------------------------------------------------------

/// One rung of the ladder. Every case is a mesh: mesh builders take it whole, point builders its
/// vertices. Point-like cases carry a triangle soup over their points (consecutive triples), so
/// mesh builders see the same positions, as degenerate triangles where the points are.
struct ladder_case {
  std::string name;
  triangle_mesh mesh;
  /// When set, every builder must throw InvalidArgument with a message matching this.
  std::optional<std::string> reject;
  /// Every emitted colour must be this (up to RGB 565 rounding).
  std::optional<rgb8> single_colour;
};

rgb8 varied_colour(std::size_t i) {
  return {static_cast<std::uint8_t>(40 + (i * 37) % 200),
          static_cast<std::uint8_t>(40 + (i * 91) % 200),
          static_cast<std::uint8_t>(40 + (i * 53) % 200)};
}

/// A mesh over `pts` (world = positions, origin 0) with consecutive triples as faces.
triangle_mesh soup(const std::vector<vec3f>& pts) {
  triangle_mesh m;
  m.vertices.positions = pts;
  for (std::size_t i = 0; i < pts.size(); ++i) m.vertices.colours.push_back(varied_colour(i));
  const auto n = static_cast<std::uint32_t>(pts.size());
  for (std::uint32_t k = 0; n > 0 && 3 * k < n; ++k)
    m.faces.push_back({(3 * k) % n, (3 * k + 1) % n, (3 * k + 2) % n});
  return m;
}

/// An nx × ny grid in the plane z = 2, spacing 0.1, triangulated, normals +z.
triangle_mesh grid(int nx, int ny) {
  triangle_mesh m;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      m.vertices.positions.emplace_back(0.1f * static_cast<float>(i), 0.1f * static_cast<float>(j),
                                        2.0f);
      m.vertices.normals.emplace_back(0.f, 0.f, 1.f);
      m.vertices.colours.push_back(varied_colour(m.vertices.positions.size()));
    }
  const auto at = [&](int i, int j) { return static_cast<std::uint32_t>(j * nx + i); };
  for (int j = 0; j + 1 < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      m.faces.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      m.faces.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  return m;
}

/// A UV sphere of radius r about c, angles jittered: every vertex on the sphere (up to float
/// rounding), radial normals, faces counter-clockwise from outside. World coordinates are c + r·d,
/// computed in double and stored relative to `origin`.
triangle_mesh uv_sphere(double r, const vec3d& c, const vec3d& origin = vec3d::Zero()) {
  triangle_mesh m;
  m.vertices.origin = origin;
  constexpr int rings = 16, segs = 32;
  const auto add = [&](const vec3d& d) {
    m.vertices.positions.push_back((c + r * d - origin).cast<float>());
    m.vertices.normals.push_back(d.cast<float>());
    m.vertices.colours.push_back(varied_colour(m.vertices.positions.size()));
  };
  add(vec3d(0, 1, 0));
  // Angles jittered by up to a third of a step (seeded: the same mesh every run), so that no
  // vertex lies exactly on a symmetry plane where a split would depend on the last bit.
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> jitter(-1.0 / 3, 1.0 / 3);
  for (int i = 1; i < rings; ++i)
    for (int j = 0; j < segs; ++j) {
      const double th = std::numbers::pi * (i + jitter(rng)) / rings,
                   ph = 2 * std::numbers::pi * (j + jitter(rng)) / segs;
      add(vec3d(std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph)));
    }
  add(vec3d(0, -1, 0));
  const auto ring = [&](int i, int j) {
    return static_cast<std::uint32_t>(1 + (i - 1) * segs + (j % segs));
  };
  const auto bottom = static_cast<std::uint32_t>(m.vertices.positions.size() - 1);
  for (int j = 0; j < segs; ++j) {
    m.faces.push_back({0, ring(1, j + 1), ring(1, j)});
    m.faces.push_back({bottom, ring(rings - 1, j), ring(rings - 1, j + 1)});
    for (int i = 1; i + 1 < rings; ++i) {
      m.faces.push_back({ring(i, j), ring(i, j + 1), ring(i + 1, j + 1)});
      m.faces.push_back({ring(i, j), ring(i + 1, j + 1), ring(i + 1, j)});
    }
  }
  return m;
}

const vec3d kSphereCentre(1, 1, 1);
constexpr double kSphereRadius = 3;
/// 10⁷ units from the origin, as georeferenced scans are; the stored origin is off the model's
/// centre, as a reader's would be, so a builder that assumed origin = centre would show it.
const vec3d kFar(1e7, -1e7, 1e7);
const vec3d kFarOrigin = kFar + vec3d(0.37, -0.21, 0.13) * kSphereRadius;
constexpr std::size_t kBadIndex = 13;

std::vector<ladder_case> make_ladder() {
  std::vector<ladder_case> l;
  const std::string bad_index = "\\b" + std::to_string(kBadIndex) + "\\b";
  l.push_back({"empty", triangle_mesh{}, "no (points|triangles|vertices)", {}});
  l.push_back({"one_point", soup({vec3f(1, 2, 3)}), {}, {}});
  l.push_back({"two_points", soup({vec3f(0, 0, 0), vec3f(1, 0, 0)}), {}, {}});
  l.push_back({"duplicates", soup(std::vector<vec3f>(200, vec3f(0.5f, -0.25f, 2.f))), {}, {}});
  std::vector<vec3f> line;
  for (int i = 0; i < 200; ++i) line.emplace_back(0.01f * i, 0.02f * i, -0.005f * i);
  l.push_back({"collinear", soup(line), {}, {}});
  l.push_back({"coplanar_grid", grid(30, 30), {}, {}});
  l.push_back({"cospherical", uv_sphere(kSphereRadius, kSphereCentre), {}, {}});
  l.push_back(
      {"far_from_origin", uv_sphere(kSphereRadius, kSphereCentre + kFar, kFarOrigin), {}, {}});
  l.push_back({"scaled_1e-9", uv_sphere(kSphereRadius * 1e-9, kSphereCentre * 1e-9), {}, {}});
  l.push_back({"scaled_1e9", uv_sphere(kSphereRadius * 1e9, kSphereCentre * 1e9), {}, {}});
  {
    auto m = uv_sphere(kSphereRadius, kSphereCentre);
    m.vertices.positions[kBadIndex].y() = std::numeric_limits<float>::quiet_NaN();
    l.push_back({"nan_position", m, bad_index + ".*finite", {}});
    m.vertices.positions[kBadIndex].y() = std::numeric_limits<float>::infinity();
    l.push_back({"inf_position", m, bad_index + ".*finite", {}});
  }
  {
    // Zero-area (collinear), needle, duplicate (rotated), three faces on one edge, a repeated
    // vertex, a single point — next to a proper quad.
    triangle_mesh m;
    m.vertices.positions = {vec3f(0, 0, 0), vec3f(1, 0, 0),     vec3f(0, 1, 0), vec3f(1, 1, 0),
                            vec3f(2, 0, 0), vec3f(0.5f, 0, 0),  vec3f(0, 0, 1), vec3f(0, 0, -1),
                            vec3f(3, 0, 0), vec3f(3, 1e-7f, 0), vec3f(6, 0, 0), vec3f(5, 5, 5)};
    for (std::size_t i = 0; i < m.vertices.positions.size(); ++i)
      m.vertices.colours.push_back(varied_colour(i));
    m.faces = {{0, 1, 2}, {1, 3, 2},  {0, 5, 4},   {1, 2, 0},   {0, 1, 6},
               {0, 1, 7}, {8, 9, 10}, {11, 11, 3}, {11, 11, 11}};
    l.push_back({"degenerate_triangles", m, {}, {}});
  }
  {
    // Vertices no face uses, far from the surface: mesh builders must not draw or bound by them
    // wrongly; point builders take them as points.
    auto m = grid(20, 20);
    for (int i = 0; i < 50; ++i) {
      m.vertices.positions.emplace_back(0.2f * static_cast<float>(i % 7), 5.f,
                                        0.3f * static_cast<float>(i / 7));
      m.vertices.normals.emplace_back(0.f, 1.f, 0.f);
      m.vertices.colours.push_back(varied_colour(1000 + static_cast<std::size_t>(i)));
    }
    l.push_back({"unreferenced_vertices", m, {}, {}});
  }
  {
    auto m = grid(20, 20);
    for (std::size_t i = 0; i < m.vertices.normals.size(); i += 7) m.vertices.normals[i].setZero();
    l.push_back({"zero_normals", m, {}, {}});
    // Every normal zero, as every trained 3-D Gaussian Splatting `.ply` stores them.
    for (auto& n : m.vertices.normals) n.setZero();
    l.push_back({"all_zero_normals", m, {}, {}});
  }
  {
    // One triangle written 50,000 times (its three vertices shared): the ρ-grid's AABB tree
    // overflowed the stack on this. Every builder must build it at the cost of one triangle.
    triangle_mesh m = soup({vec3f(0, 0, 0), vec3f(1, 0, 0), vec3f(0, 1, 0)});
    m.faces.assign(50000, {0, 1, 2});
    l.push_back({"repeated_triangle", m, {}, {}});
  }
  {
    // 2,000 coincident copies of a small grid, each with vertices of its own: 2,000 copies
    // of every triangle for the mesh builders, 2,000 points at each position for the others.
    const triangle_mesh g = grid(4, 4);
    triangle_mesh m;
    for (int c = 0; c < 2000; ++c) {
      const auto base = static_cast<std::uint32_t>(m.vertices.positions.size());
      m.vertices.positions.insert(m.vertices.positions.end(), g.vertices.positions.begin(),
                                  g.vertices.positions.end());
      m.vertices.normals.insert(m.vertices.normals.end(), g.vertices.normals.begin(),
                                g.vertices.normals.end());
      m.vertices.colours.insert(m.vertices.colours.end(), g.vertices.colours.begin(),
                                g.vertices.colours.end());
      for (const auto& f : g.faces) m.faces.push_back({base + f[0], base + f[1], base + f[2]});
    }
    l.push_back({"coincident_copies", m, {}, {}});
  }
  {
    auto m = uv_sphere(kSphereRadius, kSphereCentre);
    const rgb8 c{88, 136, 200};
    std::fill(m.vertices.colours.begin(), m.vertices.colours.end(), c);
    l.push_back({"single_colour", m, {}, c});
  }
  return l;
}

const std::vector<ladder_case>& ladder() {
  static const std::vector<ladder_case> l = make_ladder();
  return l;
}

// ---- the builders ---------------------------------------------------------------------------
//
// One adapter per ladder entry, in each builder's tests/builders/adapters/ID.hpp
// (adapter_support.hpp says what an adapter holds); all_builder_tests.hpp lists them from the
// registry, cmake/builders.cmake.

// ---- the checks -----------------------------------------------------------------------------

constexpr double kContainSlack = 1e-5;
constexpr float kUnitTolerance = 1e-3f;

bool inside(const vec3d& p, double extent, const sphere& s) {
  const vec3d c = s.centre.cast<double>();
  const double slack = kContainSlack * (static_cast<double>(s.radius) + c.norm());
  return (p - c).norm() + extent <= static_cast<double>(s.radius) + slack;
}

/// Half the longest chord of the ellipse centre + cos t·u + sin t·v: √λmax of the Gram matrix.
double ellipse_extent(const vec3f& u, const vec3f& v) {
  const double a = u.cast<double>().squaredNorm(), b = u.cast<double>().dot(v.cast<double>()),
               c = v.cast<double>().squaredNorm();
  return std::sqrt(0.5 * (a + c) + std::sqrt(0.25 * (a - c) * (a - c) + b * b));
}

/// Checks every primitive: finite, unit normals, the case's single colour, and (when `bound` is
/// set) inside that sphere. Counts failures so one message per kind reports them.
template <attributes A>
struct checking_sink {
  const sphere* bound = nullptr;
  std::optional<rgb8> colour;
  std::size_t prims = 0, not_finite = 0, not_unit = 0, outside = 0, wrong_colour = 0;

  void normal(const vec3f& n) {
    if (!all_finite(n))
      ++not_finite;
    else if (std::abs(n.norm() - 1) >= kUnitTolerance)
      ++not_unit;
  }
  void position(const vec3f& p, double extent) {
    if (!all_finite(p) || !std::isfinite(extent))
      ++not_finite;
    else if (bound && !inside(p.cast<double>(), extent, *bound))
      ++outside;
  }
  void paint(const rgb8& c) {
    if (!colour) return;
    const auto off = [](int a, int b) { return std::abs(a - b) > 8; };
    if (off(c.r, colour->r) || off(c.g, colour->g) || off(c.b, colour->b)) ++wrong_colour;
  }
  template <class P>
  void attributes_of(const P& p) {
    if constexpr (A.normal) normal(p.normal);
    if constexpr (A.colour) paint(p.colour);
  }
  void point(const point_prim<A>& p) {
    ++prims;
    position(p.position, 0);
    if (!std::isfinite(p.size_px)) ++not_finite;
    attributes_of(p);
  }
  void splat(const splat_prim<A>& s) {
    ++prims;
    if (!all_finite(s.u) || !all_finite(s.v)) ++not_finite;
    position(s.centre, ellipse_extent(s.u, s.v));
    attributes_of(s);
  }
  void triangle(const triangle_prim<A>& t) {
    ++prims;
    for (std::size_t k = 0; k < 3; ++k) {
      position(t.p[k], 0);
      if constexpr (A.normal) normal(t.normal[k]);
      if constexpr (A.colour) paint(t.colour[k]);
    }
  }
  void expect_clean(const std::string& where) const {
    EXPECT_EQ(not_finite, 0u) << where << ": primitives with NaN or Inf";
    EXPECT_EQ(not_unit, 0u) << where << ": normals not unit length";
    EXPECT_EQ(outside, 0u) << where << ": primitives outside the emitting node's sphere";
    EXPECT_EQ(wrong_colour, 0u) << where << ": colours other than the input's single colour";
  }
};

/// The camera every check uses: the input's bounding sphere (world, double) seen from 3 radii.
camera ladder_camera(const point_cloud& pts, int size) {
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    lo = lo.cwiseMin(pts.world(i));
    hi = hi.cwiseMax(pts.world(i));
  }
  const vec3d c = 0.5 * (lo + hi);
  double r = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) r = std::max(r, (pts.world(i) - c).norm());
  return camera::orbit(c, r, 30, 20, 3, 1, {size, size});
}

/// Walks every node: spheres finite and nested, cones finite and unit, each node's emit() inside
/// its sphere, finite, with unit normals. Returns the number of nodes.
template <class H>
std::size_t check_nodes(const H& h, const view& v, const std::optional<rgb8>& colour) {
  using id = typename H::node_id;
  std::vector<id> stack{h.root()};
  std::size_t nodes = 0, bad_sphere = 0, escaping = 0, bad_cone = 0;
  checking_sink<H::attrs> emitted{.colour = colour};
  while (!stack.empty()) {
    const id n = stack.back();
    stack.pop_back();
    ++nodes;
    const sphere s = h.bounding_sphere(n);
    if (!all_finite(s.centre) || !std::isfinite(s.radius) || s.radius < 0) ++bad_sphere;
    if constexpr (HasNormalCones<H>) {
      const normal_cone k = h.normal_cone(n);
      if (!all_finite(k.axis) || std::abs(k.axis.norm() - 1) >= kUnitTolerance ||
          !(k.semi_angle >= 0 && k.semi_angle <= std::numbers::pi_v<float> + 1e-6f))
        ++bad_cone;
    }
    for (const auto& c : h.children(n)) {
      const sphere cs = h.bounding_sphere(c);
      if (!inside(cs.centre.cast<double>(), cs.radius, s)) ++escaping;
      stack.push_back(c);
    }
    emitted.bound = &s;
    h.emit(n, v, emitted);
  }
  EXPECT_EQ(bad_sphere, 0u) << "non-finite or negative bounding spheres";
  EXPECT_EQ(escaping, 0u) << "child spheres not inside their parent's";
  EXPECT_EQ(bad_cone, 0u) << "normal cones not finite and unit";
  emitted.expect_clean("emit() of every node");
  EXPECT_GT(emitted.prims, 0u) << "no node emits anything";
  return nodes;
}

std::vector<char> file_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

std::string temp_path(const std::string& builder, const std::string& what) {
  return (std::filesystem::temp_directory_path() /
          ("pbr_lod_ladder_" + std::to_string(::getpid()) + "_" + builder + "_" + what + ".lod"))
      .string();
}

/// True when the input has something the builder's output can draw: any point, or for a builder
/// whose leaves draw triangles (draws_faces_only), a triangle of non-zero area — a mesh of
/// degenerate triangles only draws nothing, like the mesh itself.
bool drawable(const ladder_case& c, bool faces_only) {
  if (c.mesh.vertices.empty()) return false;
  if (!faces_only) return true;
  const auto& P = c.mesh.vertices.positions;
  for (const auto& f : c.mesh.faces)
    if ((P[f[1]] - P[f[0]]).cross(P[f[2]] - P[f[0]]).squaredNorm() > 0) return true;
  return false;
}

template <class Adapter>
void run_case(const ladder_case& c) {
  const std::string builder = Adapter::name;
  std::optional<std::string> reject = c.reject;
  if (!reject) reject = Adapter::rejects(c.name);
  if (reject) {
    try {
      (void)Adapter::build(c.mesh, 1);
      ADD_FAILURE() << "built; expected InvalidArgument matching /" << *reject << "/";
    } catch (const InvalidArgument& e) {
      std::printf("%s, %s: rejected: %s\n", Adapter::name, c.name.c_str(), e.what());
      EXPECT_TRUE(std::regex_search(e.what(), std::regex(*reject)))
          << "message \"" << e.what() << "\" does not match /" << *reject << "/";
    }
    return;
  }
  const typename Adapter::built b = Adapter::build(c.mesh, 1);
  Adapter::visit(b, [&](const auto& h, const auto& make_policy) {
    using H = std::decay_t<decltype(h)>;
    ASSERT_FALSE(h.empty());
    ASSERT_TRUE(all_finite(h.origin()));
    const camera cam = ladder_camera(c.mesh.vertices, 64);
    const view v(cam, h.origin());
    check_nodes(h, v, c.single_colour);

    checking_sink<H::attrs> cut{.colour = c.single_colour};
    const auto st = traverse(h, v, {.tolerance_px = 1}, cut, make_policy(v));
    cut.expect_clean("traversal at 1 px");
    EXPECT_EQ(cut.prims, st.primitives());

    render_options ro;
    ro.fx = {.shading = H::attrs.normal, .colour = H::attrs.colour};
    const image img = render<H::attrs>(
        v, ro, [&](auto& sink) { traverse(h, v, {.tolerance_px = 1}, sink, make_policy(v)); });
    EXPECT_EQ(
        std::count_if(img.depth.begin(), img.depth.end(), [](float d) { return std::isnan(d); }),
        0);
    constexpr bool faces_only = requires {
      Adapter::draws_faces_only;
    };
    if (drawable(c, faces_only)) {
      EXPECT_GT(img.covered_count(), 0u) << "nothing drawn";
    }
  });

  const std::string path = temp_path(builder, c.name), again = temp_path(builder, c.name + "_2");
  Adapter::save(b, path);
  const auto bytes = file_bytes(path);
  const auto loaded = Adapter::load(path);
  EXPECT_TRUE(loaded == b) << "load(save(h)) differs from h";
  Adapter::save(loaded, again);
  EXPECT_TRUE(file_bytes(again) == bytes) << "saving the loaded hierarchy gives other bytes";
  Adapter::save(Adapter::build(c.mesh, 2), again);
  EXPECT_TRUE(file_bytes(again) == bytes) << "two builds (1 and 2 threads) give other bytes";
  std::filesystem::remove(path);
  std::filesystem::remove(again);
}

/// The far case renders like the same sphere at the origin, each seen by a camera placed
/// relative to its own data: the hierarchy keeps a double origin, so the images can differ only
/// where float rounding moves an edge by a pixel. Measured: identical images for the point
/// octree, the ρ-grid, the PCA octree and PMR, 89 dB for POP. 40 dB and 1 % of the covered
/// pixels fail on any real loss of precision (a float
/// origin at 10⁷ rounds positions to whole units: a blur) and on any rule that a last bit
/// decides (the PCA octree's span generator picked a square leaf's longer side by its extents'
/// last bits: 23 dB, every such leaf's points mirrored).
template <class Adapter>
void run_far(const ladder_case& near_case, const ladder_case& far_case) {
  const auto draw = [](const ladder_case& c) {
    const auto b = Adapter::build(c.mesh, 1);
    image img;
    Adapter::visit(b, [&](const auto& h, const auto& make_policy) {
      using H = std::decay_t<decltype(h)>;
      const view v(ladder_camera(c.mesh.vertices, 256), h.origin());
      render_options ro;
      ro.fx = {.shading = H::attrs.normal, .colour = H::attrs.colour};
      img = render<H::attrs>(
          v, ro, [&](auto& sink) { traverse(h, v, {.tolerance_px = 1}, sink, make_policy(v)); });
    });
    return img;
  };
  const image a = draw(near_case), b = draw(far_case);
  const auto err = compare_images(a, b);
  std::printf("%s: near %zu px, far %zu px covered, PSNR %.2f dB\n", Adapter::name,
              a.covered_count(), b.covered_count(), err.psnr);
  ASSERT_GT(a.covered_count(), 400u);  // the ρ-grid from points: one pixel per input point
  EXPECT_LT(
      std::abs(static_cast<double>(a.covered_count()) - static_cast<double>(b.covered_count())),
      0.01 * static_cast<double>(a.covered_count()));
  EXPECT_GT(err.psnr, 40.0);
}

/// Every hierarchy promises that const traversals are safe from several threads at once
/// (traverse/hierarchy.hpp). Four threads each traverse the one loaded hierarchy from four
/// views, three times over, and must emit exactly what one thread emitted alone. Run under
/// ThreadSanitizer (`cmake --preset tsan`, scripts/tsan.sh) this is the check of the promise; in
/// the other builds it still catches state a traversal shares and changes.
template <class Adapter>
void run_concurrent(const ladder_case& c) {
  const std::string path = temp_path(Adapter::name, "concurrent");
  Adapter::save(Adapter::build(c.mesh, 2), path);
  const auto b = Adapter::load(path);  // loaded, as a host renderer has it
  std::filesystem::remove(path);
  Adapter::visit(b, [&](const auto& h, const auto& make_policy) {
    using H = std::decay_t<decltype(h)>;
    std::vector<view> views;
    for (const double az : {0.0, 90.0, 200.0, 300.0}) {
      camera cam = ladder_camera(c.mesh.vertices, 96);
      const vec3d d = cam.eye - cam.target;
      const double a = az * std::numbers::pi / 180;
      cam.eye = cam.target + vec3d(std::cos(a) * d.x() + std::sin(a) * d.z(), d.y(),
                                   -std::sin(a) * d.x() + std::cos(a) * d.z());
      views.emplace_back(cam, h.origin());
    }
    const auto cut = [&](const view& v) {
      buffer_sink<H::attrs> s;
      traverse(h, v, {.tolerance_px = 1}, s, make_policy(v));
      // Every primitive's position, in order (points, splat centres, triangle corners, Gaussians).
      std::vector<vec3f> at;
      for (const auto& p : s.points) at.push_back(p.position);
      for (const auto& q : s.splats) at.push_back(q.centre);
      for (const auto& t : s.triangles) at.insert(at.end(), t.p.begin(), t.p.end());
      for (const auto& g : s.gaussians) at.push_back(g.position);
      return at;
    };
    std::vector<decltype(cut(views[0]))> alone;
    for (const view& v : views) alone.push_back(cut(v));
    std::atomic<int> differ{0};
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
      threads.emplace_back([&, t] {
        for (int round = 0; round < 3; ++round)
          for (std::size_t k = 0; k < views.size(); ++k) {
            const std::size_t vi = (k + std::size_t(t)) % views.size();
            if (cut(views[vi]) != alone[vi]) ++differ;
          }
      });
    for (auto& th : threads) th.join();
    EXPECT_EQ(differ.load(), 0) << "cuts drawn concurrently differ from one thread's";
    EXPECT_GT(alone[0].size(), 100u);
  });
}

/// Cut normals against the sphere's radial directions: how many primitives' normals lie within
/// 25° of the radial line (either sign), and how many point outwards.
struct radial_agreement {
  std::size_t normals = 0, on_line = 0, outward = 0;
  [[nodiscard]] double line_fraction() const { return double(on_line) / double(normals); }
  [[nodiscard]] double outward_fraction() const { return double(outward) / double(normals); }
};

template <class Adapter>
radial_agreement agreement(const typename Adapter::built& b, const point_cloud& pts,
                           const vec3d& centre) {
  radial_agreement a;
  Adapter::visit(b, [&](const auto& h, const auto& make_policy) {
    using H = std::decay_t<decltype(h)>;
    if constexpr (H::attrs.normal) {
      const view v(ladder_camera(pts, 128), h.origin());
      buffer_sink<H::attrs> s;
      // Without the Gaussian hook: a Gaussian hierarchy sends the splats (with their surface
      // normals) that every sink without it gets; the other builders send what they always do.
      struct surface_sink {
        buffer_sink<H::attrs>& b;
        void point(const point_prim<H::attrs>& p) { b.point(p); }
        void splat(const splat_prim<H::attrs>& q) { b.splat(q); }
        void triangle(const triangle_prim<H::attrs>& t) { b.triangle(t); }
      } surface{s};
      traverse(h, v, {.tolerance_px = 1}, surface, make_policy(v));
      const auto add = [&](const vec3f& p, const vec3f& n) {
        ASSERT_TRUE(all_finite(p) && all_finite(n));
        const vec3d r = (h.origin() + p.cast<double>() - centre).normalized();
        const double c = r.dot(n.cast<double>().normalized());
        ++a.normals;
        a.on_line += std::abs(c) >= std::cos(25 * std::numbers::pi / 180) ? 1 : 0;
        a.outward += c > 0 ? 1 : 0;
      };
      for (const auto& q : s.points) add(q.position, q.normal);
      for (const auto& q : s.splats) add(q.centre, q.normal);
      for (const auto& t : s.triangles)
        for (std::size_t k = 0; k < 3; ++k) add(t.p[k], t.normal[k]);
    }
  });
  return a;
}

/// A zero or non-finite normal is no normal. The jittered sphere with every fifth normal zero
/// (and one NaN), and with every normal zero: each build reports how many it estimated (where
/// it reports), and draws normals that agree with the sphere as the build from the true normals
/// does — within 5 % of its primitives on the radial line; the partly zeroed sphere also
/// outwards (the given normals orient the estimates), the all-zero one inwards or outwards as a
/// whole (≥ 95 % one way: an estimate has no outside to go by).
template <class Adapter>
void run_missing_normals(const ladder_case& sphere) {
  const triangle_mesh& truth = sphere.mesh;
  triangle_mesh some = truth, none = truth;
  std::size_t zeroed = 0;
  for (std::size_t i = 0; i < some.vertices.normals.size(); i += 5, ++zeroed)
    some.vertices.normals[i].setZero();
  some.vertices.normals[3].x() = std::numeric_limits<float>::quiet_NaN();
  ++zeroed;
  for (auto& n : none.vertices.normals) n.setZero();
  const auto ref = agreement<Adapter>(Adapter::build(truth, 1), truth.vertices, kSphereCentre);
  ASSERT_GT(ref.normals, 100u);
  std::printf("%s: true normals %.3f on the line, %.3f outward\n", Adapter::name,
              ref.line_fraction(), ref.outward_fraction());
  for (const auto* m : {&some, &none}) {
    const bool all = m == &none;
    const auto b = Adapter::build(*m, 1);
    if (const auto filled = Adapter::normals_filled(b)) {
      EXPECT_EQ(*filled, all ? m->vertices.size() : zeroed) << (all ? "all zero" : "some zero");
    }
    const auto a = agreement<Adapter>(b, m->vertices, kSphereCentre);
    std::printf("%s, %s zero: %.3f on the line, %.3f outward\n", Adapter::name,
                all ? "all" : "some", a.line_fraction(), a.outward_fraction());
    EXPECT_GE(a.line_fraction(), ref.line_fraction() - 0.05) << (all ? "all zero" : "some zero");
    if (all) {
      EXPECT_GE(std::max(a.outward_fraction(), 1 - a.outward_fraction()), 0.95);
    } else {
      EXPECT_GE(a.outward_fraction(), std::min(0.95, ref.outward_fraction()));
    }
  }
}

struct builder_entry {
  std::string name;
  std::function<void(const ladder_case&)> run;
  std::function<void(const ladder_case&, const ladder_case&)> far;
  std::function<void(const ladder_case&)> concurrent;
  std::function<void(const ladder_case&)> missing_normals;
};

template <class Adapter>
builder_entry entry() {
  return {Adapter::name, &run_case<Adapter>, &run_far<Adapter>, &run_concurrent<Adapter>,
          &run_missing_normals<Adapter>};
}

/// The builders on the ladder, in the registry's order: every ladder adapter of every builder.
const std::vector<builder_entry>& builders() {
  static const std::vector<builder_entry> b = [] {
    std::vector<builder_entry> all;
    const auto add_builder = [&all]<class Tests>(std::type_identity<Tests>) {
      [&all]<class... Adapter>(std::type_identity<std::tuple<Adapter...>>) {
        (all.push_back(entry<Adapter>()), ...);
      }(std::type_identity<typename Tests::ladder>{});
    };
    [&]<class... Tests>(std::type_identity<std::tuple<Tests...>>) {
      (add_builder(std::type_identity<Tests>{}), ...);
    }(std::type_identity<test::all_builder_tests>{});
    return all;
  }();
  return b;
}

// ---- the tests ------------------------------------------------------------------------------

class Ladder : public ::testing::TestWithParam<std::tuple<std::size_t, std::size_t>> {};

TEST_P(Ladder, Holds) {
  const auto [b, c] = GetParam();
  builders()[b].run(ladder()[c]);
}

INSTANTIATE_TEST_SUITE_P(AllBuilders, Ladder,
                         ::testing::Combine(::testing::Range<std::size_t>(0, builders().size()),
                                            ::testing::Range<std::size_t>(0, ladder().size())),
                         [](const auto& p) {
                           std::string s = builders()[std::get<0>(p.param)].name + "_" +
                                           ladder()[std::get<1>(p.param)].name;
                           for (char& ch : s)
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           return s;
                         });

class FarCloud : public ::testing::TestWithParam<std::size_t> {};

TEST_P(FarCloud, RendersLikeTheOneAtTheOrigin) {
  const auto find = [](const std::string& name) {
    return *std::find_if(ladder().begin(), ladder().end(),
                         [&](const ladder_case& c) { return c.name == name; });
  };
  builders()[GetParam()].far(find("cospherical"), find("far_from_origin"));
}

INSTANTIATE_TEST_SUITE_P(AllBuilders, FarCloud, ::testing::Range<std::size_t>(0, builders().size()),
                         [](const auto& p) { return builders()[p.param].name; });

class ConcurrentTraversal : public ::testing::TestWithParam<std::size_t> {};

TEST_P(ConcurrentTraversal, ThreadsDrawWhatOneThreadDraws) {
  const auto find = [](const std::string& name) {
    return *std::find_if(ladder().begin(), ladder().end(),
                         [&](const ladder_case& c) { return c.name == name; });
  };
  builders()[GetParam()].concurrent(find("cospherical"));
}

INSTANTIATE_TEST_SUITE_P(AllBuilders, ConcurrentTraversal,
                         ::testing::Range<std::size_t>(0, builders().size()),
                         [](const auto& p) { return builders()[p.param].name; });

class MissingNormals : public ::testing::TestWithParam<std::size_t> {};

TEST_P(MissingNormals, EstimatedLikeTheTrueOnes) {
  builders()[GetParam()].missing_normals(
      *std::find_if(ladder().begin(), ladder().end(),
                    [](const ladder_case& c) { return c.name == "cospherical"; }));
}

INSTANTIATE_TEST_SUITE_P(AllBuilders, MissingNormals,
                         ::testing::Range<std::size_t>(0, builders().size()),
                         [](const auto& p) { return builders()[p.param].name; });

}  // namespace
}  // namespace pbr_lod
