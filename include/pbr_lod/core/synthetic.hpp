// pbr_lod — generated inputs: the demo scene and large synthetic surfaces for scale tests.
//
// The demo scene is built to exercise what LOD methods get wrong: varying sampling density
// (a sphere whose rings crowd towards one pole), sharp creases (a box with per-face vertices, so
// normals jump at the edges), a thin part (a fin 1/100 of its height thick, which coarse levels
// merge front and back of) and per-vertex colours (gradients and stripes, so colour averaging
// shows). Everything is deterministic.
#pragma once

#include <cstddef>
#include <cstdint>

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// The demo scene as a triangle mesh with per-vertex normals and colours. `detail` scales the
/// tessellation: about 10·detail² triangles (detail 64 → ~45k triangles).
[[nodiscard]] triangle_mesh make_demo_scene(int detail = 64);

/// n points sampled uniformly by area on the mesh (seeded), with normals (interpolated per-vertex
/// normals, or the face normal) and colours (interpolated) where the mesh has them.
[[nodiscard]] point_cloud sample_surface(const triangle_mesh& mesh, std::size_t n,
                                         std::uint64_t seed = 1);

/// A closed, wavy surface of revolution with n samples, normals and colours: a large input for
/// scale tests and build-throughput benchmarks (millions of points without a file).
[[nodiscard]] point_cloud make_wavy_surface(std::size_t n, std::uint64_t seed = 1);

/// About n returns of an airborne LiDAR strip over a 100 m × 100 m tile, positions only (as a
/// LAS tile arrives), in UTM-like coordinates (origin (500000, 4100000, 0), z up): rolling
/// terrain scanned in lines 4× sparser across the track than along it, flat roofs of boxy
/// buildings with a few returns on their walls, tree crowns that scatter returns through their
/// volume (no surface), and 0.05 % isolated returns high above (birds, noise). The hard case of
/// normal and splat estimation: very uneven density, 2.5-D, neighbourhoods that are not surfaces.
/// outliers = false leaves the isolated returns out (coverage measurements need a reference
/// render that they do not dominate).
[[nodiscard]] point_cloud make_lidar_tile(std::size_t n, std::uint64_t seed = 1,
                                          bool outliers = true);

/// A scene of the cases where a builder's finest cut stops looking like its input, with
/// per-vertex normals and colours (about 8·detail² triangles; detail 48 → ~19k):
///  * two separate surfaces close together: two spheres of radius 0.5 whose gap is 0.04, each
///    0.1 above the floor — a triangle or splat that joins them shows in the gap;
///  * an open boundary and a hole: the floor is a single-sided 3.2 × 2.4 plate (open outer edge)
///    with a 0.6 × 0.5 square hole in front of the spheres;
///  * a sharp concave crease: a wall 1 high standing on the floor's back edge (separate vertices,
///    so normals jump 90°), its top edge open;
///  * colours: a two-colour checkerboard floor (per-vertex colours constant on each tile's
///    vertices), a hue ramp on the wall, one red and one blue sphere.
/// y is up; the scene spans x ∈ [−1.6, 1.6], y ∈ [0, 1.1], z ∈ [−1.2, 1.2]. Deterministic.
[[nodiscard]] triangle_mesh make_hard_cases_scene(int detail = 48);

}  // namespace pbr_lod
