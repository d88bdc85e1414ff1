// pbr_lod — compile-time attribute sets.
//
// Position is always present. Normal, colour, material and splat ellipse are optional and chosen
// at compile time: a point_set<attributes{.colour = false}> has no colour member at all (not an
// empty vector — no member), primitives sent to a Sink carry no colour field, and the builders do
// no colour work. "Simulate only the effects a scene calls for", on the data side.
//
// attributes is a structural type, so it is used directly as a template argument:
//   pbr_lod::point_set<pbr_lod::attributes{.normal = true, .colour = true}> pts;
#pragma once

#include <cstddef>
#include <string>
#include <type_traits>

namespace pbr_lod {

struct attributes {
  bool normal = false;    ///< unit surface normal per sample
  bool colour = false;    ///< 8-bit RGB per sample
  bool material = false;  ///< small material index per sample (ρ-grid: 3 bits)
  bool ellipse = false;   ///< object-space splat ellipse: two tangent semi-axis vectors per sample

  friend constexpr bool operator==(const attributes&, const attributes&) = default;

  /// True when every attribute of `other` is also in *this.
  [[nodiscard]] constexpr bool contains(const attributes& other) const {
    return (normal || !other.normal) && (colour || !other.colour) &&
           (material || !other.material) && (ellipse || !other.ellipse);
  }
  [[nodiscard]] constexpr attributes operator&(const attributes& o) const {
    return {normal && o.normal, colour && o.colour, material && o.material, ellipse && o.ellipse};
  }
  [[nodiscard]] constexpr attributes operator|(const attributes& o) const {
    return {normal || o.normal, colour || o.colour, material || o.material, ellipse || o.ellipse};
  }

  /// Bytes one sample takes in a point_set with these attributes (SoA, no padding).
  [[nodiscard]] constexpr std::size_t bytes_per_point() const {
    return 3 * sizeof(float) + (normal ? 3 * sizeof(float) : 0) + (colour ? 3 : 0) +
           (material ? 1 : 0) + (ellipse ? 6 * sizeof(float) : 0);
  }

  [[nodiscard]] std::string to_string() const {
    std::string s = "position";
    if (normal) s += "+normal";
    if (colour) s += "+colour";
    if (material) s += "+material";
    if (ellipse) s += "+ellipse";
    return s;
  }
};

inline constexpr attributes positions_only{};
inline constexpr attributes with_normals{.normal = true};
inline constexpr attributes with_normals_colours{.normal = true, .colour = true};
inline constexpr attributes all_attributes{
    .normal = true, .colour = true, .material = true, .ellipse = true};

namespace detail {
/// An empty stand-in for an attribute the set does not have. The Tag keeps the empty members of
/// one struct distinct types, so [[no_unique_address]] can give them all zero size.
template <int Tag>
struct absent {
  friend constexpr bool operator==(const absent&, const absent&) = default;
};
template <bool Present, class T, int Tag>
using maybe = std::conditional_t<Present, T, absent<Tag>>;
}  // namespace detail

}  // namespace pbr_lod
