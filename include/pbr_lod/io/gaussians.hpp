// pbr_lod — reading 3-D Gaussian Splatting scenes and writing the standard 3DGS PLY.
//
// Formats (chosen by the file extension, case-insensitive):
//   .ply    the 3DGS PLY (Kerbl et al. 2023's `point_cloud.ply`): element vertex with x y z,
//           f_dc_0..2, f_rest_0..N−1 (N = 0, 9, 24, 45 → SH degree 0–3, channel-major),
//           opacity (logit), scale_0..2 (log), rot_0..3 (quaternion w x y z, unnormalised);
//           any property order, any scalar type, binary or ASCII; other properties (nx ny nz,
//           …) and elements are read past.
//   .splat  antimatter15's 32-byte records: float x y z, float linear scales, uint8 RGBA
//           (colour = 0.5 + C0·dc, alpha = opacity), uint8 quaternion w x y z as (b − 128)/128.
//           SH degree 0.
//   .spz    Niantic's packed format, versions 1–3 (one gzip stream) and 4 (zstd streams), as
//           the reference reader (github.com/nianticlabs/spz) decodes them, in the coordinates
//           the file stores (the reference's default: no conversion); SH degree ≤ 3.
//
// The bad-value rule (one for every format; counted in read_report):
//  * a non-finite position → the Gaussian is dropped (dropped_non_finite);
//  * a non-finite or overflowing scale, or a NaN opacity → dropped (dropped_bad_gaussians);
//  * a zero or non-finite quaternion → the identity (rotations_reset);
//  * an opacity logit of ±inf → 1 / 0, a non-finite SH coefficient → 0, a negative linear scale
//    (.splat) → its absolute value (values_clamped).
// So every cloud returned passes gaussian_cloud::validate: no NaN goes downstream.
//
// Origin: the centre of the bounding box of the kept positions, in double (read.hpp's rule); a
// PLY with "comment pbr_lod_origin X Y Z" (write_gaussians_ply writes one) gets that origin back.
// Every count, size and offset is checked before use; malformed files throw FormatError and
// unreadable ones IoError, naming the file, the element and what was expected.
#pragma once

#include <memory>
#include <string>

#include "pbr_lod/core/gaussian_source.hpp"
#include "pbr_lod/core/gaussians.hpp"
#include "pbr_lod/io/read.hpp"

namespace pbr_lod {

/// Whether the file is a Gaussian scene: a .splat or .spz, or a PLY whose vertex element has the
/// 3DGS properties f_dc_0, opacity, scale_0 and rot_0 (only its header is read). Throws IoError
/// when it cannot be read and FormatError for a PLY with a malformed header.
[[nodiscard]] bool is_gaussian_file(const std::string& path);

/// Reads a .ply (3DGS), .splat or .spz file. Throws IoError or FormatError.
[[nodiscard]] gaussian_cloud read_gaussians(const std::string& path, read_report* report = nullptr);

/// The file as a gaussian_source (the input of build_gaussian_hierarchy_chunked), giving block by
/// block exactly the Gaussians read_gaussians gives (the same rule, origin and report). A .splat
/// and a binary PLY without lists up to its vertex element are read by rows (one pass at
/// opening applies the bad-value rule, then only the rows asked for are decoded: memory does
/// not grow with the file); any other file (.spz, an ASCII PLY) is read whole. Throws IoError or
/// FormatError.
[[nodiscard]] std::unique_ptr<gaussian_source> open_gaussian_source(const std::string& path,
                                                                    read_report* report = nullptr);

/// Writes the standard 3DGS binary little-endian PLY: float x y z (world coordinates), nx ny nz
/// = 0, f_dc_0..2, f_rest_* (channel-major), opacity (logit, opacities clamped to
/// [10⁻⁷, 1 − 10⁻⁷] first so the logit is finite: a hierarchy's merged opacities above 1 are
/// written as 1, which a logit cannot exceed), scale_0..2 (log, scales clamped to ≥ the
/// smallest float denormal), rot_0..3; plus "comment pbr_lod_origin" so read_gaussians restores
/// the origin. Whole or not at all (core/atomic_file.hpp). Throws InvalidArgument when the cloud
/// is not valid and IoError when the file cannot be written.
void write_gaussians_ply(const gaussian_cloud& cloud, const std::string& path);

}  // namespace pbr_lod
