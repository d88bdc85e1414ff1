// pbr_lod — per-point normals and splat ellipses estimated from the k nearest neighbours.
//
// This work is based on:
//   R. Pajarola, "Efficient Level-of-Details for Point Based Rendering", CGIM 2003, end of §4:
//   initial splat ellipses from the covariance of the k nearest neighbours, projected into the
//   tangent plane and scaled to bound them (the node rule of Fig. 5 / Fig. 6a, EQ 5–6).
//   H. Hoppe, T. DeRose, T. Duchamp, J. McDonald, W. Stuetzle, "Surface Reconstruction from
//   Unorganized Points", SIGGRAPH 1992, §3 (tangent planes): normal = smallest eigenvector of the
//   k-NN covariance, orientation propagated along a minimum spanning tree of the Riemannian graph
//   (CGAL::mst_orient_normals, Point_set_processing_3).
//
// Neighbourhoods come from knn_index (FLANN, exact), one batch of queries per call in Morton
// order; FLANN and Boost appear only in the .cpp files. Every function runs on up to `threads`
// threads of the library's pool (0: all cores) and is deterministic: each point's result depends
// only on the input, never on the scheduling or the thread count. docs/estimation.md has the
// measured speed and accuracy.
//
// Coordinates: pass positions relative to a nearby origin (point_cloud / point_set store them
// that way). The covariance is accumulated in double and centred on the neighbourhood mean, so
// the result is translation invariant up to float rounding of the relative positions; absolute
// coordinates of a georeferenced scan cast to float would already have lost the surface.
#pragma once

#include <functional>
#include <span>
#include <vector>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// How estimated normals get their signs.
enum class normal_orientation {
  none,       ///< the canonical sign (largest-magnitude component positive)
  mst,        ///< consistent over the k-NN graph (Hoppe et al. 1992, minimum spanning forest)
  viewpoint,  ///< towards a sensor position: n·(viewpoint − p) ≥ 0 (one parallel pass)
};

/// How large an estimated splat ellipse may grow.
enum class ellipse_rule {
  /// Pajarola's rule alone: the ellipse bounds all k neighbours, however far they are.
  neighbours,
  /// The same ellipse, bounded by the local point spacing (robust on real scans; default):
  ///  * the major semi-axis is at most local_spacing_reach × ρᵢ, ρᵢ the distance to the
  ///    farthest of the k neighbours, and at most local_spacing_outlier_factor × the median ρⱼ
  ///    of those neighbours (an isolated sample borrows its neighbours' spacing); the minor is
  ///    then grown just enough to keep the neighbours inside (at most the major), so no splat
  ///    is a spike, and every neighbour stays covered unless the outlier bound applies;
  ///  * a neighbourhood thicker than local_spacing_max_thickness (its variance along the normal
  ///    over its total variance, Pauly's surface variation: 0 on a plane, 1/3 for an isotropic
  ///    blob — vegetation, corners) is no surface, and a sample whose ρᵢ exceeds
  ///    local_spacing_sparse_factor × the cloud's median ρ is sparse: either gets a round disk
  ///    of radius non_surface_disk_factor × d₈ (d₈ its distance to the 8th nearest neighbour),
  ///    bounded as above, and a sparse one at most the typical sample's: non_surface_disk_factor
  ///    × the cloud's median d₈;
  ///  * at an open edge or a crease the ellipse is compressed, direction by direction, until it
  ///    reaches in no tangent direction farther than its neighbourhood does on the nearer side
  ///    plus local_spacing_edge_margin × d₈: inside a surface the neighbours surround the sample
  ///    and nothing changes, at an edge they lie on one side and the splat no longer sticks out
  ///    by the neighbourhood's radius beyond it.
  local_spacing,
};

/// ellipse_rule::local_spacing: how far beyond its own neighbourhood radius a splat may reach.
inline constexpr double local_spacing_reach = 1.5;
/// ellipse_rule::local_spacing: how far beyond its neighbours' median spacing a splat may reach.
inline constexpr double local_spacing_outlier_factor = 8.0;
/// ellipse_rule::local_spacing: the thickness above which a neighbourhood is not a surface.
inline constexpr double local_spacing_max_thickness = 0.1;
/// ellipse_rule::local_spacing: a sample whose neighbourhood radius exceeds this many times the
/// cloud's median neighbourhood radius is sparse (an isolated return, a stray hit).
inline constexpr double local_spacing_sparse_factor = 16.0;
/// ellipse_rule::local_spacing: how far (over d₈, the distance to the 8th nearest neighbour) a
/// splat may reach beyond the nearer side of its neighbourhood in any tangent direction.
inline constexpr double local_spacing_edge_margin = 0.75;
/// ellipse_rule::local_spacing: the radius of the round splat of a non-surface or sparse sample
/// over its distance to the 8th nearest neighbour d₈. A disk of radius r seen from a uniformly
/// random direction covers πr²/2 on average; the full-detail reference draws a bare position as
/// a view-facing square of side 2 × 0.8 d₈ (raster/reference.hpp). Equal areas: r = 1.6·√(2/π)·d₈.
inline constexpr double non_surface_disk_factor = 1.2766;

/// Parameters of the estimation, shared by every entry point below.
struct estimation_options {
  int k_normals = 16;   ///< neighbourhood of the PCA normal (≥ 3)
  int k_ellipses = 16;  ///< neighbourhood the splat ellipse bounds (≥ 2)
  normal_orientation orientation = normal_orientation::mst;
  vec3f viewpoint = vec3f::Zero();  ///< sensor position, in the positions' frame (relative to
                                    ///< the cloud's origin), for normal_orientation::viewpoint
  ellipse_rule ellipses = ellipse_rule::local_spacing;
  unsigned threads = 0;  ///< 0: all cores
  /// Called on the calling thread between stages (index, k-NN, normals, ellipses) with the
  /// fraction done; returning false cancels: the call throws pbr_lod::Cancelled.
  std::function<bool(double)> progress = {};
};

/// Unit normals, one per position (P #P by 3 positions).
///
/// The neighbourhood of a point is its min(k, #P) nearest samples *including itself* (and any
/// duplicates of it). Normal = eigenvector of the smallest eigenvalue of the neighbourhood's
/// covariance (double, centred on the neighbourhood mean). Degenerate neighbourhoods still give
/// a finite unit normal:
///  * all samples at one position (a single point, duplicates): +z;
///  * collinear (middle eigenvalue ≤ 1e-12 × largest): any_orthogonal(line direction);
///  * coplanar, any count ≥ 3 distinct: the plane normal.
/// Sign: with orient == false, the largest-magnitude component is made positive (a canonical,
/// deterministic choice that knows nothing about the surface). With orient == true the signs
/// are then made consistent over the k-NN Riemannian graph (Hoppe 1992, the rule of
/// CGAL::mst_orient_normals): in each connected component the sample with the largest z gets a
/// normal with z ≥ 0 and the orientation is propagated along the minimum spanning forest (edge
/// weight 1 − |nᵢ·nⱼ|). On a closed surface this is outward. The neighbourhoods of the PCA pass
/// are reused; the k-NN queries and the edge sort run in parallel.
///
/// With normal_orientation::viewpoint the PCA normals are instead flipped to face
/// opt.viewpoint, each on its own (a scan that knows where its sensor was needs no graph).
///
/// Throws InvalidArgument when k < 3, a position is not finite or the viewpoint is not finite.
/// Empty input → empty output. Uses opt.k_normals, opt.orientation, opt.viewpoint, opt.threads.
[[nodiscard]] std::vector<vec3f> estimate_normals(std::span<const vec3f> positions,
                                                  const estimation_options& opt);

/// estimate_normals with k_normals = k and orientation mst (orient) or none.
[[nodiscard]] std::vector<vec3f> estimate_normals(std::span<const vec3f> positions, int k = 16,
                                                  bool orient = true, unsigned threads = 0);

/// Semi-axis vectors of per-point splat ellipses: u[i] the major, v[i] the minor semi-axis
/// (direction × length), both orthogonal to the normal and to each other. The layout of
/// point_cloud::axis_u / axis_v.
struct splat_axes {
  std::vector<vec3f> u, v;
};

/// Smallest ratio minor / major of an estimated splat ellipse. Without a floor a neighbourhood
/// that is collinear in the tangent plane (a scan line) would give a needle of zero width.
inline constexpr double splat_min_axis_ratio = 0.1;

/// Splat ellipses centred at each sample, in its tangent plane (normals[i]; need not be unit,
/// the sign is irrelevant), bounding its min(k, #P) nearest samples (itself included).
///
/// Per point: project the neighbour offsets pⱼ − pᵢ into the tangent plane, take the eigen-
/// vectors of their 2×2 second-moment matrix (about pᵢ, the splat's centre) as the axis
/// directions with the eigenvalues λ₁ ≥ λ₂ (λ₂ raised to splat_min_axis_ratio²·λ₁ if smaller),
/// and scale the axes √λ₁, √λ₂ by f = max over neighbours of √(x²/λ₁ + y²/λ₂) — the bounding
/// rule of Pajarola Fig. 6a — times (1 + 1e-5) so that rounding the axes to float never leaves
/// the farthest neighbour just outside. Every neighbour then lies in the ellipse; for a sample
/// whose Delaunay neighbours are among its k nearest, the ellipse contains the whole Delaunay
/// triangles around it (an ellipse is convex), so the union of the ellipses has no gaps.
///
/// Degenerate neighbourhoods (all neighbours project onto pᵢ: duplicates, or samples stacked
/// along the normal): a circular disk whose radius is the distance to the nearest sample not at
/// pᵢ (searched among up to 4096 nearest), else 1e-6 × the bounding-box half-diagonal of all
/// positions, else (all samples identical) 1e-6 × max(1, |pᵢ|∞). Always finite and non-zero.
///
/// Throws InvalidArgument when k < 2, the spans differ in length, a position is not finite or
/// a normal is zero or not finite. Empty input → empty output.
[[nodiscard]] splat_axes estimate_splat_ellipses(std::span<const vec3f> positions,
                                                 std::span<const vec3f> normals, int k = 16,
                                                 unsigned threads = 0,
                                                 ellipse_rule rule = ellipse_rule::local_spacing);

/// Oriented normals and splat ellipses of a bare point set in one pass over one k-NN index:
/// the same results as estimate_normals(positions, k_normals, orient) followed by
/// estimate_splat_ellipses(positions, normals, k_ellipses) up to the order of equidistant
/// neighbours, with the neighbourhoods searched once (max(k_normals, k_ellipses) nearest).
struct estimated_splats {
  std::vector<vec3f> normals;
  splat_axes axes;
};
[[nodiscard]] estimated_splats estimate_normals_and_ellipses(std::span<const vec3f> positions,
                                                             const estimation_options& opt);
[[nodiscard]] estimated_splats estimate_normals_and_ellipses(std::span<const vec3f> positions,
                                                             int k_normals = 16,
                                                             int k_ellipses = 16,
                                                             bool orient = true,
                                                             unsigned threads = 0);

}  // namespace pbr_lod
