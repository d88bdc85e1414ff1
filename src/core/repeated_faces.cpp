// Exact repeats among a mesh's triangles: see include/pbr_lod/core/repeated_faces.hpp.
#include "pbr_lod/core/repeated_faces.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <numeric>

namespace pbr_lod {
namespace {

/// A corner position's bits, comparable as a whole (−0 and +0 differ: "as stored").
using key3 = std::array<std::uint32_t, 3>;

key3 bits(const vec3f& p) {
  key3 k;
  std::memcpy(k.data(), p.data(), sizeof k);
  return k;
}

}  // namespace

std::vector<std::uint32_t> unique_faces(const triangle_mesh& m) {
  const auto& P = m.vertices.positions;
  const std::size_t n = m.faces.size();
  // Each face's corners rotated to start at the smallest: the three rotations of one triangle
  // give one key, the other winding (a back face, which culling treats differently) another.
  std::vector<std::array<key3, 3>> key(n);
  for (std::size_t f = 0; f < n; ++f) {
    for (int c = 0; c < 3; ++c) key[f][std::size_t(c)] = bits(P[m.faces[f][std::size_t(c)]]);
    std::rotate(key[f].begin(), std::min_element(key[f].begin(), key[f].end()), key[f].end());
  }
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return key[a] < key[b]; });
  std::vector<std::uint32_t> keep;
  for (std::size_t i = 0; i < n; ++i)
    if (i == 0 || key[order[i]] != key[order[i - 1]]) keep.push_back(order[i]);  // first of a run
  std::sort(keep.begin(), keep.end());
  return keep;
}

}  // namespace pbr_lod
