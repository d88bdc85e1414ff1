// pbr_lod — internals of the PLY reader shared by read_mesh (ply_reader.cpp) and the streaming
// point source (point_source_file.cpp): the header, the two row decoders (binary and ASCII), the
// plan that gives each vertex property its role, and one row's decoding. Not installed.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <type_traits>
#include <utility>

#include "io_internal.hpp"

namespace pbr_lod::detail {

enum class scalar : std::uint8_t { i8, u8, i16, u16, i32, u32, f32, f64 };

inline std::size_t scalar_size(scalar t) {
  switch (t) {
    case scalar::i8:
    case scalar::u8:
      return 1;
    case scalar::i16:
    case scalar::u16:
      return 2;
    case scalar::i32:
    case scalar::u32:
    case scalar::f32:
      return 4;
    case scalar::f64:
      return 8;
  }
  return 8;
}

inline bool is_integer(scalar t) {
  return t != scalar::f32 && t != scalar::f64;
}

inline std::pair<std::int64_t, std::int64_t> integer_range(scalar t) {
  switch (t) {
    case scalar::i8:
      return {-128, 127};
    case scalar::u8:
      return {0, 255};
    case scalar::i16:
      return {-32768, 32767};
    case scalar::u16:
      return {0, 65535};
    case scalar::i32:
      return {std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::max()};
    default:
      return {0, std::numeric_limits<std::uint32_t>::max()};
  }
}

enum class encoding : std::uint8_t { ascii, binary_le, binary_be };

/// What a property feeds. Everything not listed is read and discarded.
enum class slot : std::uint8_t {
  skip,
  x,
  y,
  z,
  nx,
  ny,
  nz,
  red,
  green,
  blue,
  tu,
  tv,
  indices,
  texcoords
};

struct property {
  std::string name;
  scalar type = scalar::f32;
  bool is_list = false;
  scalar count_type = scalar::u8;
  slot role = slot::skip;
};

struct element {
  std::string name;
  std::uint64_t count = 0;
  std::vector<property> props;
  std::size_t header_line = 0;
};

struct ply_header {
  encoding format = encoding::ascii;
  std::vector<element> elements;
  std::size_t data_begin = 0;       ///< byte offset of the first data byte
  std::size_t first_data_line = 0;  ///< 1-based line number where ASCII data starts
  std::optional<vec3d> origin;      ///< "comment pbr_lod_origin X Y Z"
  std::string texture_file;         ///< "comment TextureFile NAME"
};

/// Up to 24 characters of s with non-printable ones as '?' (for messages).
[[nodiscard]] std::string printable_prefix(std::string_view s);

/// Parses the header (magic to end_header) of the PLY whose first bytes are `bytes`; they must
/// reach past the end_header line (or be the whole file, which then gets the truncation error).
[[nodiscard]] ply_header parse_ply_header(const std::string& path, std::string_view bytes);

/// Binary rows: a cursor over the data bytes; every read is bounds-checked.
class binary_source {
 public:
  binary_source(const unsigned char* b, const unsigned char* e, bool swap)
      : p_(b), end_(e), swap_(swap) {}

  [[nodiscard]] bool has(std::uint64_t n) const {
    return static_cast<std::uint64_t>(end_ - p_) >= n;
  }
  [[nodiscard]] std::size_t remaining() const { return static_cast<std::size_t>(end_ - p_); }
  bool begin_row() { return true; }
  [[nodiscard]] bool end_row() const { return true; }
  [[nodiscard]] std::size_t line() const { return 0; }

  /// false when the file ends first.
  /// Reads one scalar of type t into out; an integer target refuses float types (the header
  /// check keeps them out of lists and indices anyway).
  template <class Out>
  bool read_scalar(scalar t, Out& out) {
    if (!has(scalar_size(t))) return false;
    switch (t) {
      case scalar::i8:
        out = static_cast<Out>(get<std::int8_t>());
        break;
      case scalar::u8:
        out = static_cast<Out>(get<std::uint8_t>());
        break;
      case scalar::i16:
        out = static_cast<Out>(get<std::int16_t>());
        break;
      case scalar::u16:
        out = static_cast<Out>(get<std::uint16_t>());
        break;
      case scalar::i32:
        out = static_cast<Out>(get<std::int32_t>());
        break;
      case scalar::u32:
        out = static_cast<Out>(get<std::uint32_t>());
        break;
      case scalar::f32:
      case scalar::f64:
        if constexpr (std::is_floating_point_v<Out>) {
          out = t == scalar::f32 ? static_cast<Out>(get<float>()) : static_cast<Out>(get<double>());
          break;
        } else {
          return false;
        }
    }
    return true;
  }
  bool real(scalar t, double& out) { return read_scalar(t, out); }
  bool integer(scalar t, std::int64_t& out) { return read_scalar(t, out); }
  /// Can a list of n items of type t still be read?
  [[nodiscard]] bool list_fits(std::uint64_t n, scalar t) const {
    const auto bytes = mul_checked(n, scalar_size(t));
    return bytes && has(*bytes);
  }
  [[nodiscard]] const char* truncated_what() const { return "the file ends (truncated)"; }

 private:
  template <class T>
  T get() {
    T v;
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return swap_ ? byte_swapped(v) : v;
  }
  const unsigned char* p_;
  const unsigned char* end_;
  bool swap_;
};

/// ASCII rows: one row per non-empty line, values separated by spaces.
class ascii_source {
 public:
  ascii_source(std::string_view data, std::size_t first_line)
      : data_(data), line_(first_line - 1) {}
  /// Starts over on other data (keeps the token buffer: one decoder serves many lines).
  void reset(std::string_view data, std::size_t first_line) {
    data_ = data;
    pos_ = next_ = 0;
    line_ = first_line - 1;
    bad_value_.clear();
  }

  /// Moves to the next non-empty line; false when there is none.
  bool begin_row() {
    while (pos_ < data_.size()) {
      std::size_t nl = data_.find('\n', pos_);
      if (nl == std::string_view::npos) nl = data_.size();
      const std::string_view l = data_.substr(pos_, nl - pos_);
      pos_ = nl + 1;
      ++line_;
      if (split_ws(l, tok_) > 0) {
        next_ = 0;
        return true;
      }
    }
    return false;
  }
  /// True when the row had no values left over.
  [[nodiscard]] bool end_row() const { return next_ == tok_.size(); }
  [[nodiscard]] std::size_t line() const { return line_; }

  bool real(scalar t, double& out) {
    if (next_ >= tok_.size()) return false;
    const std::string_view s = tok_[next_++];
    if (t == scalar::f32) {
      const auto v = parse_number<float>(s);
      if (!v) return bad(s, t);
      out = *v;
    } else if (t == scalar::f64) {
      const auto v = parse_number<double>(s);
      if (!v) return bad(s, t);
      out = *v;
    } else {
      std::int64_t i = 0;
      if (!parse_int(s, t, i)) return false;
      out = static_cast<double>(i);
    }
    return true;
  }
  bool integer(scalar t, std::int64_t& out) {
    if (next_ >= tok_.size()) return false;
    return parse_int(tok_[next_++], t, out);
  }
  [[nodiscard]] bool list_fits(std::uint64_t n, scalar) const { return n <= tok_.size() - next_; }
  [[nodiscard]] std::string truncated_what() const {
    return bad_value_.empty() ? cat("expected more values on the line (found ", tok_.size(), ")")
                              : bad_value_;
  }

 private:
  bool parse_int(std::string_view s, scalar t, std::int64_t& out) {
    const auto v = parse_number<std::int64_t>(s);
    const auto [lo, hi] = integer_range(t);
    if (!v || *v < lo || *v > hi) return bad(s, t);
    out = *v;
    return true;
  }
  bool bad(std::string_view s, scalar t) {
    bad_value_ = cat("value '", printable_prefix(s), "' is not ",
                     is_integer(t) ? "an integer of the declared type" : "a number");
    return false;
  }
  std::string_view data_;
  std::size_t pos_ = 0, line_ = 0, next_ = 0;
  std::vector<std::string_view> tok_;
  std::string bad_value_;
};

/// What plan_ply found: the vertex and face elements and which attributes the vertices carry.
struct ply_plan {
  const element* vertex = nullptr;
  const element* face = nullptr;
  bool has_normals = false, has_colours = false, has_vertex_tc = false, has_face_tc = false;
};

/// Assigns each property its role, checks that the vertex/face elements are usable and warns
/// (into `report`) about incomplete normals or colours.
[[nodiscard]] ply_plan plan_ply(const std::string& path, ply_header& h, read_report& report);

/// Binary: the least number of bytes the header implies (lists empty) must be in the file.
/// Returns that number; throws FormatError when `available` data bytes are fewer.
std::uint64_t check_binary_size(const std::string& path, const ply_header& h,
                                std::uint64_t available);

/// ASCII: the number of rows (= non-empty data lines) the header promises (FormatError on
/// overflow).
[[nodiscard]] std::uint64_t ascii_rows(const std::string& path, const ply_header& h);
/// The FormatError for an ASCII file with only `lines` non-empty data lines of `rows` promised.
[[noreturn]] void ascii_truncated(const std::string& path, const ply_header& h, std::uint64_t rows,
                                  std::uint64_t lines);

/// Decodes one row of any element into values by slot (`v`, 16 entries; colours already as
/// 0–255), the face's index list (`poly`) and texcoord list (`tc`). Throws FormatError naming the
/// element, the row and, for ASCII, the line.
class ply_row_reader {
 public:
  ply_row_reader(const std::string& path, encoding format) : path_(path), format_(format) {}
  std::vector<std::int64_t> poly;
  std::vector<float> tc;

  template <class Src>
  [[noreturn]] void row_error(const Src& src, const element& e, std::uint64_t row,
                              const std::string& what) const {
    std::string where = cat(e.name, " ", row);
    if (format_ == encoding::ascii) where += cat(" (line ", src.line(), ")");
    format_error(path_, where, what);
  }

  template <class Src>
  void read(Src& src, const element& e, std::uint64_t row, double* v) {
    if (!src.begin_row()) row_error(src, e, row, "the file ends (truncated)");
    std::fill(v, v + 16, 0.0);
    poly.clear();
    tc.clear();
    for (const property& p : e.props) {
      if (!p.is_list) {
        double x = 0;
        if (!src.real(p.type, x)) row_error(src, e, row, src.truncated_what());
        v[static_cast<int>(p.role)] = x;
        if (p.role == slot::red || p.role == slot::green || p.role == slot::blue)
          v[static_cast<int>(p.role)] = colour_channel(x, p.type);
        continue;
      }
      std::int64_t n = 0;
      if (!src.integer(p.count_type, n)) row_error(src, e, row, src.truncated_what());
      if (n < 0) row_error(src, e, row, cat("negative list length ", n, " for ", p.name));
      if (!src.list_fits(static_cast<std::uint64_t>(n), p.type))
        row_error(src, e, row,
                  cat("list ", p.name, " of length ", n, " runs past the end of the ",
                      format_ == encoding::ascii ? "line" : "file (truncated)"));
      if (p.role == slot::indices) {
        poly.resize(static_cast<std::size_t>(n));
        for (auto& i : poly)
          if (!src.integer(p.type, i)) row_error(src, e, row, src.truncated_what());
      } else if (p.role == slot::texcoords) {
        tc.resize(static_cast<std::size_t>(n));
        for (auto& t : tc) {
          double x = 0;
          if (!src.real(p.type, x)) row_error(src, e, row, src.truncated_what());
          t = static_cast<float>(x);
        }
      } else {
        for (std::int64_t k = 0; k < n; ++k) {
          double x = 0;
          if (!src.real(p.type, x)) row_error(src, e, row, src.truncated_what());
        }
      }
    }
    if (!src.end_row())
      row_error(src, e, row, cat("more values on the line than the header declares"));
  }

 private:
  static double colour_channel(double x, scalar t) {
    if (t == scalar::f32 || t == scalar::f64) return unit_to_u8(x);
    if (t == scalar::u16) return std::floor(x / 256.0);
    return std::clamp(x, 0.0, 255.0);
  }
  const std::string& path_;
  encoding format_;
};

/// One vertex from a decoded row (ply_row_reader::read's values by slot).
struct ply_vertex {
  vec3d position;
  vec3f normal;
  rgb8 colour;
  vec2f tc;
};
[[nodiscard]] inline ply_vertex make_ply_vertex(const double* v) {
  const auto at = [&](slot s) { return v[static_cast<int>(s)]; };
  return {vec3d(at(slot::x), at(slot::y), at(slot::z)),
          vec3f(static_cast<float>(at(slot::nx)), static_cast<float>(at(slot::ny)),
                static_cast<float>(at(slot::nz))),
          {static_cast<std::uint8_t>(at(slot::red)), static_cast<std::uint8_t>(at(slot::green)),
           static_cast<std::uint8_t>(at(slot::blue))},
          vec2f(static_cast<float>(at(slot::tu)), static_cast<float>(at(slot::tv)))};
}

}  // namespace pbr_lod::detail
