// Generated inputs: see include/pbr_lod/core/synthetic.hpp.
#include "pbr_lod/core/synthetic.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

namespace pbr_lod {
namespace {

rgb8 to_rgb(const vec3f& c) {
  const auto q = [](float x) {
    return static_cast<std::uint8_t>(std::clamp(x, 0.0f, 1.0f) * 255.0f + 0.5f);
  };
  return {q(c.x()), q(c.y()), q(c.z())};
}

// Hue in [0,1) to a saturated RGB colour.
vec3f hue(float h) {
  h = h - std::floor(h);
  const float r = std::clamp(std::abs(h * 6 - 3) - 1, 0.0f, 1.0f);
  const float g = std::clamp(2 - std::abs(h * 6 - 2), 0.0f, 1.0f);
  const float b = std::clamp(2 - std::abs(h * 6 - 4), 0.0f, 1.0f);
  return {r, g, b};
}

struct builder {
  triangle_mesh m;
  std::uint32_t vertex(const vec3f& p, const vec3f& n, const vec3f& c) {
    m.vertices.positions.push_back(p);
    m.vertices.normals.push_back(n.normalized());
    m.vertices.colours.push_back(to_rgb(c));
    return static_cast<std::uint32_t>(m.vertices.positions.size() - 1);
  }
  void tri(std::uint32_t a, std::uint32_t b, std::uint32_t c) { m.faces.push_back({a, b, c}); }

  // The faces of a latitude/longitude sphere whose (rings + 1) × (segs + 1) vertices start at
  // `base`, ring by ring; the pole rings get one triangle per segment.
  void sphere_faces(std::uint32_t base, int rings, int segs) {
    const auto at = [&](int i, int j) {
      return base + static_cast<std::uint32_t>(j * (segs + 1) + i);
    };
    for (int j = 0; j < rings; ++j)
      for (int i = 0; i < segs; ++i) {
        if (j > 0) tri(at(i, j), at(i + 1, j), at(i + 1, j + 1));
        if (j < rings - 1) tri(at(i, j), at(i + 1, j + 1), at(i, j + 1));
      }
  }

  // A grid patch p(u,v) = o + u·U + v·V, u,v in [0,1], with n×k quads, flat normal U×V.
  void patch(const vec3f& o, const vec3f& U, const vec3f& V, int n, int k, const vec3f& colour,
             bool stripes) {
    const vec3f normal = U.cross(V).normalized();
    const auto base = static_cast<std::uint32_t>(m.vertices.positions.size());
    for (int j = 0; j <= k; ++j)
      for (int i = 0; i <= n; ++i) {
        const float u = static_cast<float>(i) / static_cast<float>(n);
        const float v = static_cast<float>(j) / static_cast<float>(k);
        vec3f c = colour;
        if (stripes && (static_cast<int>(v * 12) % 2 == 0)) c = vec3f(0.95f, 0.95f, 0.9f);
        vertex(o + u * U + v * V, normal, c);
      }
    const auto at = [&](int i, int j) {
      return base + static_cast<std::uint32_t>(j * (n + 1) + i);
    };
    for (int j = 0; j < k; ++j)
      for (int i = 0; i < n; ++i) {
        tri(at(i, j), at(i + 1, j), at(i + 1, j + 1));
        tri(at(i, j), at(i + 1, j + 1), at(i, j + 1));
      }
  }

  // An axis-aligned box with per-face vertices (sharp creases).
  void box(const vec3f& lo, const vec3f& hi, int n, const std::array<vec3f, 6>& colours,
           bool stripes) {
    const vec3f d = hi - lo;
    const vec3f X(d.x(), 0, 0), Y(0, d.y(), 0), Z(0, 0, d.z());
    const auto cells = [&](float a) {
      return std::max(1, static_cast<int>(std::lround(n * a / d.maxCoeff())));
    };
    patch(lo, Y, X, cells(d.y()), cells(d.x()), colours[0], stripes);      // -z
    patch(lo + Z, X, Y, cells(d.x()), cells(d.y()), colours[1], stripes);  // +z
    patch(lo, Z, Y, cells(d.z()), cells(d.y()), colours[2], stripes);      // -x
    patch(lo + X, Y, Z, cells(d.y()), cells(d.z()), colours[3], stripes);  // +x
    patch(lo, X, Z, cells(d.x()), cells(d.z()), colours[4], stripes);      // -y
    patch(lo + Y, Z, X, cells(d.z()), cells(d.x()), colours[5], stripes);  // +y
  }
};

}  // namespace

triangle_mesh make_demo_scene(int detail) {
  detail = std::clamp(detail, 4, 4096);
  builder b;
  // 1. Sphere with rings crowded towards the north pole: latitude t ↦ π·t² puts most rings near
  //    the top, so sampling density varies by ~an order of magnitude over the surface.
  {
    const vec3f c(-1.3f, 1.0f, 0);
    const float r = 1.0f;
    const int rings = 2 * detail, segs = 2 * detail;
    const auto base = static_cast<std::uint32_t>(b.m.vertices.positions.size());
    for (int j = 0; j <= rings; ++j) {
      const float t = static_cast<float>(j) / static_cast<float>(rings);
      const float theta = std::numbers::pi_v<float> * t * t;
      for (int i = 0; i <= segs; ++i) {
        const float phi =
            2 * std::numbers::pi_v<float> * static_cast<float>(i) / static_cast<float>(segs);
        const vec3f n(std::sin(theta) * std::cos(phi), std::cos(theta),
                      std::sin(theta) * std::sin(phi));
        b.vertex(c + r * n, n, hue(0.6f * t + 0.05f));
      }
    }
    b.sphere_faces(base, rings, segs);
  }
  // 2. A box with sharp creases, one colour per face.
  b.box(vec3f(0.4f, 0.0f, -0.7f), vec3f(1.8f, 1.4f, 0.7f), detail,
        {vec3f(0.9f, 0.2f, 0.2f), vec3f(0.2f, 0.8f, 0.3f), vec3f(0.2f, 0.3f, 0.9f),
         vec3f(0.9f, 0.8f, 0.2f), vec3f(0.8f, 0.3f, 0.8f), vec3f(0.2f, 0.8f, 0.8f)},
        false);
  // 3. A thin fin: 2 units tall, 1.2 long, 0.02 thick (1/100 of its height), striped.
  const vec3f fin(0.8f, 0.3f, 0.3f);
  b.box(vec3f(-0.3f, 0.0f, -1.4f), vec3f(0.9f, 2.0f, -1.38f), detail,
        {fin, fin, fin, fin, fin, fin}, true);
  // 4. A floor slab under everything, a little darker, so shadows and holes have a receiver.
  const vec3f floor(0.55f, 0.55f, 0.5f);
  b.box(vec3f(-2.6f, -0.1f, -1.8f), vec3f(2.2f, 0.0f, 1.4f), detail,
        {floor, floor, floor, floor, floor, floor}, false);
  return std::move(b.m);
}

triangle_mesh make_hard_cases_scene(int detail) {
  detail = std::clamp(detail, 4, 1024);
  builder b;
  // Two spheres, gap 0.04 between them, 0.1 above the floor.
  const auto sphere = [&](const vec3f& c, float r, const vec3f& colour) {
    const int rings = detail, segs = 2 * detail;
    const auto base = static_cast<std::uint32_t>(b.m.vertices.positions.size());
    for (int j = 0; j <= rings; ++j) {
      const float theta = std::numbers::pi_v<float> * static_cast<float>(j) / float(rings);
      for (int i = 0; i <= segs; ++i) {
        const float phi = 2 * std::numbers::pi_v<float> * static_cast<float>(i) / float(segs);
        const vec3f n(std::sin(theta) * std::cos(phi), std::cos(theta),
                      std::sin(theta) * std::sin(phi));
        b.vertex(c + r * n, n, colour);
      }
    }
    b.sphere_faces(base, rings, segs);
  };
  sphere(vec3f(-0.52f, 0.6f, 0), 0.5f, vec3f(0.85f, 0.2f, 0.2f));
  sphere(vec3f(0.52f, 0.6f, 0), 0.5f, vec3f(0.2f, 0.3f, 0.9f));
  // The floor: y = 0, normal +y, a grid of 2·detail × (3·detail/2) quads with a square hole.
  // Tiles of the checkerboard are 4 × 4 quads; a vertex takes the colour of the tile it starts.
  {
    const int nx = 2 * detail, nz = 3 * detail / 2;
    const float x0 = -1.6f, z0 = -1.2f, dx = 3.2f / float(nx), dz = 2.4f / float(nz);
    const auto base = static_cast<std::uint32_t>(b.m.vertices.positions.size());
    for (int j = 0; j <= nz; ++j)
      for (int i = 0; i <= nx; ++i) {
        const bool dark = ((i / 4) + (j / 4)) % 2 == 1;
        b.vertex(vec3f(x0 + dx * float(i), 0, z0 + dz * float(j)), vec3f(0, 1, 0),
                 dark ? vec3f(0.25f, 0.45f, 0.25f) : vec3f(0.9f, 0.85f, 0.6f));
      }
    const auto at = [&](int i, int j) {
      return base + static_cast<std::uint32_t>(j * (nx + 1) + i);
    };
    for (int j = 0; j < nz; ++j)
      for (int i = 0; i < nx; ++i) {
        const float cx = x0 + dx * (float(i) + 0.5f), cz = z0 + dz * (float(j) + 0.5f);
        if (cx > -0.3f && cx < 0.3f && cz > 0.55f && cz < 1.05f) continue;  // the hole
        b.tri(at(i, j), at(i, j + 1), at(i + 1, j + 1));  // counter-clockwise seen from +y
        b.tri(at(i, j), at(i + 1, j + 1), at(i + 1, j));
      }
  }
  // The wall on the floor's back edge (z = −1.2), facing +z, with a hue ramp along x.
  {
    const int nx = 2 * detail, ny = detail / 2;
    const auto base = static_cast<std::uint32_t>(b.m.vertices.positions.size());
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        const float u = float(i) / float(nx);
        b.vertex(vec3f(-1.6f + 3.2f * u, float(j) / float(ny), -1.2f), vec3f(0, 0, 1),
                 hue(0.8f * u));
      }
    const auto at = [&](int i, int j) {
      return base + static_cast<std::uint32_t>(j * (nx + 1) + i);
    };
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        b.tri(at(i, j), at(i + 1, j), at(i + 1, j + 1));
        b.tri(at(i, j), at(i + 1, j + 1), at(i, j + 1));
      }
  }
  return std::move(b.m);
}

point_cloud sample_surface(const triangle_mesh& mesh, std::size_t n, std::uint64_t seed) {
  mesh.validate("sample_surface input");
  point_cloud out;
  out.origin = mesh.vertices.origin;
  if (mesh.faces.empty() || n == 0) return out;
  const auto& P = mesh.vertices.positions;
  std::vector<double> cdf(mesh.faces.size());
  double total = 0;
  for (std::size_t f = 0; f < mesh.faces.size(); ++f) {
    const auto& t = mesh.faces[f];
    total +=
        0.5 * (P[t[1]] - P[t[0]]).cast<double>().cross((P[t[2]] - P[t[0]]).cast<double>()).norm();
    cdf[f] = total;
  }
  if (!(total > 0)) return out;  // all faces degenerate: nothing to sample
  const bool normals = !mesh.vertices.normals.empty();
  const bool colours = !mesh.vertices.colours.empty();
  out.positions.reserve(n);
  out.normals.reserve(n);
  if (colours) out.colours.reserve(n);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u01(0, 1);
  for (std::size_t s = 0; s < n; ++s) {
    const double x = u01(rng) * total;
    const auto f =
        static_cast<std::size_t>(std::lower_bound(cdf.begin(), cdf.end(), x) - cdf.begin());
    const auto& t = mesh.faces[std::min(f, mesh.faces.size() - 1)];
    double a = u01(rng), b = u01(rng);
    if (a + b > 1) {
      a = 1 - a;
      b = 1 - b;
    }
    const double c = 1 - a - b;
    const auto w = [&](const vec3f& p0, const vec3f& p1, const vec3f& p2) {
      return (c * p0.cast<double>() + a * p1.cast<double>() + b * p2.cast<double>()).cast<float>();
    };
    out.positions.push_back(w(P[t[0]], P[t[1]], P[t[2]]));
    vec3f nn = (P[t[1]] - P[t[0]]).cross(P[t[2]] - P[t[0]]);
    if (normals) {
      const vec3f ni =
          w(mesh.vertices.normals[t[0]], mesh.vertices.normals[t[1]], mesh.vertices.normals[t[2]]);
      if (ni.norm() > 1e-12f) nn = ni;
    }
    out.normals.push_back(nn.norm() > 0 ? vec3f(nn.normalized()) : vec3f::UnitZ());
    if (colours) {
      const auto& C = mesh.vertices.colours;
      const auto ch = [&](auto get) {
        return static_cast<std::uint8_t>(
            std::lround(c * get(C[t[0]]) + a * get(C[t[1]]) + b * get(C[t[2]])));
      };
      out.colours.push_back({ch([](rgb8 q) { return q.r; }), ch([](rgb8 q) { return q.g; }),
                             ch([](rgb8 q) { return q.b; })});
    }
  }
  return out;
}

point_cloud make_wavy_surface(std::size_t n, std::uint64_t seed) {
  // A torus-like closed surface: tube radius modulated by waves in both angles, so curvature and
  // density vary. Sampled by uniform angles (density varies with the local area element).
  point_cloud out;
  out.positions.reserve(n);
  out.normals.reserve(n);
  out.colours.reserve(n);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> ang(0, 2 * std::numbers::pi_v<float>);
  const float R = 1.0f;
  for (std::size_t i = 0; i < n; ++i) {
    const float u = ang(rng), v = ang(rng);
    const auto pos = [&](float uu, float vv) {
      const float r = 0.35f + 0.05f * std::sin(5 * uu) * std::cos(3 * vv);
      return vec3f((R + r * std::cos(vv)) * std::cos(uu), r * std::sin(vv),
                   (R + r * std::cos(vv)) * std::sin(uu));
    };
    const float h = 1e-3f;
    const vec3f p = pos(u, v);
    const vec3f du = pos(u + h, v) - pos(u - h, v), dv = pos(u, v + h) - pos(u, v - h);
    vec3f nn = du.cross(dv);
    nn = nn.norm() > 0 ? vec3f(nn.normalized()) : vec3f::UnitY();
    out.positions.push_back(p);
    out.normals.push_back(nn);
    out.colours.push_back(to_rgb(hue(u / (2 * std::numbers::pi_v<float>))));
  }
  return out;
}

namespace {

struct lidar_box {
  float x0, y0, x1, y1, height;
  [[nodiscard]] bool contains(float x, float y) const {
    return x >= x0 && x <= x1 && y >= y0 && y <= y1;
  }
};

struct lidar_tree {
  float x, y, radius, base, top;
};

float lidar_ground(float x, float y) {
  return 2.0f * std::sin(x / 15.0f) * std::cos(y / 20.0f) + 0.02f * x;
}

}  // namespace

point_cloud make_lidar_tile(std::size_t n, std::uint64_t seed, bool outliers) {
  point_cloud out;
  out.origin = vec3d(500000, 4100000, 0);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> unit(0, 1);
  constexpr float side = 100;
  // Scan lines along x, 4× sparser across (y) than along: n ≈ (side/d_a)·(side/d_c), d_c = 4·d_a.
  const float along = side / std::sqrt(4.0f * static_cast<float>(std::max<std::size_t>(n, 16)));
  const float across = 4 * along;
  std::vector<lidar_box> boxes;
  for (int b = 0; b < 6; ++b) {
    const float x = 5 + 80 * unit(rng), y = 5 + 80 * unit(rng);
    boxes.push_back({x, y, x + 8 + 10 * unit(rng), y + 8 + 10 * unit(rng), 5 + 10 * unit(rng)});
  }
  std::vector<lidar_tree> trees;
  for (int t = 0; t < 25; ++t) {
    const float x = 100 * unit(rng), y = 100 * unit(rng);
    bool in_box = false;
    for (const auto& b : boxes) in_box = in_box || b.contains(x, y);
    if (in_box) continue;
    const float base = 2 + 3 * unit(rng);
    trees.push_back({x, y, 2.5f + 3 * unit(rng), base, base + 4 + 6 * unit(rng)});
  }
  out.positions.reserve(n + n / 8);
  for (float y = 0; y < side; y += across)
    for (float x = 0; x < side; x += along) {
      const float px = x + 0.2f * along * (unit(rng) - 0.5f), py = y + 0.1f * across * unit(rng);
      float z = lidar_ground(px, py) + 0.03f * (unit(rng) - 0.5f);
      for (const auto& b : boxes)
        if (b.contains(px, py)) z = lidar_ground(b.x0, b.y0) + b.height;
      for (const auto& t : trees) {
        const float r2 = (px - t.x) * (px - t.x) + (py - t.y) * (py - t.y);
        if (r2 < t.radius * t.radius && unit(rng) < 0.75f) {
          // A return from anywhere inside the crown's vertical extent at this (x, y).
          const float h = std::sqrt(1 - r2 / (t.radius * t.radius));
          const float mid = 0.5f * (t.base + t.top), half = 0.5f * (t.top - t.base) * h;
          z = lidar_ground(t.x, t.y) + mid + half * (2 * unit(rng) - 1);
        }
      }
      out.positions.emplace_back(px, py, z);
    }
  // A few returns on the walls (an airborne scanner sees them at a grazing angle).
  for (const auto& b : boxes) {
    const float z0 = lidar_ground(b.x0, b.y0);
    for (float s = 0; s < 2 * (b.x1 - b.x0 + b.y1 - b.y0); s += 4 * across) {
      const float h = b.height * unit(rng);
      const float w = b.x1 - b.x0, d = b.y1 - b.y0;
      const vec3f p = s < w           ? vec3f(b.x0 + s, b.y0, z0 + h)
                      : s < w + d     ? vec3f(b.x1, b.y0 + s - w, z0 + h)
                      : s < 2 * w + d ? vec3f(b.x1 - (s - w - d), b.y1, z0 + h)
                                      : vec3f(b.x0, b.y1 - (s - 2 * w - d), z0 + h);
      out.positions.push_back(p);
    }
  }
  const std::size_t isolated = outliers ? out.positions.size() / 2000 : 0;
  for (std::size_t i = 0; i < isolated; ++i) {
    const float x = side * unit(rng), y = side * unit(rng);
    out.positions.emplace_back(x, y, lidar_ground(x, y) + 20 + 40 * unit(rng));
  }
  return out;
}

}  // namespace pbr_lod
