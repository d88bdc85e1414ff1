// pbr_lod — image and geometry error metrics: RMSE / PSNR / hole fraction between two renders
// of the same view, and the Hausdorff distance between two point sets.
#pragma once

#include <algorithm>
#include <cstddef>
#include <span>

#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/raster/image.hpp"

namespace pbr_lod {

/// Difference of a test image from a reference image of the same size.
struct image_error {
  double rmse = 0;           ///< over the RGB channels of the pixels covered in either image
  double psnr = 0;           ///< 20·log10(255 / rmse) dB; +inf when rmse = 0 (identical pixels)
  double hole_fraction = 0;  ///< holes / reference_covered (0 when the reference is empty)
  std::size_t covered_either = 0;     ///< pixels covered in at least one of the images
  std::size_t reference_covered = 0;  ///< pixels covered in the reference
  std::size_t holes = 0;  ///< pixels covered in the reference but background in the test
};

/// Compares `test` against `reference` (same width and height, else InvalidArgument).
/// RMSE and PSNR are taken over the pixels covered in either image, so that a mostly empty
/// frame does not dilute the error; a pixel covered in only one image compares its colour with
/// the colour the other image stores there (its background colour). Nothing covered in either
/// image: rmse 0, psnr +inf.
[[nodiscard]] image_error compare_images(const image& reference, const image& test);

/// How a render looks next to the input's own full-detail render from the same view (the mesh;
/// the cloud's every point) — what the user sees, as opposed to compare_images against a
/// builder's own finest cut, which a wrong finest cut passes.
struct input_likeness {
  /// PSNR over the RGB channels of the interior pixels: covered in the input render and at least
  /// `inset_px` pixels inside its silhouette (every pixel within that Euclidean distance is
  /// covered too; pixels beyond the frame do not count as uncovered). A test pixel left empty
  /// there compares its background colour. +inf when they all agree; +inf with interior_pixels
  /// 0 when the input render has no interior.
  double psnr_interior = 0;
  /// |covered in both| / |covered in either| (1 when neither covers anything).
  double silhouette_iou = 0;
  std::size_t interior_pixels = 0;  ///< the pixels psnr_interior is taken over
  std::size_t interior_holes = 0;   ///< interior pixels the test leaves empty
};

/// Compares `test` with `input_render` (same size, else InvalidArgument) as above; inset_px ≥ 0.
[[nodiscard]] input_likeness compare_to_input(const image& input_render, const image& test,
                                              int inset_px = 2);

/// Mean structural similarity (Wang, Bovik, Sheikh & Simoncelli 2004, eq. 13) of the luminance
/// (Y = 0.299 R + 0.587 G + 0.114 B) of the two images: local means, variances and covariance
/// under an 11×11 Gaussian window (σ = 1.5, renormalised at the borders), C1 = (0.01·255)²,
/// C2 = (0.03·255)², averaged over the pixels covered in either image (as compare_images) — 1
/// for identical images; background pixels take part with their stored colour. Nothing covered
/// in either image: 1. Same size, else InvalidArgument.
[[nodiscard]] double ssim(const image& reference, const image& test);

/// One-sided and symmetric Hausdorff distances between two point clouds (world units).
struct hausdorff_result {
  double a_to_b_max = 0;  ///< max over points of a of the distance to the nearest point of b
  double b_to_a_max = 0;
  double a_to_b_mean = 0;  ///< mean of the same distances
  double b_to_a_mean = 0;
  double a_to_b_rms = 0;  ///< root mean square of the same distances
  double b_to_a_rms = 0;
  /// The Hausdorff distance max(a→b, b→a).
  [[nodiscard]] double symmetric() const { return std::max(a_to_b_max, b_to_a_max); }
};

/// One direction of a Hausdorff distance: the largest, mean and root-mean-square distance from
/// a point of `from` to its nearest point of `to`.
struct one_sided_distance {
  double max = 0, mean = 0, rms = 0;
};

/// one_sided_distance of `from` (#F positions) to the points indexed by `to`, in one frame,
/// queried on up to `threads` threads (0: all cores) in fixed chunks, so the result does not
/// depend on the thread count. Throws InvalidArgument when either is empty.
[[nodiscard]] one_sided_distance distance_to(std::span<const vec3f> from, const knn_index& to,
                                             unsigned threads = 0);

/// Hausdorff distance between the positions of a and b, via exact k-d tree queries. Computed in
/// the frame of a's origin: b's positions are re-expressed relative to it in double first, so two
/// georeferenced clouds with different origins compare correctly. Throws InvalidArgument when
/// either cloud is empty or has non-finite positions.
[[nodiscard]] hausdorff_result hausdorff(const point_cloud& a, const point_cloud& b);

/// As above for positions already in one frame, with an index over `a` built by the caller (a
/// sweep compares many cuts with the same input and builds its index once): A #A positions,
/// index_a a knn_index over exactly them, B #B positions. The per-point queries run on up to
/// `threads` threads (0: all cores); the result does not depend on it. Throws InvalidArgument
/// when either set is empty or index_a's size differs from #A.
[[nodiscard]] hausdorff_result hausdorff(std::span<const vec3f> a, const knn_index& index_a,
                                         std::span<const vec3f> b, unsigned threads = 0);

}  // namespace pbr_lod
