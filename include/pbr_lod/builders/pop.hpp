// pbr_lod — POP: hybrid point and polygon rendering with triangle-leaf bounding-sphere trees.
//
// This work is based on:
//   B. Chen, M. X. Nguyen. POP: A Hybrid Point and Polygon Rendering System for Large Data.
//   IEEE Visualization 2001.
//   (building on S. Rusinkiewicz, M. Levoy. QSplat. SIGGRAPH 2000, for the top-down tree.)
// What each part implements:
//   §3.1, §3.5  leaves: the input triangles grouped into leaves of at most four edge-adjacent
//               triangles (sorted-edge adjacency, or OpenMesh's — pop_adjacency; in
//               src/builders/pop/pop_build.cpp), so that leaves ≈
//               vertices; leaf normal = average of its vertices' normals, colour = average of
//               its triangles' colours (with a texture: the average of the texels inside each
//               triangle).
//   §3.1        leaf spheres: circumcircle when no angle exceeds 90°, the longest edge as the
//               diameter otherwise; a multi-triangle leaf bounds its triangles' spheres.
//   §3.1        QSplat-style top-down tree over the leaves (split at the median of the longest
//               axis, twice: up to four children); inner attributes = averages of the children;
//               inner spheres by the paper's rules (one child's sphere if it holds the others,
//               else the 2-, 3- and 4-child constructions) — pop_sphere_rule::paper — or the
//               exact smallest enclosing sphere (CGAL Min_sphere_of_spheres_d) —
//               pop_sphere_rule::exact. Normal cones per node for back-face culling.
//   §3.1, Fig. 5 with a texture, the leaves keep their triangles' texture coordinates and the tree
//               the texture: leaves are drawn texture-mapped (backward mapping; a
//               textured_triangle_prim to sinks that take it), inner nodes as points with the
//               averaged (prefiltered) texel colours.
//   §3.2        RENDER: frustum and back-face culling, refine while the splat size exceeds the
//               threshold, a point for an inner node, the leaf's 1–4 triangles at a leaf, the
//               optional silhouette rule — pop_policy with the generic traverse().
//   §3.2        RENDER-COHERENCY: the previous frame's cut is kept and moved up or down —
//               pop_coherent_traversal, the generic coherent_traversal (traverse/coherent.hpp)
//               with pop_policy.
//   §3.3        splat size from eye-space z only (traverse_options::metric = eye_z) or exact
//               (projection_metric::exact).
//   §3.4        simplified splatting (constant-colour squares of the splat size) or visibility
//               splatting (one-pixel points + the rasteriser's screen-space hole filling).
//   §3.5        storage: vertices quantised to 16 bits per axis over the bounding box (Deering /
//               QSplat), normals to a q-bit table, face index lists, leaf → face range; node
//               records QSplat-quantised relative to the parent (13 levels per centre axis and
//               radius, rounded outwards; 2-bit cones; RGB 565); save()/load() of a versioned,
//               validated file ("PBRLODPP" v3; src/builders/pop/pop_io.cpp).
//
// Layout: a flat node array in breadth-first order. An inner node's children are contiguous
// [first, first + count), 2..4 of them, all after it; a leaf's triangles are faces()[first,
// first + count), 1..4 of them. Render a node as a point when its splat is within the threshold,
// else its children; a leaf is always its triangles.
//
// Threading: build() uses up to `options.threads` threads. A built pop_tree is immutable; const
// member functions are safe for concurrent readers. pop_coherent_traversal holds per-frame state
// and is for one thread.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <ranges>
#include <string>
#include <vector>

#include "pbr_lod/core/attributes.hpp"
#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"
#include "pbr_lod/traverse/coherent.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/sink.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

/// How bounding spheres above single triangles are computed (§3.1).
enum class pop_sphere_rule : std::uint32_t {
  paper = 0,  ///< the paper's rules: a child's sphere if it holds the others, else the 2/3/4 cases
  exact = 1,  ///< beyond the paper: the smallest enclosing sphere (CGAL Min_sphere_of_spheres_d)
};

/// How the triangles' edge adjacency (for grouping them into leaves, §3.5) is found.
enum class pop_adjacency : std::uint32_t {
  /// Sorted undirected edge keys (min vertex, max vertex, face), in parallel. Defined on any
  /// input: duplicate faces and faces repeating a vertex get no neighbours; an edge with three
  /// or more faces links none of them (docs/pop.md). ≈ 6× faster than OpenMesh on 2 cores (2 M
  /// triangles).
  edge_sort = 0,
  /// OpenMesh's halfedge structure (add_face, ff_iter), sequential; faces it refuses
  /// (non-manifold edge or vertex, duplicate, inconsistent orientation) get no neighbours.
  openmesh = 1,
};

struct pop_options {
  /// Triangles per leaf, 1..4. The paper groups up to four adjacent triangles so that leaves ≈
  /// vertices and the tree is about QSplat's size (§3.5); 1 gives one leaf per triangle.
  std::uint32_t max_leaf_triangles = 4;
  pop_sphere_rule spheres = pop_sphere_rule::paper;
  /// Bits of the quantised vertex and node normals (§3.5; 6..24). 16: worst error < 0.5°.
  int normal_bits = 16;
  /// Threads for the build (0 = hardware concurrency).
  unsigned threads = 0;
  /// Edge adjacency for the leaf grouping; edge_sort unless OpenMesh's behaviour is wanted.
  pop_adjacency adjacency = pop_adjacency::edge_sort;
  /// QSplat-style node records (§3.5; Rusinkiewicz & Levoy 2000): each sphere's centre (per
  /// axis) and radius quantised to 13 levels relative to its parent's quantised sphere, rounded
  /// outwards so that it still holds the exact sphere and stays inside its parent; the normal
  /// cone to 2 bits (rounded up); node colours to 16 bits (RGB 565). The tree in memory holds
  /// the dequantised values, so load(save(t)) == t. false: float spheres and cones (as in
  /// file version 1).
  bool quantise_nodes = true;
};

struct pop_build_stats {
  /// Whether the timings below were measured by this build; a loaded file has none (its bytes
  /// depend only on the input and the options, so two builds compare equal).
  bool has_timings = false;
  double build_seconds = 0;  ///< whole build
  /// from the start to the end of the first phase and the face colours: validation, vertex
  /// quantisation and normals, which share the threads with the edge adjacency and grouping
  double prepare_seconds = 0;
  /// edge adjacency (edge sort or OpenMesh) + grouping into leaves, inside the first phase; so
  /// prepare + adjacency + tree may exceed build_seconds
  double adjacency_seconds = 0;
  double tree_seconds = 0;  ///< split, node records, bottom-up spheres/normals/cones, quantisation
  std::size_t vertices = 0, triangles = 0;
  std::size_t nodes = 0, leaves = 0, max_depth = 0;
  std::array<std::size_t, 4> leaves_by_size{};  ///< leaves with 1, 2, 3, 4 triangles
  /// Faces left without adjacency: with pop_adjacency::edge_sort the duplicates and faces
  /// repeating a vertex; with openmesh the faces its halfedge structure refused. They become
  /// leaves of their own and are drawn like any other.
  std::size_t isolated_faces = 0;
  std::size_t nonmanifold_edges = 0;  ///< edge_sort: edges of 3+ faces (no link); openmesh: 0
  std::size_t degenerate_faces = 0;   ///< zero-area faces (their spheres are still finite)
  /// Vertex normals that were zero or not finite ("no normal"), replaced by the area-weighted
  /// normal of the vertex's faces (area_weighted_normals). A loaded file reports 0.
  std::size_t normals_filled = 0;
  std::size_t contained_inner = 0;  ///< inner nodes whose sphere is one child's (rule 0, §3.1)
  std::size_t file_bytes = 0;       ///< size of the file save() writes
  /// The file's sections: vertex records, face index lists, node records (header + checksum
  /// are the rest).
  std::size_t vertex_file_bytes = 0, face_file_bytes = 0, node_file_bytes = 0;
  double bytes_per_vertex = 0, bytes_per_triangle = 0;  ///< file_bytes / vertices, / triangles
  friend bool operator==(const pop_build_stats&, const pop_build_stats&) = default;
};

namespace detail {
/// One node of the flat tree (see the layout comment above).
struct pop_node {
  vec3f centre = vec3f::Zero();  ///< bounding sphere: every triangle of the subtree is inside
  float radius = 0;
  vec3f normal = vec3f::UnitZ();  ///< unit, decoded from its normal code: the point's normal
  float cone_angle = std::numbers::pi_v<float>;  ///< every face normal below is within this of
                                                 ///< `normal` (π: unbounded)
  std::uint32_t first = 0;                       ///< inner: first child; leaf: first face
  std::uint32_t parent = std::numeric_limits<std::uint32_t>::max();  ///< root: max (not stored)
  std::uint8_t count = 0;   ///< inner: children (2..4); leaf: triangles (1..4)
  std::uint8_t leaf = 0;    ///< 1 for a leaf
  std::uint16_t depth = 0;  ///< root = 0 (not stored)
  friend bool operator==(const pop_node&, const pop_node&) = default;
};

/// Everything a pop_tree holds, independent of the attribute set (colours empty without them).
struct pop_data {
  vec3d origin = vec3d::Zero();
  std::vector<vec3f> positions;  ///< dequantised vertex positions relative to origin
  std::vector<vec3f> normals;    ///< decoded vertex normals
  std::vector<rgb8> colours;     ///< vertex colours, or empty
  std::vector<std::array<std::uint32_t, 3>> faces;  ///< in leaf order
  std::vector<pop_node> nodes;
  std::vector<rgb8> node_colours;  ///< or empty
  /// Textured builds (colours from a mesh with texture coordinates and a texture): each face's
  /// corner texture coordinates, in leaf order as `faces`, and the texture (RGB) they index, for
  /// drawing leaves texture-mapped (Figure 5). Otherwise empty and null.
  std::vector<std::array<vec2f, 3>> face_texcoords;
  std::shared_ptr<const texture_image> texture;
  // storage (§3.5): what the file holds and the in-memory values are derived from
  std::vector<std::array<std::uint16_t, 3>> vertex_q;
  vec3f q_min = vec3f::Zero(), q_step = vec3f::Zero();
  std::vector<std::uint32_t> vertex_normal_codes, node_normal_codes;
  int normal_bits = 16;
  pop_sphere_rule spheres = pop_sphere_rule::paper;
  pop_adjacency adjacency = pop_adjacency::edge_sort;
  bool quantised_nodes = true;
  /// quantised_nodes: per node, its sphere relative to the parent's (4 bits each for the centre's
  /// x, y, z and the radius, levels 0..12); the root's entry is unused (its sphere is stored in
  /// float).
  std::vector<std::uint16_t> node_sphere_codes;
  pop_build_stats stats;
  friend bool operator==(const pop_data& a, const pop_data& b);
};

// Compiled in src/builders/pop/pop_build.cpp (OpenMesh stays there).
[[nodiscard]] pop_data build_pop_data(const triangle_mesh& mesh, const pop_options& options,
                                      bool colour);
void save_pop_data(const pop_data& d, const std::string& path);
[[nodiscard]] pop_data load_pop_data(const std::string& path, bool colour);
[[nodiscard]] std::size_t pop_file_bytes(const pop_data& d);

/// Smallest sphere enclosing the n spheres (centres c, radii r), via CGAL
/// Min_sphere_of_spheres_d (src/builders/pop/pop_min_sphere.cpp). Returns false when n == 0.
bool min_sphere_of_spheres(const vec3d* c, const double* r, std::size_t n, vec3d& centre,
                           double& radius);
/// The paper's inner-node sphere (§3.1) of n ≤ 4 spheres, in double. Exposed for the tests.
void pop_paper_sphere(const vec3d* c, const double* r, std::size_t n, vec3d& centre,
                      double& radius);
/// The paper's triangle circle (§3.1): circumcircle when no angle exceeds 90°, else the longest
/// edge as diameter; degenerate triangles fall back to the longest edge. Radius = the largest
/// distance from the centre to a corner (so it always contains them).
void pop_triangle_circle(const vec3d& a, const vec3d& b, const vec3d& c, vec3d& centre,
                         double& radius);
/// pop_triangle_circle() of four triangles (a[k], b[k], c[k]) at once, as the builder does for
/// leaves of four triangles: four lanes, the same bits as four calls. Exposed for the tests.
void pop_triangle_circle4(const vec3d* a, const vec3d* b, const vec3d* c, vec3d* centre,
                          double* radius);
}  // namespace detail

template <attributes A>
class pop_tree {
  static_assert(A.normal && !A.material && !A.ellipse,
                "pop_tree<with_normals> or pop_tree<with_normals_colours>");

 public:
  using node_id = std::uint32_t;
  using node = detail::pop_node;
  static constexpr attributes attrs = A;
  static constexpr node_id no_node = std::numeric_limits<node_id>::max();

  pop_tree() = default;

  // ---- the Hierarchy interface
  [[nodiscard]] vec3d origin() const { return d_.origin; }
  [[nodiscard]] bool empty() const { return d_.nodes.empty(); }
  [[nodiscard]] node_id root() const { return 0; }
  [[nodiscard]] bool is_leaf(node_id n) const { return d_.nodes[n].leaf != 0; }
  [[nodiscard]] auto children(node_id n) const {
    const node& nd = d_.nodes[n];
    const std::uint32_t end = nd.leaf ? nd.first : nd.first + nd.count;
    return std::views::iota(nd.first, end);
  }
  [[nodiscard]] sphere bounding_sphere(node_id n) const {
    return {d_.nodes[n].centre, d_.nodes[n].radius};
  }
  [[nodiscard]] pbr_lod::normal_cone normal_cone(node_id n) const {
    return {d_.nodes[n].normal, d_.nodes[n].cone_angle};
  }
  /// The same cone with cos θ and sin θ derived once after build and load, so that back-face
  /// culling takes no trigonometry per node and frame (sincos was an eighth of a traversal).
  /// The same values the per-frame path computed, so the same nodes are culled.
  [[nodiscard]] pbr_lod::normal_cone_cs normal_cone_cs(node_id n) const {
    return {d_.nodes[n].normal, cone_cs_[n][0], cone_cs_[n][1]};
  }
  /// Inner node: a point whose size is its exact projected diameter. Leaf: its triangles.
  template <class S>
  void emit(node_id n, const view& v, S& sink) const {
    if (is_leaf(n))
      emit_triangles(n, sink);
    else
      emit_point(n, std::max(1.0f, 2 * projected_radius_exact(v, bounding_sphere(n))), sink);
  }
  /// The node's point (§3.2): a square of size_px pixels with the node's normal and colour.
  template <class S>
  void emit_point(node_id n, float size_px, S& sink) const {
    point_prim<A> p{d_.nodes[n].centre, size_px};
    p.normal = d_.nodes[n].normal;
    if constexpr (A.colour) p.colour = d_.node_colours[n];
    sink.point(p);
  }
  /// A leaf's 1–4 triangles with per-vertex normals (and colours). A textured tree sends a sink
  /// that takes them (TexturedTriangleSink) textured_triangle_prims — the same triangles with
  /// their corners' texture coordinates and the tree's texture, drawn by backward mapping
  /// (Figure 5); every other sink gets the triangle_prims alone.
  template <class S>
  void emit_triangles(node_id n, S& sink) const {
    const node& nd = d_.nodes[n];
    for (std::uint32_t f = nd.first; f < nd.first + nd.count; ++f) {
      const auto& F = d_.faces[f];
      triangle_prim<A> t{{d_.positions[F[0]], d_.positions[F[1]], d_.positions[F[2]]}};
      t.normal = {d_.normals[F[0]], d_.normals[F[1]], d_.normals[F[2]]};
      if constexpr (A.colour) t.colour = {d_.colours[F[0]], d_.colours[F[1]], d_.colours[F[2]]};
      if constexpr (A.colour && TexturedTriangleSink<S, A>) {
        if (d_.texture) {
          sink.textured_triangle(
              textured_triangle_prim<A>{t, d_.face_texcoords[f], d_.texture.get()});
          continue;
        }
      }
      sink.triangle(t);
    }
  }
  /// Every triangle of n's subtree (the silhouette rule draws a node this way).
  template <class S>
  void emit_subtree_triangles(node_id n, S& sink) const {
    std::vector<node_id> stack{n};
    while (!stack.empty()) {
      const node_id m = stack.back();
      stack.pop_back();
      if (is_leaf(m)) {
        emit_triangles(m, sink);
        continue;
      }
      for (node_id c = d_.nodes[m].first + d_.nodes[m].count; c-- > d_.nodes[m].first;)
        stack.push_back(c);
    }
  }

  // ---- inspection
  [[nodiscard]] const std::vector<node>& nodes() const { return d_.nodes; }
  [[nodiscard]] const node& at(node_id n) const { return d_.nodes[n]; }
  [[nodiscard]] node_id parent(node_id n) const { return d_.nodes[n].parent; }
  [[nodiscard]] const std::vector<vec3f>& positions() const { return d_.positions; }
  [[nodiscard]] const std::vector<vec3f>& vertex_normals() const { return d_.normals; }
  [[nodiscard]] const std::vector<std::array<std::uint32_t, 3>>& faces() const { return d_.faces; }
  [[nodiscard]] rgb8 node_colour(node_id n) const requires(A.colour) { return d_.node_colours[n]; }
  /// The texture of a textured tree (leaves drawn texture-mapped), else null.
  [[nodiscard]] const texture_image* texture() const { return d_.texture.get(); }
  /// Per face (in faces() order) its corners' texture coordinates; empty unless textured.
  [[nodiscard]] const std::vector<std::array<vec2f, 3>>& face_texcoords() const {
    return d_.face_texcoords;
  }
  [[nodiscard]] pop_sphere_rule sphere_rule() const { return d_.spheres; }
  [[nodiscard]] pop_adjacency adjacency() const { return d_.adjacency; }
  /// True when the node records are QSplat-quantised (pop_options::quantise_nodes).
  [[nodiscard]] bool quantised_nodes() const { return d_.quantised_nodes; }
  [[nodiscard]] const pop_build_stats& stats() const { return d_.stats; }
  [[nodiscard]] std::size_t file_bytes() const { return detail::pop_file_bytes(d_); }

  // ---- storage (§3.5)
  /// Writes the versioned file; throws IoError. load(save(t)) == t exactly.
  void save(const std::string& path) const { detail::save_pop_data(d_, path); }
  /// Reads and validates a file written by save(): magic "PBRLODPP", version (3; versions 1 and 2
  /// are rejected with a FormatError saying to rebuild), attribute set, every count and index
  /// against the file size and the tree, finite values, a checksum. Throws IoError (cannot read) or
  /// FormatError naming the element at fault.
  [[nodiscard]] static pop_tree load(const std::string& path) {
    pop_tree t;
    t.d_ = detail::load_pop_data(path, A.colour);
    t.derive();
    return t;
  }

  friend bool operator==(const pop_tree& a, const pop_tree& b) { return a.d_ == b.d_; }

 private:
  template <attributes B>
  friend pop_tree<B> build_pop(const triangle_mesh&, const pop_options&);
  /// What the tree derives from d_ after build and load (not stored, not compared).
  void derive() {
    cone_cs_.resize(d_.nodes.size());
    for (std::size_t n = 0; n < d_.nodes.size(); ++n) {
      const float a = d_.nodes[n].cone_angle;
      cone_cs_[n] = a >= std::numbers::pi_v<float> / 2 ? std::array<float, 2>{-1.0f, 0.0f}
                                                       : std::array{std::cos(a), std::sin(a)};
    }
  }
  detail::pop_data d_;
  std::vector<std::array<float, 2>> cone_cs_;  ///< cos, sin of each node's cone_angle
};

/// Builds the POP tree of a triangle mesh. Vertex normals are the mesh's, else area-weighted
/// face normals. With colours (A.colour): the texture's texels when the mesh has texture
/// coordinates and a loaded texture (triangle_mesh::texture, which read_mesh loads), else its
/// vertex colours; InvalidArgument when it has neither. A tree built from a texture keeps it and
/// the leaves' texture coordinates (emit_triangles()). Throws InvalidArgument on an empty or
/// invalid mesh (NaN/Inf, out-of-range indices, an empty texture) or bad options.
template <attributes A>
[[nodiscard]] pop_tree<A> build_pop(const triangle_mesh& mesh, const pop_options& options = {}) {
  pop_tree<A> t;
  t.d_ = detail::build_pop_data(mesh, options, A.colour);
  t.derive();
  return t;
}

/// True when build_pop<with_normals_colours> can colour this mesh (texture or vertex colours).
[[nodiscard]] inline bool pop_mesh_has_colour(const triangle_mesh& m) {
  return (!m.face_texcoords.empty() && m.texture != nullptr) || !m.vertices.colours.empty();
}

/// How inner nodes are drawn when their splat is within the threshold (§3.4).
enum class pop_point_mode {
  simplified,  ///< a constant-colour square of the splat size (QSplat's simplified splatting)
  /// A one-pixel point only; render with effects::hole_filling, radius = threshold. Without a
  /// first pass a surface behind the gaps between the points shows through them, and the hole
  /// filling cannot repair those pixels (they are covered).
  visibility,
  /// §3.4 as the paper does it: each point node drawn twice, first at its full splat size in the
  /// background colour (an occluder_prim: hides what lies behind, leaves a hole), then as a
  /// one-pixel point in its own colour; leaves' triangles once. Render with
  /// effects::hole_filling (radius = threshold) to reconstruct the holes. The occluder is pushed
  /// back along its view ray by the node's radius, so it hides neither its own point nor its
  /// neighbours' on a tilted surface (Surfel visibility splatting's ε). Sinks that do not take
  /// occluders (OccluderSink) get the one-pixel points alone, as with `visibility`.
  visibility_two_pass,
};

/// POP's RENDER (§3.2) as a traversal policy: the screen size is the splat size under
/// traverse_options::metric (eye_z = the paper's §3.3, exact = projected_radius_exact); refine
/// while it exceeds the threshold; a leaf draws its triangles, an inner node a point.
/// Silhouette rule (optional): an inner node whose normal is nearly perpendicular to the
/// direction from the eye (|n·d| < silhouette_cos) draws its subtree's triangles instead of a
/// point. It changes what a cut node draws, not the cut, so coherent traversals stay exact.
struct pop_policy : default_policy {
  /// A parent's sphere holds its children's (quantised outwards) and its normal cone theirs, so
  /// whenever a node refines its ancestors do: the coherent traversal may stop its upward
  /// search at the first parent that refines (traverse/coherent.hpp).
  static constexpr bool monotone_refine = true;

  float silhouette_cos = 0;  ///< 0: off; e.g. 0.1 (within ≈ 5.7° of perpendicular)
  pop_point_mode points = pop_point_mode::simplified;
  /// QSplat (Rusinkiewicz & Levoy 2000), the all-points tree POP's Fig. 6 compares against: a
  /// leaf draws a point of its splat size (at least one pixel) instead of its triangles. The
  /// same tree and cut, so the two differ only in what a leaf draws (a POP leaf holds 1–4
  /// triangles, about one vertex: §3.5's "about QSplat's size"). Silhouette rule off.
  bool leaves_as_points = false;

  template <class H, class S>
  void emit(const H& h, const typename H::node_id& n, const view& v, float size_px,
            const traverse_options& /*o*/, S& sink) const {
    if (leaves_as_points) {
      h.emit_point(n, std::max(1.0f, std::min(size_px, 1e4f)), sink);
      return;
    }
    if (h.is_leaf(n)) {
      h.emit_triangles(n, sink);
      return;
    }
    if (silhouette_cos > 0) {
      const auto& nd = h.at(n);
      const vec3f d = nd.centre - v.eye;
      const float len = d.norm();
      if (len > 0 && std::abs(nd.normal.dot(d)) < silhouette_cos * len) {
        h.emit_subtree_triangles(n, sink);
        return;
      }
    }
    const float splat = std::max(1.0f, std::min(size_px, 1e4f));
    if (points == pop_point_mode::simplified) {
      h.emit_point(n, splat, sink);
      return;
    }
    if constexpr (OccluderSink<S>) {
      if (points == pop_point_mode::visibility_two_pass) {
        const sphere b = h.bounding_sphere(n);
        const vec3f d = b.centre - v.eye;
        const float len = d.norm();
        sink.occluder({len > 0 ? vec3f(b.centre + d * (b.radius / len)) : b.centre, splat});
      }
    }
    h.emit_point(n, 1.0f, sink);
  }
};

/// POP's RENDER-COHERENCY (§3.2): the generic frame-coherent traversal (traverse/coherent.hpp)
/// with POP's policy — the previous frame's cut, moved down or up, emitted in traverse()'s
/// order, so images are byte-identical to the plain traversal's.
template <attributes A>
using pop_coherent_traversal = coherent_traversal<pop_tree<A>, pop_policy>;

}  // namespace pbr_lod

namespace pbr_lod {
// The common interface (traverse/hierarchy.hpp): render, stats and tests drive it like any other.
static_assert(Hierarchy<pop_tree<with_normals>>);
static_assert(Hierarchy<pop_tree<with_normals_colours>>);
}  // namespace pbr_lod
