// pbr_lod — what the POP builder's stages share (internal to src/builders): the state
// build_pop_data() carries from stage to stage and the types its members need. The stages, each
// in the file of its paper step:
//   pop_adjacency.cpp  Stage 1 (§3.5): vertices quantised, leaves grouped from the adjacency
//   pop_build.cpp      Stages 2–3 (§3.1): colours; topology (median splits); the driver
//   pop_spheres.cpp    Stages 4–5 (§3.1, §3.5): spheres, normals, cones bottom up; sphere codes
#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <utility>
#include <vector>

#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/core/memory.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/core/scratch.hpp"
#include "pop_internal.hpp"

namespace pbr_lod::detail::pop_stages {

using namespace pop_internal;

/// Three u32 per face: the adjacency's neighbours, and the same type as pop_data::faces, so the
/// adjacency's storage is recycled for the faces in leaf order once the grouping is done.
using face_slots = std::array<std::uint32_t, 3>;

/// f(lo, hi) over contiguous pieces of at least 2048 indices, 8 per thread, handed out one at a
/// time (core/parallel.hpp): every caller's work is element by element, and more pieces than
/// threads keep both cores busy when one of them runs slower.
constexpr std::size_t pieces_per_thread = 8, min_piece = 2048;
template <class F>
void for_pieces(std::size_t n, unsigned threads, F&& f) {
  detail::parallel_pieces(n, threads, pieces_per_thread * threads, min_piece, f);
}

struct texture {
  texture_image img;
  [[nodiscard]] rgb8 at(double x, double y) const {  // texel coordinates, wrapped (GL_REPEAT)
    const auto w = static_cast<long>(img.width), h = static_cast<long>(img.height);
    long ix = static_cast<long>(std::floor(x)) % w, iy = static_cast<long>(std::floor(y)) % h;
    if (ix < 0) ix += w;
    if (iy < 0) iy += h;
    return img.texels[static_cast<std::size_t>(iy) * static_cast<std::size_t>(w) +
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

/// A leaf's split key (the mean of its triangles' corners, as ordered_bits) and its index.
struct split_key {
  std::array<std::uint32_t, 3> k;
  std::uint32_t id;
};

/// The tree's shape before it has geometry: node i covers leaves [lo, hi) of the sorted split
/// keys; `first`/`count` are its children (count 0: a leaf).
struct topo {
  std::uint32_t lo, hi, first = 0, count = 0, parent = none;
  std::uint16_t depth = 0;
};
using node_ranges = std::vector<std::pair<std::size_t, std::size_t>>;

/// Per-worker counts of the bottom-up pass (one cache line each: no false sharing).
struct alignas(64) counts {
  std::size_t contained = 0, degenerate = 0;
};
/// What node_geometry() hands to normal_cone(): a leaf's face normals; fdeg bit j: face j is
/// degenerate.
struct pending {
  std::array<vec3f, 4> fn;
  std::uint8_t fdeg;
};
/// Nodes are done in blocks of `block`: the geometry of the whole block, then its normal encodes
/// back to back, which do not depend on each other, so they overlap in the pipeline (bench_core:
/// BM_Encode, independent encodes, against BM_EncodeLatency, a chain of them); through
/// encode(span, span), which also loads their candidate cells first (−5 %).
constexpr std::size_t block = 32;

/// Where a range of sorted leaves splits: the partition and the topology must agree exactly.
inline std::uint32_t mid_of(std::uint32_t lo, std::uint32_t hi) {
  return lo + (hi - lo) / 2;
}

/// The state the stages share: the input, the options, the output under construction and the
/// intermediate arrays one stage hands to the next.
struct pop_build_state {
  using clock = std::chrono::steady_clock;

  const triangle_mesh& mesh;
  const pop_options& opt;
  const bool colour;
  std::shared_ptr<const normal_quantizer> shared_quant;
  const normal_quantizer& quant;
  const bool textured, qn, exact;
  /// With colours from a texture: the leaves keep their texture coordinates and the texture.
  const bool keep_texture;
  const unsigned threads;
  const std::size_t nv, nf;
  const std::vector<vec3f>& P;

  pop_data d;
  // prepare(): the leaves as CSR groups of faces, and the adjacency (becomes d.faces).
  scratch_vector<std::uint32_t> gstart, gfaces;
  std::vector<face_slots> nbr;
  double adjacency_seconds = 0;
  // colour_faces()
  std::vector<rgb8> face_colour;
  texture tex;
  // leaf_keys(), partition_leaves()
  std::size_t n_leaves = 0;
  scratch_vector<split_key> perm;
  scratch_vector<topo> tn;
  node_ranges levels;  // node ranges by depth
  // lay_out_nodes(): a leaf's group's members start at gfaces[leaf_members[i]]
  scratch_vector<std::uint32_t> leaf_members;
  // spheres_and_cones(), reused by quantise_spheres()
  std::size_t split_level = 0, roots_begin = 0, roots = 0;
  std::vector<node_ranges> subtrees;

  pop_build_state(const triangle_mesh& m, const pop_options& o, bool c)
      : mesh(m),
        opt(o),
        colour(c),
        shared_quant(normal_quantizer::shared(o.normal_bits)),
        quant(*shared_quant),
        textured(!m.face_texcoords.empty() && m.texture != nullptr),
        qn(o.quantise_nodes),
        exact(o.spheres == pop_sphere_rule::exact),
        keep_texture(c && textured),
        threads(resolve_threads(o.threads)),
        nv(m.num_vertices()),
        nf(m.num_faces()),
        P(m.vertices.positions) {}

  void prepare();
  void quantise_vertices(std::size_t lo, std::size_t hi, bool estimate,
                         const std::vector<vec3d>& normal_sum);
  void colour_vertices();
  void colour_faces();
  void leaf_keys();
  std::uint32_t split(std::uint32_t lo, std::uint32_t hi);
  void partition(std::uint32_t lo, std::uint32_t hi);
  void build_topology();
  void partition_leaves();
  void lay_out_nodes();
  void leaf4_geometry(const std::array<std::uint32_t, 3>* tri, vec3d& x, double& r, vec3d& nsum,
                      rgb_sum& csum, const std::uint32_t* members, counts& acc, pending& out,
                      pop_node& nd) const;
  void node_geometry(std::size_t i, counts& acc, pending& out, vec3f& nsum_out);
  void normal_cone(std::size_t i, std::uint32_t code, const pending& in);
  void gather(std::size_t i);
  void bottom_up(std::size_t a, std::size_t b, counts& acc);
  void subtree_levels(std::size_t root, node_ranges& out) const;
  void spheres_and_cones();
  void top_down(std::size_t i);
  void quantise_spheres();
  void finish_stats(clock::time_point t0, clock::time_point t_prep, clock::time_point t1);
};

/// The checks build_pop_data() makes before any work (InvalidArgument on each).
void check_pop_input(const triangle_mesh& mesh, const pop_options& opt, bool colour);

}  // namespace pbr_lod::detail::pop_stages
