// Point sources: see include/pbr_lod/core/point_source.hpp.
#include "pbr_lod/core/point_source.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod {
namespace {

void check_range(const point_source& s, std::uint64_t first, std::size_t count) {
  if (first > s.size() || count > s.size() - first)
    throw InvalidArgument(s.name() + ": points [" + std::to_string(first) + ", " +
                          std::to_string(first + count) + ") requested of " +
                          std::to_string(s.size()));
}

// SplitMix64 (Steele, Lea & Flood 2014): a point's parameters from its index alone.
std::uint64_t splitmix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

float unit_float(std::uint64_t bits) {  // [0, 1) from the top 24 bits
  return static_cast<float>(bits >> 40) * (1.0f / 16777216.0f);
}

rgb8 hue_rgb(float h) {
  h -= std::floor(h);
  const auto q = [](float x) {
    return static_cast<std::uint8_t>(std::clamp(x, 0.0f, 1.0f) * 255.0f + 0.5f);
  };
  return {q(std::abs(h * 6 - 3) - 1), q(2 - std::abs(h * 6 - 2)), q(2 - std::abs(h * 6 - 4))};
}

}  // namespace

cloud_point_source::cloud_point_source(const point_cloud& c, std::string name)
    : cloud_(c), name_(std::move(name)) {
  c.validate(name_);
}

attributes cloud_point_source::attrs() const {
  return {.normal = !cloud_.normals.empty(), .colour = !cloud_.colours.empty()};
}

void cloud_point_source::read(std::uint64_t first, std::size_t count, point_block& out) const {
  check_range(*this, first, count);
  const auto b = static_cast<std::ptrdiff_t>(first), e = b + static_cast<std::ptrdiff_t>(count);
  out.positions.assign(cloud_.positions.begin() + b, cloud_.positions.begin() + e);
  out.normals.clear();
  out.colours.clear();
  if (!cloud_.normals.empty())
    out.normals.assign(cloud_.normals.begin() + b, cloud_.normals.begin() + e);
  if (!cloud_.colours.empty())
    out.colours.assign(cloud_.colours.begin() + b, cloud_.colours.begin() + e);
}

generated_point_source::generated_point_source(std::uint64_t n, std::uint64_t seed, bool normals,
                                               bool colours)
    : n_(n), seed_(seed), normals_(normals), colours_(colours) {}

std::string generated_point_source::name() const {
  return "generated:" + std::to_string(n_);
}

void generated_point_source::read(std::uint64_t first, std::size_t count, point_block& out) const {
  check_range(*this, first, count);
  out.positions.resize(count);
  out.normals.resize(normals_ ? count : 0);
  out.colours.resize(colours_ ? count : 0);
  constexpr float two_pi = 2 * std::numbers::pi_v<float>;
  // make_wavy_surface's surface: a torus whose tube radius waves in both angles.
  const auto pos = [](float u, float v) {
    const float r = 0.35f + 0.05f * std::sin(5 * u) * std::cos(3 * v);
    return vec3f((1 + r * std::cos(v)) * std::cos(u), r * std::sin(v),
                 (1 + r * std::cos(v)) * std::sin(u));
  };
  for (std::size_t k = 0; k < count; ++k) {
    const std::uint64_t h = splitmix(seed_ * 0x2545F4914F6CDD1Dull + first + k);
    const float u = two_pi * unit_float(h), v = two_pi * unit_float(splitmix(h));
    out.positions[k] = pos(u, v);
    if (normals_) {
      const float d = 1e-3f;
      const vec3f n = (pos(u + d, v) - pos(u - d, v)).cross(pos(u, v + d) - pos(u, v - d));
      out.normals[k] = n.norm() > 0 ? vec3f(n.normalized()) : vec3f::UnitY();
    }
    if (colours_) out.colours[k] = hue_rgb(u / two_pi + 0.25f * std::sin(3 * v));
  }
}

point_cloud read_all(const point_source& src) {
  point_cloud c;
  c.origin = src.origin();
  c.sensor = src.sensor();
  const std::uint64_t n = src.size();
  const attributes a = src.attrs();
  c.positions.reserve(n);
  if (a.normal) c.normals.reserve(n);
  if (a.colour) c.colours.reserve(n);
  point_block b;
  for (std::uint64_t first = 0; first < n; first += 1u << 20) {
    src.read(first, static_cast<std::size_t>(std::min<std::uint64_t>(1u << 20, n - first)), b);
    c.positions.insert(c.positions.end(), b.positions.begin(), b.positions.end());
    if (a.normal) c.normals.insert(c.normals.end(), b.normals.begin(), b.normals.end());
    if (a.colour) c.colours.insert(c.colours.end(), b.colours.begin(), b.colours.end());
  }
  return c;
}

}  // namespace pbr_lod
