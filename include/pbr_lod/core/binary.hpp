// pbr_lod — little-endian byte buffers for the builders' file formats: a writer, a reader that
// checks every read against the buffer's end and names what it was reading, and what every
// hierarchy file shares: its head (8-byte magic, u32 version), the FNV-1a checksum it ends with,
// the colour flag, and reading and writing the whole file. Used by all five builders' formats
// and by the pbrlod tool (which method wrote a file).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "pbr_lod/core/atomic_file.hpp"
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
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  if (!f) throw IoError(path + ": cannot open");
  // One read of the size the file has (a byte-wise copy through stream iterators was 13 % of a
  // chunked build); a stream without a size (a pipe) is copied as it comes.
  const std::streamoff size = f.tellg();
  std::vector<unsigned char> bytes;
  if (size >= 0 && f.seekg(0)) {
    bytes.resize(static_cast<std::size_t>(size));
    f.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size));
    if (f.gcount() != size) throw IoError(path + ": read error (file changed while read)");
  } else {
    f.clear();
    bytes.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  if (f.bad()) throw IoError(path + ": read error");
  return bytes;
}

/// The first `n` bytes of the file at `path` (fewer when it is shorter): enough to tell which
/// format a file is without reading all of it. Throws IoError when it cannot be opened.
inline std::vector<unsigned char> load_file_prefix(const std::string& path, std::size_t n) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError(path + ": cannot open");
  std::vector<unsigned char> bytes(n);
  f.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(n));
  if (f.bad()) throw IoError(path + ": read error");
  bytes.resize(static_cast<std::size_t>(f.gcount()));
  return bytes;
}

struct byte_reader {
  std::span<const unsigned char> bytes;  ///< a loaded file or a mapping of one
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
  float get_non_negative(const char* what, std::size_t element) {
    const float f = get_finite(what, element);
    if (!(f >= 0))
      fail(std::string(what) + " of element " + std::to_string(element) + " is negative");
    return f;
  }
  vec3f get_vec(const char* what, std::size_t element) {
    const float x = get_finite(what, element), y = get_finite(what, element),
                z = get_finite(what, element);
    return {x, y, z};
  }
  /// The bytes `count` elements of `size` bytes need must still be there (checked before
  /// anything is allocated, so that a hostile count cannot exhaust memory).
  void need(std::uint64_t count, std::size_t size, const char* what) const {
    if (count > (bytes.size() - pos) / size)
      fail(std::string("truncated: ") + std::to_string(count) + " " + what + " need " +
           std::to_string(count * size) + " bytes, " + std::to_string(bytes.size() - pos) +
           " remain");
  }
  [[noreturn]] void fail(const std::string& msg) const {
    throw FormatError(path + ": " + msg + " (at byte " + std::to_string(pos) + ")");
  }
  std::uint32_t get_code(int bits, const char* what) {
    return bits <= 16 ? get<std::uint16_t>(what) : get<std::uint32_t>(what);
  }
};

/// FNV-1a of n bytes; `h` the hash of the bytes before them, for a file hashed in pieces.
inline std::uint64_t fnv1a(const unsigned char* p, std::size_t n,
                           std::uint64_t h = 1469598103934665603ull) {
  for (std::size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

/// What a hierarchy file format is called and how it starts: "PBRLOD" + two letters naming the
/// method, then the u32 version this library writes and reads.
struct file_format {
  const char* name;  ///< for messages: "point-octree", "POP", ...
  char magic[8];
  std::uint32_t version;
};

inline void write_head(byte_writer& w, const file_format& f) {
  for (const char c : f.magic) w.put(c);
  w.put(f.version);
}

/// Reads and checks the magic and the version. Older versions (`retired` and below) name
/// themselves and ask for a rebuild; any other version names the one this library reads.
inline void read_head(byte_reader& r, const file_format& f, std::uint32_t retired = 0) {
  for (const char c : f.magic)
    if (r.get<char>("magic") != c)
      throw FormatError(r.path + ": not a pbr_lod " + f.name + " file (bad magic, expected " +
                        std::string(f.magic, 8) + ")");
  const auto v = r.get<std::uint32_t>("version");
  if (v >= 1 && v <= retired)
    throw FormatError(r.path + ": " + f.name + " file version " + std::to_string(v) +
                      " is no longer read; this library reads version " +
                      std::to_string(f.version) + ": rebuild the file with pbrlod build");
  if (v != f.version)
    throw FormatError(r.path + ": version " + std::to_string(v) + ", this library reads version " +
                      std::to_string(f.version));
}

/// Whether a file's colour flag matches the hierarchy type asked to load it.
inline void check_colour_flag(bool file_has, bool type_has, const std::string& path,
                              const char* type_name) {
  if (file_has != type_has)
    throw FormatError(path +
                      (file_has ? ": the file has colours, the requested "
                                : ": the file has no colours, the requested ") +
                      type_name + (file_has ? " has none" : " needs them"));
}

/// Appends the FNV-1a checksum of everything written so far.
inline void append_checksum(byte_writer& w) {
  w.put(fnv1a(w.bytes.data(), w.bytes.size()));
}

/// Whether the last 8 bytes are the FNV-1a checksum of the rest (a file shorter than that is
/// never valid).
inline bool checksum_matches(const std::vector<unsigned char>& bytes) {
  if (bytes.size() < 8) return false;
  std::uint64_t stored = 0;
  std::memcpy(&stored, bytes.data() + bytes.size() - 8, 8);
  return stored == fnv1a(bytes.data(), bytes.size() - 8);
}

/// Writes the whole file, whole or not at all (core/atomic_file.hpp): a failed or killed write
/// leaves the previous file as it was. Throws IoError naming the file and the reason.
inline void save_file_bytes(const std::string& path, const std::vector<unsigned char>& bytes) {
  write_file_atomically(path, bytes.data(), bytes.size());
}

}  // namespace pbr_lod::detail
