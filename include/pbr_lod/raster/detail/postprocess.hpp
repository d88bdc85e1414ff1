// pbr_lod — per-frame passes over the whole framebuffer, compiled once in
// src/raster/postprocess.cpp (they do not depend on the attribute or effect set).
#pragma once

#include <span>
#include <vector>

#include "pbr_lod/core/math.hpp"
#include "pbr_lod/raster/effects.hpp"

namespace pbr_lod::detail {

/// Screen-space hole filling (visibility splatting + image reconstruction in the spirit of
/// Pfister et al. 2000 and the uniform reconstruction filter of POP, Chen & Nguyen 2001 §3.4).
/// A background pixel (key ≤ key_far) is filled when, within `opt.hole_filling_radius`, the
/// covered pixels near the front-most depth of the window (relative tolerance
/// opt.hole_filling_depth_tolerance) lie in at least opt.hole_filling_min_sectors of the 8 45°
/// sectors around it; it gets their mean colour and the front-most depth. Reads the unfilled
/// frame only, so the result does not depend on the scan order and filled pixels never seed
/// more filling (no cascade, so silhouettes cannot creep outwards).
void fill_holes(int width, int height, std::vector<float>& key, std::vector<rgb8>& colour,
                float key_far, const render_options& opt);

/// Eye-space depth from the perspective depth key 1/z: +inf where key ≤ key_far (background).
[[nodiscard]] std::vector<float> keys_to_depth(std::span<const float> key, float key_far);

}  // namespace pbr_lod::detail
