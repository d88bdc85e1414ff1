// pbr_lod — internals shared by the file readers and writers in src/io (not installed).
//
// Every reader parses into a raw_geometry (world coordinates in double, nothing dropped yet) and
// hands it to finish_mesh, which is the one place that drops non-finite points, picks the origin
// and converts to the float-relative containers. So the rules of read.hpp hold for every format.
#pragma once

#include <array>
#include <bit>
#include <charconv>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"
#include "pbr_lod/io/read.hpp"

namespace pbr_lod::detail {

/// A file as parsed, before finish_mesh: world positions in double, attribute vectors empty or
/// one entry per position (normals, colours) or per face (face_texcoords).
struct raw_geometry {
  std::vector<vec3d> positions;
  std::vector<vec3f> normals;
  std::vector<rgb8> colours;
  std::vector<std::array<std::uint32_t, 3>> faces;
  std::vector<std::array<vec2f, 3>> face_texcoords;
  std::string texture_path;
  /// An origin the file asks for (write_ply stores one); used when it is finite and inside the
  /// bounding box of the finite points, else the box centre is used.
  std::optional<vec3d> origin_hint;
  /// The scanner's position in the file's coordinates, when the format records it.
  std::optional<vec3d> sensor;
};

/// Drops non-finite points (and faces using them), chooses the origin, converts positions to
/// float relative to it, and records counts and warnings in `report`.
[[nodiscard]] triangle_mesh finish_mesh(raw_geometry&& g, const std::string& path,
                                        read_report& report);

// --- finish_mesh's per-point rules, shared with the streaming sources (point_source_file.cpp),
// so that a file read whole and the same file read in blocks cannot disagree -----------------

/// The bounding box of the finite points, in double, grown one point at a time.
struct finite_box {
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity());
  vec3d hi = vec3d::Constant(-std::numeric_limits<double>::infinity());
  std::uint64_t total = 0;   ///< points seen
  std::uint64_t finite = 0;  ///< of those, with three finite coordinates (the ones kept)
  /// Counts p and returns whether it is kept.
  bool add(const vec3d& p) {
    ++total;
    if (!all_finite(p)) return false;
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
    ++finite;
    return true;
  }
};

/// Records points_read / dropped_non_finite (and the dropped warning) in `report` and returns the
/// origin read.hpp promises: the box centre, or `hint` when it is finite and near the box.
/// Throws FormatError when the finite points span more than a float can hold.
[[nodiscard]] vec3d choose_origin(const finite_box& box, const std::optional<vec3d>& hint,
                                  const std::string& path, read_report& report);

/// The rule for a stored normal: non-finite → zero, clearly non-unit → normalised; counts both.
struct normal_rule {
  std::size_t bad = 0, renormalised = 0;
  vec3f operator()(vec3f n);
  /// The warnings for what was counted.
  void report_to(const std::string& path, read_report& report) const;
};

// --- the format parsers (one .cpp each) ---------------------------------------------------------
[[nodiscard]] raw_geometry read_ply_file(const std::string& path, read_report& report);
[[nodiscard]] raw_geometry read_obj_file(const std::string& path, read_report& report);
[[nodiscard]] raw_geometry read_off_file(const std::string& path, read_report& report);
[[nodiscard]] raw_geometry read_pcd_file(const std::string& path, read_report& report);
[[nodiscard]] raw_geometry read_las_file(const std::string& path, read_report& report);

// --- small utilities ----------------------------------------------------------------------------

/// The whole file in memory. Throws IoError when it is missing, a directory or unreadable.
[[nodiscard]] std::string read_file_bytes(const std::string& path);

/// A file opened for positioned reads (pread): no shared cursor, so const reads from several
/// threads at once are safe. Throws IoError as read_file_bytes does.
class posix_file {
 public:
  explicit posix_file(const std::string& path);
  ~posix_file();
  posix_file(const posix_file&) = delete;
  posix_file& operator=(const posix_file&) = delete;
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] std::uint64_t size() const { return size_; }
  /// Up to n bytes at `offset` into out; returns how many (fewer only at the end of the file).
  std::size_t read_some(std::uint64_t offset, std::size_t n, void* out) const;
  /// Exactly n bytes at `offset`; IoError when the file is shorter (it changed since opening).
  void read_exact(std::uint64_t offset, std::size_t n, void* out) const;

 private:
  std::string path_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
};

/// The file's first bytes through the first complete line whose first word is `last_key`
/// ("end_header", "DATA"), read in growing pieces so that a header is parsed without reading
/// the data; the whole file when there is no such line. FormatError when the header would
/// exceed 64 MiB.
[[nodiscard]] std::string read_header_lines(const posix_file& f, std::string_view last_key);

/// ".ply" for "a/b.PLY"; empty when there is no extension.
[[nodiscard]] std::string lower_extension(const std::string& path);

/// Concatenates anything streamable into a string (messages).
template <class... Args>
[[nodiscard]] std::string cat(const Args&... args) {
  std::ostringstream s;
  (s << ... << args);
  return s.str();
}

/// Throws FormatError "<path>: <where>: <what>" (where may be empty).
[[noreturn]] void format_error(const std::string& path, const std::string& where,
                               const std::string& what);

/// Strips spaces, tabs and a trailing '\r'.
[[nodiscard]] std::string_view trim(std::string_view s);

/// Splits on spaces/tabs into `out` (cleared first); returns out.size().
std::size_t split_ws(std::string_view line, std::vector<std::string_view>& out);

/// Parses the whole token as a number (from_chars; a leading '+' is accepted). nullopt on any
/// garbage, overflow or partial parse. For floating types "nan"/"inf" parse.
template <class T>
[[nodiscard]] std::optional<T> parse_number(std::string_view tok) {
  if (!tok.empty() && tok.front() == '+') tok.remove_prefix(1);
  T v{};
  const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), v);
  if (ec != std::errc{} || ptr != tok.data() + tok.size() || tok.empty()) return std::nullopt;
  return v;
}

/// a * b, or nullopt when it overflows.
[[nodiscard]] inline std::optional<std::uint64_t> mul_checked(std::uint64_t a, std::uint64_t b) {
  std::uint64_t r = 0;
  if (__builtin_mul_overflow(a, b, &r)) return std::nullopt;
  return r;
}
[[nodiscard]] inline std::optional<std::uint64_t> add_checked(std::uint64_t a, std::uint64_t b) {
  std::uint64_t r = 0;
  if (__builtin_add_overflow(a, b, &r)) return std::nullopt;
  return r;
}

/// Reverses the bytes of an arithmetic value (endianness).
template <class T>
[[nodiscard]] inline T byte_swapped(T v) {
  static_assert(std::is_trivially_copyable_v<T>);
  std::array<unsigned char, sizeof(T)> b{};
  std::memcpy(b.data(), &v, sizeof(T));
  for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
  std::memcpy(&v, b.data(), sizeof(T));
  return v;
}

/// Loads a little-endian value from unaligned memory (the caller has bounds-checked p).
template <class T>
[[nodiscard]] inline T load_le(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) v = byte_swapped(v);
  return v;
}

/// 8-bit colour channel from a [0, 1] float (clamped; NaN → 0).
[[nodiscard]] inline std::uint8_t unit_to_u8(double v) {
  if (!(v > 0.0)) return 0;
  if (v >= 1.0) return 255;
  return static_cast<std::uint8_t>(v * 255.0 + 0.5);
}

}  // namespace pbr_lod::detail
