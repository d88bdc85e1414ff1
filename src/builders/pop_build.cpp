// pbr_lod — the POP builder and file format (Chen & Nguyen 2001; see builders/pop.hpp for the
// section-by-section map). OpenMesh provides the triangle adjacency that groups triangles into
// leaves (§3.5); it stays in this file.

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <mutex>
#include <numeric>
#include <span>
#include <thread>

#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/raster/png.hpp"
#include "pbr_lod/raster/reference.hpp"

namespace pbr_lod::detail {

namespace {

constexpr std::uint32_t none = std::numeric_limits<std::uint32_t>::max();

/// f(lo, hi) over contiguous chunks of at least ~2048 indices (core/parallel.hpp).
template <class F>
void parallel_chunks(std::size_t n, unsigned threads, F&& f) {
  detail::parallel_chunks(n, threads, 2048, f);
}

/// The smallest float ≥ x (x ≥ 0): stored radii never shrink below what was computed in double.
float round_up(double x) {
  float f = static_cast<float>(x);
  if (static_cast<double>(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

/// Vertex position from its 16-bit code (§3.5). The same expression in build and load, so a
/// loaded tree holds bit-identical positions.
vec3f dequantise(const std::array<std::uint16_t, 3>& q, const vec3f& mn, const vec3f& step) {
  return {mn.x() + static_cast<float>(q[0]) * step.x(),
          mn.y() + static_cast<float>(q[1]) * step.y(),
          mn.z() + static_cast<float>(q[2]) * step.z()};
}

double angle_between(const vec3f& a, const vec3f& b) {
  const double c = std::clamp(a.cast<double>().dot(b.cast<double>()), -1.0, 1.0);
  return std::acos(c);
}

/// Sphere (double centre x, radius r) made safe to store in float: the float centre, and a
/// radius rounded up so that it still holds every child sphere measured from that centre.
void finalise(const vec3d& x, double r, const vec3d* c, const double* cr, std::size_t n,
              vec3f& out_c, float& out_r) {
  out_c = x.cast<float>();
  const vec3d xc = out_c.cast<double>();
  double need = std::isfinite(r) ? r : 0.0;
  for (std::size_t i = 0; i < n; ++i) need = std::max(need, (c[i] - xc).norm() + cr[i]);
  out_r = round_up(need);
}

struct texture {
  image img;
  [[nodiscard]] rgb8 at(double x, double y) const {  // texel coordinates, wrapped (GL_REPEAT)
    const auto w = static_cast<long>(img.width), h = static_cast<long>(img.height);
    long ix = static_cast<long>(std::floor(x)) % w, iy = static_cast<long>(std::floor(y)) % h;
    if (ix < 0) ix += w;
    if (iy < 0) iy += h;
    return img.colour[static_cast<std::size_t>(iy) * static_cast<std::size_t>(w) +
                      static_cast<std::size_t>(ix)];
  }
  /// Texel coordinates of texture coordinate (u, v): OBJ's v grows upwards, the image's rows down.
  [[nodiscard]] vec2d texel(const vec2f& uv) const {
    return {static_cast<double>(uv.x()) * img.width,
            (1.0 - static_cast<double>(uv.y())) * img.height};
  }
  /// §3.1: "the average of all texels inside the triangle" (texel centres inside; the texel at
  /// the centroid when the triangle covers no texel centre). Large triangles are sampled on a
  /// coarser grid of at most ~65k texels.
  [[nodiscard]] rgb8 average(const std::array<vec2f, 3>& uv) const {
    const vec2d a = texel(uv[0]), b = texel(uv[1]), c = texel(uv[2]);
    const double x0 = std::floor(std::min({a.x(), b.x(), c.x()})),
                 x1 = std::ceil(std::max({a.x(), b.x(), c.x()})),
                 y0 = std::floor(std::min({a.y(), b.y(), c.y()})),
                 y1 = std::ceil(std::max({a.y(), b.y(), c.y()}));
    const double area = (x1 - x0) * (y1 - y0);
    const double stride = std::max(1.0, std::ceil(std::sqrt(area / 65536.0)));
    const auto edge = [](const vec2d& p, const vec2d& q, double x, double y) {
      return (q.x() - p.x()) * (y - p.y()) - (q.y() - p.y()) * (x - p.x());
    };
    double sr = 0, sg = 0, sb = 0, n = 0;
    for (double y = y0 + 0.5 * stride; y < y1; y += stride)
      for (double x = x0 + 0.5 * stride; x < x1; x += stride) {
        const double e0 = edge(a, b, x, y), e1 = edge(b, c, x, y), e2 = edge(c, a, x, y);
        if (!((e0 >= 0 && e1 >= 0 && e2 >= 0) || (e0 <= 0 && e1 <= 0 && e2 <= 0))) continue;
        const rgb8 t = at(x, y);
        sr += t.r;
        sg += t.g;
        sb += t.b;
        n += 1;
      }
    if (n == 0) {
      const vec2d m = (a + b + c) / 3.0;
      return at(m.x(), m.y());
    }
    return {static_cast<std::uint8_t>(std::lround(sr / n)),
            static_cast<std::uint8_t>(std::lround(sg / n)),
            static_cast<std::uint8_t>(std::lround(sb / n))};
  }
};

struct rgb_sum {
  double r = 0, g = 0, b = 0, n = 0;
  void add(rgb8 c) {
    r += c.r;
    g += c.g;
    b += c.b;
    n += 1;
  }
  [[nodiscard]] rgb8 mean() const {
    if (n == 0) return {};
    return {static_cast<std::uint8_t>(std::lround(r / n)),
            static_cast<std::uint8_t>(std::lround(g / n)),
            static_cast<std::uint8_t>(std::lround(b / n))};
  }
};

/// Leaves (§3.5): groups of at most `max` edge-adjacent triangles, grown breadth-first from the
/// first ungrouped triangle in input order over OpenMesh's face–face adjacency. Faces the
/// halfedge structure refuses (non-manifold edges or vertices, duplicates, repeated indices)
/// have no adjacency and become leaves of their own. Returns CSR arrays (start, faces).
void group_faces(std::size_t n_vertices, std::span<const std::array<std::uint32_t, 3>> faces,
                 std::uint32_t max, std::vector<std::uint32_t>& start,
                 std::vector<std::uint32_t>& members, std::size_t& isolated) {
  using om_mesh = OpenMesh::TriMesh_ArrayKernelT<>;
  om_mesh om;
  om.reserve(n_vertices, 3 * faces.size(), faces.size());
  std::vector<om_mesh::VertexHandle> vh(n_vertices);
  for (std::size_t i = 0; i < n_vertices; ++i) vh[i] = om.add_vertex(om_mesh::Point(0, 0, 0));
  std::vector<std::uint32_t> input_of;  // OpenMesh face index -> input face
  input_of.reserve(faces.size());
  std::vector<int> om_of(faces.size(), -1);
  {
    // OpenMesh reports every refused face on omerr; refusals are expected here (and counted).
    static std::mutex mute;
    const std::lock_guard lock(mute);
    const bool was = ::omerr().is_enabled();
    ::omerr().disable();
    for (std::size_t f = 0; f < faces.size(); ++f) {
      const auto& F = faces[f];
      if (F[0] == F[1] || F[1] == F[2] || F[0] == F[2]) continue;
      const auto fh = om.add_face(vh[F[0]], vh[F[1]], vh[F[2]]);
      if (!fh.is_valid()) continue;
      om_of[f] = fh.idx();
      if (static_cast<std::size_t>(fh.idx()) >= input_of.size())
        input_of.resize(static_cast<std::size_t>(fh.idx()) + 1, none);
      input_of[static_cast<std::size_t>(fh.idx())] = static_cast<std::uint32_t>(f);
    }
    if (was) ::omerr().enable();
  }
  isolated = 0;
  std::vector<char> taken(faces.size(), 0);
  start.clear();
  members.clear();
  start.reserve(faces.size() / 2 + 2);
  members.reserve(faces.size());
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (taken[f]) continue;
    const std::size_t g0 = members.size();
    start.push_back(static_cast<std::uint32_t>(g0));
    members.push_back(static_cast<std::uint32_t>(f));
    taken[f] = 1;
    if (om_of[f] < 0) {
      ++isolated;
      continue;
    }
    for (std::size_t k = g0; k < members.size() && members.size() - g0 < max; ++k) {
      const om_mesh::FaceHandle fh(om_of[members[k]]);
      for (auto it = om.ff_iter(fh); it.is_valid() && members.size() - g0 < max; ++it) {
        const std::uint32_t h = input_of[static_cast<std::size_t>(it->idx())];
        if (h == none || taken[h]) continue;
        taken[h] = 1;
        members.push_back(h);
      }
    }
  }
  start.push_back(static_cast<std::uint32_t>(members.size()));
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Spheres (§3.1)
// ---------------------------------------------------------------------------------------------

void pop_triangle_circle(const vec3d& a, const vec3d& b, const vec3d& c, vec3d& centre,
                         double& radius) {
  const vec3d ab = b - a, ac = c - a, bc = c - b;
  const auto longest_edge = [&] {
    const double lab = ab.squaredNorm(), lac = ac.squaredNorm(), lbc = bc.squaredNorm();
    if (lab >= lac && lab >= lbc)
      centre = 0.5 * (a + b);
    else if (lac >= lbc)
      centre = 0.5 * (a + c);
    else
      centre = 0.5 * (b + c);
  };
  // An angle exceeds 90° where the two edges leaving its corner have a negative dot product.
  const bool obtuse = ab.dot(ac) < 0 || (-ab).dot(bc) < 0 || ac.dot(bc) < 0;
  const vec3d w = ab.cross(ac);
  const double w2 = w.squaredNorm();
  const double scale = std::max({ab.squaredNorm(), ac.squaredNorm(), bc.squaredNorm()});
  if (obtuse || !(w2 > 1e-24 * scale * scale)) {
    longest_edge();  // obtuse (paper), or degenerate: the circumcentre is at infinity
  } else {
    centre = a + (ab.squaredNorm() * ac.cross(w) + ac.squaredNorm() * w.cross(ab)) / (2 * w2);
    if (!all_finite(centre)) longest_edge();
  }
  radius = std::max({(a - centre).norm(), (b - centre).norm(), (c - centre).norm()});
}

namespace {
/// The paper's inner-node sphere; returns true when rule 0 (one child holds the others) applied.
bool paper_sphere(const vec3d* c, const double* r, std::size_t n, vec3d& centre, double& radius) {
  // Rule 0: one child's sphere holds all the others (the largest such, for determinism).
  int best = -1;
  for (std::size_t i = 0; i < n; ++i) {
    bool holds = true;
    for (std::size_t j = 0; j < n && holds; ++j)
      holds = j == i || (c[j] - c[i]).norm() + r[j] <= r[i];
    if (holds && (best < 0 || r[i] > r[static_cast<std::size_t>(best)])) best = static_cast<int>(i);
  }
  if (best >= 0) {
    centre = c[best];
    radius = r[best];
    return true;
  }
  const double rmax = *std::max_element(r, r + n);
  if (n == 2) {  // centre on the segment, r = (d + r1 + r2) / 2
    const vec3d dv = c[1] - c[0];
    const double d = dv.norm();
    radius = 0.5 * (d + r[0] + r[1]);
    centre = d > 0 ? vec3d(c[0] + dv * ((radius - r[0]) / d)) : c[0];
    return false;
  }
  if (n == 3) {  // the centres' triangle circle, plus the largest radius
    pop_triangle_circle(c[0], c[1], c[2], centre, radius);
    radius += rmax;
    return false;
  }
  // n == 4: for each face of the tetrahedron of centres, the centre lies on the line through the
  // face's circle centre perpendicular to it; we take the point on that line where the fourth
  // centre is no farther than the face's corners (the face circle's centre itself when it
  // already is). Radius: distance to the corners plus the largest radius. Minimum over faces.
  radius = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < 4; ++k) {
    std::array<vec3d, 3> base;
    for (std::size_t i = 0, m = 0; i < 4; ++i)
      if (i != k) base[m++] = c[i];
    vec3d bc;
    double br;
    pop_triangle_circle(base[0], base[1], base[2], bc, br);
    const vec3d to4 = c[k] - bc;
    vec3d nrm = (base[1] - base[0]).cross(base[2] - base[0]);
    if (nrm.squaredNorm() > 0) {
      nrm.normalize();
    } else {  // collinear base: any direction across the line, towards the fourth centre
      const vec3d line = (base[1] - base[0]).squaredNorm() > (base[2] - base[0]).squaredNorm()
                             ? vec3d(base[1] - base[0])
                             : vec3d(base[2] - base[0]);
      nrm = line.squaredNorm() > 0 ? vec3d(to4 - line * (to4.dot(line) / line.squaredNorm())) : to4;
      if (nrm.squaredNorm() > 0) nrm.normalize();
    }
    const double h = to4.dot(nrm);
    const double rho2 = std::max(0.0, to4.squaredNorm() - h * h);
    double t = 0;
    if (rho2 + h * h > br * br && std::abs(h) > 0) t = (rho2 + h * h - br * br) / (2 * h);
    const vec3d x = bc + t * nrm;
    double dist = 0;
    for (std::size_t i = 0; i < 4; ++i) dist = std::max(dist, (c[i] - x).norm());
    const double rk = dist + rmax;
    if (rk < radius) {
      radius = rk;
      centre = x;
    }
  }
  return false;
}
}  // namespace

void pop_paper_sphere(const vec3d* c, const double* r, std::size_t n, vec3d& centre,
                      double& radius) {
  if (n == 0) throw InvalidArgument("pop_paper_sphere: no spheres");
  if (n > 4) throw InvalidArgument("pop_paper_sphere: the paper's rules cover 1..4 children");
  paper_sphere(c, r, n, centre, radius);
}

// ---------------------------------------------------------------------------------------------
// Build
// ---------------------------------------------------------------------------------------------

pop_data build_pop_data(const triangle_mesh& mesh, const pop_options& opt, bool colour) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  if (opt.max_leaf_triangles < 1 || opt.max_leaf_triangles > 4)
    throw InvalidArgument("build_pop: max_leaf_triangles must be 1..4, got " +
                          std::to_string(opt.max_leaf_triangles));
  if (opt.spheres != pop_sphere_rule::paper && opt.spheres != pop_sphere_rule::exact)
    throw InvalidArgument("build_pop: unknown sphere rule");
  const normal_quantizer quant(opt.normal_bits);  // throws on bad bits
  mesh.validate("build_pop");
  if (mesh.faces.empty()) throw InvalidArgument("build_pop: the mesh has no triangles");
  if (mesh.faces.size() >= none || mesh.num_vertices() >= none)
    throw InvalidArgument("build_pop: more than 2^32 - 1 vertices or triangles");
  const bool textured = !mesh.face_texcoords.empty() && !mesh.texture_path.empty();
  if (colour && !textured && mesh.vertices.colours.empty())
    throw InvalidArgument(
        "build_pop: colours requested but the mesh has neither vertex colours nor a texture "
        "(build pop_tree<with_normals> instead)");
  const unsigned threads =
      opt.threads ? opt.threads : std::max(1u, std::thread::hardware_concurrency());

  pop_data d;
  d.origin = mesh.vertices.origin;
  d.normal_bits = opt.normal_bits;
  d.spheres = opt.spheres;
  const std::size_t nv = mesh.num_vertices(), nf = mesh.num_faces();
  const auto& P = mesh.vertices.positions;

  // §3.5 vertices quantised to 16 bits per axis over the bounding box (Deering; QSplat).
  box3 bb = box3::of(P);
  d.q_min = bb.min;
  for (int k = 0; k < 3; ++k) {
    const float ext = bb.max[k] - bb.min[k];
    d.q_step[k] = ext > 0 ? ext / 65535.0f : 0.0f;
  }
  d.vertex_q.resize(nv);
  d.positions.resize(nv);
  d.vertex_normal_codes.resize(nv);
  d.normals.resize(nv);
  const std::vector<vec3f> est_normals =
      mesh.vertices.normals.empty() ? area_weighted_normals(mesh) : std::vector<vec3f>{};
  const std::vector<vec3f>& N = mesh.vertices.normals.empty() ? est_normals : mesh.vertices.normals;
  parallel_chunks(nv, threads, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) {
      std::array<std::uint16_t, 3> q{};
      for (int k = 0; k < 3; ++k) {
        const double s =
            d.q_step[k] > 0 ? (static_cast<double>(P[i][k]) - d.q_min[k]) / d.q_step[k] : 0.0;
        q[static_cast<std::size_t>(k)] =
            static_cast<std::uint16_t>(std::clamp<long>(std::lround(s), 0, 65535));
      }
      d.vertex_q[i] = q;
      d.positions[i] = dequantise(q, d.q_min, d.q_step);
      d.vertex_normal_codes[i] = quant.encode(N[i]);
      d.normals[i] = quant.decode(d.vertex_normal_codes[i]);
    }
  });

  // Colours: vertex colours, or with a texture the texel under each corner averaged per vertex.
  std::vector<rgb8> face_colour;
  texture tex;
  if (colour) {
    if (textured) {
      tex.img = read_png(mesh.texture_path);
      if (tex.img.width <= 0 || tex.img.height <= 0)
        throw FormatError(mesh.texture_path + ": empty texture");
      for (std::size_t f = 0; f < nf; ++f)
        for (const auto& uv : mesh.face_texcoords[f])
          if (!all_finite(uv))
            throw InvalidArgument("build_pop: face " + std::to_string(f) +
                                  " has a non-finite texture coordinate");
      std::vector<rgb_sum> acc(nv);
      for (std::size_t f = 0; f < nf; ++f)
        for (std::size_t k = 0; k < 3; ++k) {
          const vec2d t = tex.texel(mesh.face_texcoords[f][k]);
          acc[mesh.faces[f][k]].add(tex.at(t.x(), t.y()));
        }
      d.colours.resize(nv);
      for (std::size_t i = 0; i < nv; ++i) d.colours[i] = acc[i].n > 0 ? acc[i].mean() : rgb8{};
    } else {
      d.colours = mesh.vertices.colours;
    }
    face_colour.resize(nf);
  }

  // Per triangle: geometric normal, colour, sphere (§3.1).
  std::vector<vec3f> face_normal(nf);
  std::vector<vec3d> face_centre(nf);
  std::vector<double> face_radius(nf);
  std::vector<char> degenerate(nf, 0);
  parallel_chunks(nf, threads, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t f = lo; f < hi; ++f) {
      const auto& F = mesh.faces[f];
      const vec3d a = d.positions[F[0]].cast<double>(), b = d.positions[F[1]].cast<double>(),
                  c = d.positions[F[2]].cast<double>();
      const vec3d n = (b - a).cross(c - a);
      const double len = n.norm();
      if (len > 0 && std::isfinite(len)) {
        face_normal[f] = (n / len).cast<float>();
      } else {
        face_normal[f] = vec3f::Zero();
        degenerate[f] = 1;
      }
      pop_triangle_circle(a, b, c, face_centre[f], face_radius[f]);
      if (colour) {
        if (textured) {
          face_colour[f] = tex.average(mesh.face_texcoords[f]);
        } else {
          rgb_sum s;
          for (auto i : F) s.add(d.colours[i]);
          face_colour[f] = s.mean();
        }
      }
    }
  });
  d.stats.degenerate_faces =
      static_cast<std::size_t>(std::count(degenerate.begin(), degenerate.end(), char{1}));

  // Leaves (§3.5).
  std::vector<std::uint32_t> gstart, gfaces;
  group_faces(nv, mesh.faces, opt.max_leaf_triangles, gstart, gfaces, d.stats.isolated_faces);
  const std::size_t n_leaves = gstart.size() - 1;
  const auto t_adj = clock::now();

  // Split key of a leaf: the mean of its triangles' corners.
  std::vector<vec3f> key(n_leaves);
  parallel_chunks(n_leaves, threads, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t g = lo; g < hi; ++g) {
      vec3d s = vec3d::Zero();
      for (std::uint32_t k = gstart[g]; k < gstart[g + 1]; ++k)
        for (auto i : mesh.faces[gfaces[k]]) s += d.positions[i].cast<double>();
      key[g] = (s / (3.0 * (gstart[g + 1] - gstart[g]))).cast<float>();
    }
  });

  // Topology (§3.1, QSplat): breadth first; a node over leaves [lo, hi) of `perm` is split at the
  // median of the longest axis of its keys' box, and each half again: up to four children.
  struct topo {
    std::uint32_t lo, hi, first = 0, count = 0, parent = none;
    std::uint16_t depth = 0;
  };
  std::vector<std::uint32_t> perm(n_leaves);
  std::iota(perm.begin(), perm.end(), 0u);
  std::vector<topo> tn;
  tn.reserve(2 * n_leaves);
  tn.push_back({0, static_cast<std::uint32_t>(n_leaves)});
  const auto split = [&](std::uint32_t lo, std::uint32_t hi) {
    box3 b;
    for (std::uint32_t i = lo; i < hi; ++i) b.extend(key[perm[i]]);
    const vec3f e = b.extent();
    const int axis = (e.x() >= e.y() && e.x() >= e.z()) ? 0 : (e.y() >= e.z() ? 1 : 2);
    const std::uint32_t mid = lo + (hi - lo) / 2;
    std::nth_element(perm.begin() + lo, perm.begin() + mid, perm.begin() + hi,
                     [&](std::uint32_t x, std::uint32_t y) {
                       const float kx = key[x][axis], ky = key[y][axis];
                       return kx < ky || (kx == ky && x < y);
                     });
    return mid;
  };
  std::vector<std::array<std::uint32_t, 5>> cuts;  // per node of a level: up to 4 parts
  std::vector<std::pair<std::size_t, std::size_t>> levels;
  for (std::size_t a = 0; a < tn.size();) {
    const std::size_t b = tn.size();
    levels.emplace_back(a, b);
    cuts.assign(b - a, {});
    parallel_chunks(b - a, threads, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t i = lo; i < hi; ++i) {
        const topo& t = tn[a + i];
        auto& cut = cuts[i];
        cut.fill(0);
        if (t.hi - t.lo <= 1) continue;
        const std::uint32_t m = split(t.lo, t.hi);
        std::uint32_t k = 0;
        cut[k++] = t.lo;
        if (m - t.lo >= 2) cut[k++] = split(t.lo, m);
        cut[k++] = m;
        if (t.hi - m >= 2) cut[k++] = split(m, t.hi);
        for (std::uint32_t j = k; j < 5; ++j) cut[j] = t.hi;  // k parts: cut[0..k]
      }
    });
    for (std::size_t i = 0; i < b - a; ++i) {
      const auto& cut = cuts[i];
      if (tn[a + i].hi - tn[a + i].lo <= 1) continue;
      tn[a + i].first = static_cast<std::uint32_t>(tn.size());
      for (std::size_t j = 0; j < 4 && cut[j] < cut[j + 1]; ++j) {
        tn.push_back({cut[j], cut[j + 1], 0, 0, static_cast<std::uint32_t>(a + i),
                      static_cast<std::uint16_t>(tn[a + i].depth + 1)});
        ++tn[a + i].count;
      }
    }
    a = b;
  }
  if (levels.size() > 65535) throw InvalidArgument("build_pop: tree deeper than 65535 levels");

  // Faces in leaf order; leaves point at their range.
  const std::size_t nn = tn.size();
  d.nodes.resize(nn);
  d.faces.resize(nf);
  std::vector<std::uint32_t> leaf_group(nn, none);
  {
    std::uint32_t next = 0;
    for (std::size_t i = 0; i < nn; ++i) {
      auto& nd = d.nodes[i];
      nd.parent = tn[i].parent;
      nd.depth = tn[i].depth;
      if (tn[i].count == 0) {
        const std::uint32_t g = perm[tn[i].lo];
        leaf_group[i] = g;
        nd.leaf = 1;
        nd.first = next;
        nd.count = static_cast<std::uint8_t>(gstart[g + 1] - gstart[g]);
        for (std::uint32_t k = gstart[g]; k < gstart[g + 1]; ++k)
          d.faces[next++] = mesh.faces[gfaces[k]];
      } else {
        nd.first = tn[i].first;
        nd.count = static_cast<std::uint8_t>(tn[i].count);
      }
    }
  }
  if (colour) d.node_colours.resize(nn);
  d.node_normal_codes.resize(nn);

  // Bottom-up, one level at a time (children of a level all lie in the next one).
  std::vector<std::size_t> contained(threads + 1, 0);
  const bool exact = opt.spheres == pop_sphere_rule::exact;
  for (std::size_t li = levels.size(); li-- > 0;) {
    const auto [a, b] = levels[li];
    parallel_chunks(b - a, threads, [&](std::size_t lo, std::size_t hi) {
      std::size_t local_contained = 0;
      std::array<vec3d, 12> cc;
      std::array<double, 12> cr;
      for (std::size_t i = a + lo; i < a + hi; ++i) {
        auto& nd = d.nodes[i];
        vec3d x;
        double r = 0;
        vec3d nsum = vec3d::Zero();
        rgb_sum csum;
        std::size_t m = 0;
        if (nd.leaf) {
          const std::uint32_t g = leaf_group[i];
          const std::size_t k0 = gstart[g], k1 = gstart[g + 1];
          for (std::size_t k = k0; k < k1; ++k) {
            const std::uint32_t f = gfaces[k];
            for (auto v : mesh.faces[f]) nsum += d.normals[v].cast<double>();
            if (colour) csum.add(face_colour[f]);
          }
          if (k1 - k0 == 1) {
            x = face_centre[gfaces[k0]];
            r = face_radius[gfaces[k0]];
          } else if (exact) {  // smallest sphere of the leaf's corners
            for (std::size_t k = k0; k < k1; ++k)
              for (auto v : mesh.faces[gfaces[k]]) {
                cc[m] = d.positions[v].cast<double>();
                cr[m++] = 0;
              }
            min_sphere_of_spheres(cc.data(), cr.data(), m, x, r);
            m = 0;
          } else {  // the paper's rules over the triangles' spheres
            for (std::size_t k = k0; k < k1; ++k) {
              cc[m] = face_centre[gfaces[k]];
              cr[m++] = face_radius[gfaces[k]];
            }
            paper_sphere(cc.data(), cr.data(), m, x, r);
            m = 0;
          }
          // Every corner, measured from the stored centre.
          for (std::size_t k = k0; k < k1; ++k)
            for (auto v : mesh.faces[gfaces[k]]) {
              cc[m] = d.positions[v].cast<double>();
              cr[m++] = 0;
            }
          finalise(x, r, cc.data(), cr.data(), m, nd.centre, nd.radius);
          if (!(nsum.squaredNorm() > 0))
            for (std::size_t k = k0; k < k1; ++k) nsum += face_normal[gfaces[k]].cast<double>();
        } else {
          for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c) {
            const auto& ch = d.nodes[c];
            cc[m] = ch.centre.cast<double>();
            cr[m++] = ch.radius;
            nsum += ch.normal.cast<double>();
            if (colour) csum.add(d.node_colours[c]);
          }
          if (exact)
            min_sphere_of_spheres(cc.data(), cr.data(), m, x, r);
          else
            local_contained += paper_sphere(cc.data(), cr.data(), m, x, r) ? 1 : 0;
          finalise(x, r, cc.data(), cr.data(), m, nd.centre, nd.radius);
        }
        // Normal (§3.1: averages), quantised; the cone is measured about the decoded axis.
        const std::uint32_t code = quant.encode(nsum.cast<float>());
        d.node_normal_codes[i] = code;
        nd.normal = quant.decode(code);
        double cone = 0;
        if (nd.leaf) {
          for (std::uint32_t f = nd.first; f < nd.first + nd.count; ++f) {
            const std::uint32_t src = gfaces[gstart[leaf_group[i]] + (f - nd.first)];
            if (!degenerate[src]) cone = std::max(cone, angle_between(nd.normal, face_normal[src]));
          }
        } else {
          for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c)
            cone = std::max(cone, angle_between(nd.normal, d.nodes[c].normal) +
                                      static_cast<double>(d.nodes[c].cone_angle));
        }
        nd.cone_angle = std::min(std::numbers::pi_v<float>, round_up(cone + 1e-6));
        if (colour) d.node_colours[i] = csum.mean();
      }
      static std::mutex m;
      const std::lock_guard lock(m);
      contained[0] += local_contained;
    });
  }
  d.stats.contained_inner = contained[0];

  const auto t1 = clock::now();
  auto& st = d.stats;
  st.vertices = nv;
  st.triangles = nf;
  st.nodes = nn;
  for (const auto& nd : d.nodes) {
    if (nd.leaf) {
      ++st.leaves;
      ++st.leaves_by_size[nd.count - 1u];
    }
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  st.adjacency_seconds = std::chrono::duration<double>(t_adj - t0).count();
  st.tree_seconds = std::chrono::duration<double>(t1 - t_adj).count();
  st.build_seconds = std::chrono::duration<double>(t1 - t0).count();
  st.file_bytes = pop_file_bytes(d);
  st.bytes_per_vertex = static_cast<double>(st.file_bytes) / static_cast<double>(nv);
  st.bytes_per_triangle = static_cast<double>(st.file_bytes) / static_cast<double>(nf);
  return d;
}

// ---------------------------------------------------------------------------------------------
// Storage (§3.5). Little-endian file:
//   header   "PBRLODPP" | u32 version | u32 flags (1 = colour) | u32 normal_bits | u32 sphere rule
//            | u64 vertices | u64 faces | u64 nodes | f64 origin[3] | f32 q_min[3] | f32 q_step[3]
//            | build stats: f64 build, adjacency, tree seconds | u64 isolated, degenerate,
//              contained_inner
//   vertices u16 q[3] | normal code (u16 when normal_bits ≤ 16, else u32) | [u8 rgb[3]]
//   faces    u32 v[3]                          (in leaf order)
//   nodes    f32 centre[3] | f32 radius | f32 cone | normal code | u32 first | u8 count | u8 leaf
//            | [u8 rgb[3]]                    (breadth first; parent and depth are derived)
//   trailer  u64 FNV-1a of every byte before it
// ---------------------------------------------------------------------------------------------
namespace {
constexpr char pop_magic[8] = {'P', 'B', 'R', 'L', 'O', 'D', 'P', 'P'};
constexpr std::uint32_t pop_version = 1;
constexpr std::size_t header_bytes = 8 + 4 * 4 + 8 * 3 + 8 * 3 + 4 * 6 + 8 * 6;

std::size_t code_bytes(int bits) {
  return bits <= 16 ? 2 : 4;
}
std::size_t vertex_bytes(int bits, bool colour) {
  return 6 + code_bytes(bits) + (colour ? 3 : 0);
}
constexpr std::size_t face_bytes = 12;
std::size_t node_bytes(int bits, bool colour) {
  return 12 + 4 + 4 + code_bytes(bits) + 4 + 1 + 1 + (colour ? 3 : 0);
}

}  // namespace

std::size_t pop_file_bytes(const pop_data& d) {
  const bool colour = !d.node_colours.empty();
  return header_bytes + d.positions.size() * vertex_bytes(d.normal_bits, colour) +
         d.faces.size() * face_bytes + d.nodes.size() * node_bytes(d.normal_bits, colour) + 8;
}

void save_pop_data(const pop_data& d, const std::string& path) {
  const bool colour = !d.node_colours.empty();
  const int bits = d.normal_bits;
  byte_writer w;
  w.bytes.reserve(pop_file_bytes(d));
  for (char c : pop_magic) w.put(c);
  w.put(pop_version);
  w.put(static_cast<std::uint32_t>(colour ? 1u : 0u));
  w.put(static_cast<std::uint32_t>(bits));
  w.put(static_cast<std::uint32_t>(d.spheres));
  w.put(static_cast<std::uint64_t>(d.positions.size()));
  w.put(static_cast<std::uint64_t>(d.faces.size()));
  w.put(static_cast<std::uint64_t>(d.nodes.size()));
  for (int k = 0; k < 3; ++k) w.put(d.origin[k]);
  for (int k = 0; k < 3; ++k) w.put(d.q_min[k]);
  for (int k = 0; k < 3; ++k) w.put(d.q_step[k]);
  w.put(d.stats.build_seconds);
  w.put(d.stats.adjacency_seconds);
  w.put(d.stats.tree_seconds);
  w.put(static_cast<std::uint64_t>(d.stats.isolated_faces));
  w.put(static_cast<std::uint64_t>(d.stats.degenerate_faces));
  w.put(static_cast<std::uint64_t>(d.stats.contained_inner));
  for (std::size_t i = 0; i < d.positions.size(); ++i) {
    for (auto q : d.vertex_q[i]) w.put(q);
    w.put_code(d.vertex_normal_codes[i], bits);
    if (colour) w.put(d.colours[i]);
  }
  for (const auto& f : d.faces)
    for (auto v : f) w.put(v);
  for (std::size_t i = 0; i < d.nodes.size(); ++i) {
    const auto& nd = d.nodes[i];
    for (int k = 0; k < 3; ++k) w.put(nd.centre[k]);
    w.put(nd.radius);
    w.put(nd.cone_angle);
    w.put_code(d.node_normal_codes[i], bits);
    w.put(nd.first);
    w.put(nd.count);
    w.put(nd.leaf);
    if (colour) w.put(d.node_colours[i]);
  }
  w.put(fnv1a(w.bytes.data(), w.bytes.size()));
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw IoError(path + ": cannot open for writing");
  f.write(reinterpret_cast<const char*>(w.bytes.data()),
          static_cast<std::streamsize>(w.bytes.size()));
  if (!f) throw IoError(path + ": write failed");
}

pop_data load_pop_data(const std::string& path, bool colour) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError(path + ": cannot open");
  const std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(f)),
                                         std::istreambuf_iterator<char>());
  if (f.bad()) throw IoError(path + ": read error");
  byte_reader r{bytes, 0, path};
  for (char c : pop_magic)
    if (r.get<char>("magic") != c)
      throw FormatError(path + ": not a pbr_lod POP file (bad magic, expected PBRLODPP)");
  const auto version = r.get<std::uint32_t>("version");
  if (version != pop_version)
    throw FormatError(path + ": version " + std::to_string(version) +
                      ", this library reads version " + std::to_string(pop_version));
  const auto flags = r.get<std::uint32_t>("flags");
  if (flags & ~1u) throw FormatError(path + ": unknown flags " + std::to_string(flags));
  if (((flags & 1u) != 0) != colour)
    throw FormatError(path + ((flags & 1u)
                                  ? ": the file has colours, the requested pop_tree has none"
                                  : ": the file has no colours, the requested pop_tree "
                                    "needs them"));
  const auto bits = static_cast<int>(r.get<std::uint32_t>("normal bits"));
  if (bits < normal_quantizer::min_bits || bits > normal_quantizer::max_bits)
    throw FormatError(path + ": normal bits " + std::to_string(bits) + " outside 6..24");
  const auto rule = r.get<std::uint32_t>("sphere rule");
  if (rule > 1) throw FormatError(path + ": unknown sphere rule " + std::to_string(rule));
  const auto nv = r.get<std::uint64_t>("vertex count");
  const auto nf = r.get<std::uint64_t>("face count");
  const auto nn = r.get<std::uint64_t>("node count");
  const std::uint64_t vb = vertex_bytes(bits, colour), nb = node_bytes(bits, colour);
  const std::uint64_t size = bytes.size();
  if (nv == 0 || nf == 0 || nn == 0 || nv >= none || nf >= none || nn >= none || nv > size / vb ||
      nf > size / face_bytes || nn > size / nb ||
      header_bytes + nv * vb + nf * face_bytes + nn * nb + 8 != size)
    throw FormatError(path + ": " + std::to_string(nv) + " vertices, " + std::to_string(nf) +
                      " faces and " + std::to_string(nn) + " nodes do not match the file size " +
                      std::to_string(size));
  std::uint64_t stored;
  std::memcpy(&stored, bytes.data() + size - 8, 8);
  if (stored != fnv1a(bytes.data(), bytes.size() - 8))
    throw FormatError(path + ": checksum mismatch (corrupt file)");

  const normal_quantizer quant(bits);
  pop_data d;
  d.normal_bits = bits;
  d.spheres = static_cast<pop_sphere_rule>(rule);
  for (int k = 0; k < 3; ++k) d.origin[k] = r.get<double>("origin");
  if (!all_finite(d.origin)) throw FormatError(path + ": origin is not finite");
  for (int k = 0; k < 3; ++k) d.q_min[k] = r.get_finite("quantisation origin", 0);
  for (int k = 0; k < 3; ++k) d.q_step[k] = r.get_finite("quantisation step", 0);
  if ((d.q_step.array() < 0).any()) throw FormatError(path + ": negative quantisation step");
  d.stats.build_seconds = r.get<double>("stats");
  d.stats.adjacency_seconds = r.get<double>("stats");
  d.stats.tree_seconds = r.get<double>("stats");
  d.stats.isolated_faces = r.get<std::uint64_t>("stats");
  d.stats.degenerate_faces = r.get<std::uint64_t>("stats");
  d.stats.contained_inner = r.get<std::uint64_t>("stats");

  const auto check_code = [&](std::uint32_t c, const char* what, std::size_t i) {
    if (!quant.valid(c))
      throw FormatError(path + ": " + what + " " + std::to_string(i) + " has normal code " +
                        std::to_string(c) + " outside the " + std::to_string(quant.size()) +
                        "-entry table");
  };
  d.vertex_q.resize(nv);
  d.positions.resize(nv);
  d.vertex_normal_codes.resize(nv);
  d.normals.resize(nv);
  if (colour) d.colours.resize(nv);
  for (std::size_t i = 0; i < nv; ++i) {
    for (auto& q : d.vertex_q[i]) q = r.get<std::uint16_t>("vertex");
    d.positions[i] = dequantise(d.vertex_q[i], d.q_min, d.q_step);
    if (!all_finite(d.positions[i]))
      throw FormatError(path + ": vertex " + std::to_string(i) + " is not finite");
    d.vertex_normal_codes[i] = r.get_code(bits, "vertex normal");
    check_code(d.vertex_normal_codes[i], "vertex", i);
    d.normals[i] = quant.decode(d.vertex_normal_codes[i]);
    if (colour) d.colours[i] = r.get<rgb8>("vertex colour");
  }
  d.faces.resize(nf);
  for (std::size_t i = 0; i < nf; ++i)
    for (auto& v : d.faces[i]) {
      v = r.get<std::uint32_t>("face");
      if (v >= nv)
        throw FormatError(path + ": face " + std::to_string(i) + " references vertex " +
                          std::to_string(v) + ", but there are " + std::to_string(nv));
    }
  d.nodes.resize(nn);
  d.node_normal_codes.resize(nn);
  if (colour) d.node_colours.resize(nn);
  for (std::size_t i = 0; i < nn; ++i) {
    auto& nd = d.nodes[i];
    for (int k = 0; k < 3; ++k) nd.centre[k] = r.get_finite("node centre", i);
    nd.radius = r.get_finite("node radius", i);
    nd.cone_angle = r.get_finite("node cone", i);
    d.node_normal_codes[i] = r.get_code(bits, "node normal");
    check_code(d.node_normal_codes[i], "node", i);
    nd.normal = quant.decode(d.node_normal_codes[i]);
    nd.first = r.get<std::uint32_t>("node first");
    nd.count = r.get<std::uint8_t>("node count");
    nd.leaf = r.get<std::uint8_t>("node leaf");
    if (colour) d.node_colours[i] = r.get<rgb8>("node colour");
    if (nd.radius < 0 || nd.cone_angle < 0 || nd.cone_angle > std::numbers::pi_v<float> ||
        nd.leaf > 1)
      throw FormatError(path + ": node " + std::to_string(i) +
                        " has a negative radius, a cone outside [0, π] or a bad leaf flag");
  }
  // The tree: breadth first, children after their parent, every node reached once, leaves
  // partitioning the faces. Anything else is a corrupt file, not something to traverse.
  std::vector<char> reached(nn, 0), face_seen(nf, 0);
  reached[0] = 1;
  auto& st = d.stats;
  for (std::size_t i = 0; i < nn; ++i) {
    auto& nd = d.nodes[i];
    if (!reached[i])
      throw FormatError(path + ": node " + std::to_string(i) + " is not reachable from the root");
    const std::uint64_t end = std::uint64_t{nd.first} + nd.count;
    if (nd.leaf) {
      if (nd.count < 1 || nd.count > 4 || end > nf)
        throw FormatError(path + ": leaf " + std::to_string(i) + " has faces [" +
                          std::to_string(nd.first) + ", " + std::to_string(end) +
                          "), expected 1..4 faces below " + std::to_string(nf));
      for (std::uint64_t k = nd.first; k < end; ++k) {
        if (face_seen[k])
          throw FormatError(path + ": face " + std::to_string(k) + " belongs to two leaves");
        face_seen[k] = 1;
      }
      ++st.leaves;
      ++st.leaves_by_size[nd.count - 1u];
    } else {
      if (nd.count < 2 || nd.count > 4 || nd.first <= i || end > nn)
        throw FormatError(path + ": node " + std::to_string(i) + " has children [" +
                          std::to_string(nd.first) + ", " + std::to_string(end) +
                          "), expected 2..4 children after it and below " + std::to_string(nn));
      if (nd.depth >= 65535) throw FormatError(path + ": tree deeper than 65535 levels");
      for (std::uint64_t k = nd.first; k < end; ++k) {
        if (reached[k])
          throw FormatError(path + ": node " + std::to_string(k) + " has two parents");
        reached[k] = 1;
        d.nodes[k].parent = static_cast<std::uint32_t>(i);
        d.nodes[k].depth = static_cast<std::uint16_t>(nd.depth + 1);
      }
    }
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  for (std::size_t k = 0; k < nf; ++k)
    if (!face_seen[k]) throw FormatError(path + ": face " + std::to_string(k) + " is in no leaf");
  st.vertices = nv;
  st.triangles = nf;
  st.nodes = nn;
  st.file_bytes = size;
  st.bytes_per_vertex = static_cast<double>(size) / static_cast<double>(nv);
  st.bytes_per_triangle = static_cast<double>(size) / static_cast<double>(nf);
  return d;
}

bool operator==(const pop_data& a, const pop_data& b) {
  return a.origin == b.origin && a.positions == b.positions && a.normals == b.normals &&
         a.colours == b.colours && a.faces == b.faces && a.nodes == b.nodes &&
         a.node_colours == b.node_colours && a.vertex_q == b.vertex_q && a.q_min == b.q_min &&
         a.q_step == b.q_step && a.vertex_normal_codes == b.vertex_normal_codes &&
         a.node_normal_codes == b.node_normal_codes && a.normal_bits == b.normal_bits &&
         a.spheres == b.spheres && a.stats == b.stats;
}

}  // namespace pbr_lod::detail
