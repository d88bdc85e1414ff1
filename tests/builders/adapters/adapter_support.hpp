// pbr_lod tests — what a builder's adapter (tests/builders/adapters/ID.hpp) is written against.
//
// Each builder of cmake/builders.cmake has one adapter header defining `struct ID_tests` with
//  * `using ladder = std::tuple<...>`: its entries on the hard-case ladder (ladder_test.cpp), each
//    a struct with `name`; `built` (what build returns and save/load handle); build(mesh,
//    threads); save(b, path); load(path); visit(b, f) calling f(hierarchy, make_policy) with
//    make_policy(view) the builder's traversal policy for a view; normals_filled(b) (the count of
//    missing input normals the build reports, nullopt when it reports none); rejects(case name)
//    for refusals it documents beyond the ladder's own (nullopt: must build); optionally
//    `draws_faces_only` (a mesh of zero-area triangles draws nothing);
//  * `static std::vector<format_case> formats()`: a tiny valid file of each of its file formats
//    and how to load and save one (file_damage_test.cpp cuts and flips every byte of them).
// The test programs include the generated all_builder_tests.hpp, which includes every adapter
// and lists their ID_tests in the registry's order (tests/builders/CMakeLists.txt).
#pragma once

#include <cmath>
#include <cstdint>
#include <functional>
#include <optional>
#include <ostream>
#include <string>
#include <tuple>
#include <vector>

#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod::test {

using bytes_t = std::vector<unsigned char>;

/// One hierarchy file format: how to make a small valid file, and load(in) + save(out).
struct format_case {
  std::string name;
  std::function<bytes_t(const std::string& scratch)> make;
  std::function<void(const std::string& in, const std::string& out)> load_and_save;
};

/// gtest prints a case's name, not its bytes.
inline void PrintTo(const format_case& c, std::ostream* os) {
  *os << c.name;
}

/// Saves the hierarchy h to `path` and returns the file's bytes.
template <class H, class... SaveArgs>
bytes_t saved_bytes(const H& h, const std::string& path, SaveArgs... args) {
  h.save(path, args...);
  return detail::load_file_bytes(path);
}

template <class H>
void load_and_save(const std::string& in, const std::string& out) {
  H::load(in).save(out);
}

/// A wavy 4×4 grid of 32 triangles with vertex colours, and 60 points sampled on it (with normals
/// and colours): files of 0.2–9 kB, so that every cut can be tried.
inline const triangle_mesh& tiny_mesh() {
  static const triangle_mesh m = [] {
    triangle_mesh g;
    constexpr int n = 4;
    for (int y = 0; y <= n; ++y)
      for (int x = 0; x <= n; ++x) {
        const float fx = static_cast<float>(x) / n, fy = static_cast<float>(y) / n;
        g.vertices.positions.emplace_back(fx, fy, 0.2f * std::sin(6 * fx) * std::cos(5 * fy));
        g.vertices.colours.push_back(
            {static_cast<std::uint8_t>(40 * x), static_cast<std::uint8_t>(40 * y), 128});
      }
    const auto id = [](int x, int y) { return static_cast<std::uint32_t>(y * (n + 1) + x); };
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        g.faces.push_back({id(x, y), id(x + 1, y), id(x + 1, y + 1)});
        g.faces.push_back({id(x, y), id(x + 1, y + 1), id(x, y + 1)});
      }
    return g;
  }();
  return m;
}
inline const point_cloud& tiny_cloud() {
  static const point_cloud c = sample_surface(tiny_mesh(), 60, 3);
  return c;
}

/// Point builders take the mesh's vertices; with normals when the vertices have them.
template <class F>
auto with_point_set(const point_cloud& c, F&& f) {
  constexpr attributes plain{.colour = true}, oriented{.normal = true, .colour = true};
  if (c.normals.empty()) return f(point_set<plain>::from(c));
  return f(point_set<oriented>::from(c));
}

/// The parts of a ladder adapter most builders share: save/load through the hierarchy's own
/// members, no refusals beyond the ladder's.
template <class Built>
struct ladder_adapter_base {
  using built = Built;
  static void save(const built& b, const std::string& p) { b.save(p); }
  static built load(const std::string& p) { return built::load(p); }
  static std::optional<std::string> rejects(const std::string&) { return std::nullopt; }
};

}  // namespace pbr_lod::test
