// pbr_lod — little-endian byte buffers for the builders' file formats: a writer, a reader that
// checks every read against the buffer's end and names what it was reading, and the FNV-1a
// checksum every .lod file ends with. Shared by the point-octree, ρ-grid and POP formats.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <type_traits>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod::detail {

struct byte_writer {
  std::vector<unsigned char> bytes;
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    const auto* p = reinterpret_cast<const unsigned char*>(&v);
    bytes.insert(bytes.end(), p, p + sizeof(T));
  }
  void put_vec(const vec3f& v) {
    put(v.x());
    put(v.y());
    put(v.z());
  }
  void put_code(std::uint32_t c, int bits) {
    if (bits <= 16)
      put(static_cast<std::uint16_t>(c));
    else
      put(c);
  }
};

/// The whole file at `path`; throws IoError when it cannot be opened or read. Every hierarchy
/// file's load() starts here, then validates what it reads through a byte_reader.
inline std::vector<unsigned char> load_file_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError(path + ": cannot open");
  std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(f)),
                                   std::istreambuf_iterator<char>());
  if (f.bad()) throw IoError(path + ": read error");
  return bytes;
}

struct byte_reader {
  const std::vector<unsigned char>& bytes;
  std::size_t pos = 0;
  const std::string& path;
  template <class T>
  T get(const char* what) {
    if (bytes.size() - pos < sizeof(T))
      throw FormatError(path + ": truncated while reading " + what + " at byte " +
                        std::to_string(pos));
    T v;
    std::memcpy(&v, bytes.data() + pos, sizeof(T));
    pos += sizeof(T);
    return v;
  }
  float get_finite(const char* what, std::size_t element) {
    const float f = get<float>(what);
    if (!std::isfinite(f))
      throw FormatError(path + ": " + what + " of element " + std::to_string(element) +
                        " is not finite");
    return f;
  }
  vec3f get_vec(const char* what, std::size_t element) {
    const float x = get_finite(what, element), y = get_finite(what, element),
                z = get_finite(what, element);
    return {x, y, z};
  }
  std::uint32_t get_code(int bits, const char* what) {
    return bits <= 16 ? get<std::uint16_t>(what) : get<std::uint32_t>(what);
  }
};

inline std::uint64_t fnv1a(const unsigned char* p, std::size_t n) {
  std::uint64_t h = 1469598103934665603ull;
  for (std::size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

}  // namespace pbr_lod::detail
