// pbr_lod — our PLY reader (ASCII, binary little and big endian).
//
// Why our own and not OpenMesh's, which the rest of mesh I/O uses: measured with OpenMesh 9.0,
//  * `property double x` is parsed into a float (10000000.123456789 comes back as 10000000), so
//    georeferenced data and write_ply round trips would lose everything below 1 unit;
//  * its TriMesh duplicates the vertices of every non-manifold face (happy_vrip_res3: 32,328
//    vertices in the file, 45,168 after reading);
//  * a header promising more faces than the file holds reads "successfully" with garbage, and a
//    face with an out-of-range index is silently dropped.
// The header has to be parsed and every count checked anyway; the body is a few more lines.
//
// What is read: element "vertex" (x y z of any scalar type; nx ny nz or normal_x..; red green
// blue or r g b or diffuse_*; per-vertex texture coordinates s t / u v / texture_u texture_v),
// element "face" (vertex_indices or vertex_index list, fan-triangulated; MeshLab's per-corner
// `texcoord` list), comments "TextureFile <image>" (MeshLab) and "pbr_lod_origin X Y Z"
// (write_ply). Other elements and properties are read past and ignored.
//
// What is checked: magic, format line, keywords, types, counts; binary data at least as long as
// the header requires before anything is allocated, then every read bounds-checked; ASCII rows
// one per line with exactly the declared number of values, each a number of the declared type;
// every face index in range. Faces repeating a vertex or with fewer than 3 are dropped and counted.
#include <algorithm>
#include <filesystem>
#include <limits>
#include <type_traits>

#include "ply_format.hpp"

namespace pbr_lod::detail {
namespace {

std::optional<scalar> parse_scalar(std::string_view s) {
  if (s == "char" || s == "int8") return scalar::i8;
  if (s == "uchar" || s == "uint8") return scalar::u8;
  if (s == "short" || s == "int16") return scalar::i16;
  if (s == "ushort" || s == "uint16") return scalar::u16;
  if (s == "int" || s == "int32") return scalar::i32;
  if (s == "uint" || s == "uint32") return scalar::u32;
  if (s == "float" || s == "float32") return scalar::f32;
  if (s == "double" || s == "float64") return scalar::f64;
  return std::nullopt;
}

}  // namespace

std::string printable_prefix(std::string_view s) {
  std::string out;
  for (char ch : s.substr(0, 24)) out += (ch >= 32 && ch < 127) ? ch : '?';
  return out;
}

ply_header parse_ply_header(const std::string& path, std::string_view bytes) {
  if (bytes.empty()) format_error(path, "", "the file is empty; expected a PLY header");
  ply_header h;
  std::vector<std::string_view> tok;
  std::size_t pos = 0, line_no = 0;
  bool have_format = false, ended = false;
  while (pos < bytes.size()) {
    const std::size_t nl = bytes.find('\n', pos);
    if (nl == std::string_view::npos) break;  // a header line without '\n': the file ends here
    std::string_view line = bytes.substr(pos, nl - pos);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos = nl + 1;
    ++line_no;
    const std::string where = cat("header line ", line_no);
    if (line_no == 1) {
      if (trim(line) != "ply")
        format_error(path, where,
                     cat("expected the magic 'ply', found '", printable_prefix(line), "'"));
      continue;
    }
    split_ws(line, tok);
    if (tok.empty()) continue;
    const std::string_view kw = tok[0];
    if (kw == "comment") {
      if (tok.size() == 5 && tok[1] == "pbr_lod_origin") {
        const auto x = parse_number<double>(tok[2]), y = parse_number<double>(tok[3]),
                   z = parse_number<double>(tok[4]);
        if (x && y && z) h.origin = vec3d(*x, *y, *z);
      } else if (tok.size() >= 3 && tok[1] == "TextureFile") {
        const std::size_t at = line.find("TextureFile") + std::string_view("TextureFile").size();
        h.texture_file = std::string(trim(line.substr(at)));
      }
    } else if (kw == "obj_info") {
      // free text
    } else if (kw == "format") {
      if (tok.size() != 3)
        format_error(path, where,
                     "expected 'format ascii|binary_little_endian|binary_big_endian 1.0'");
      if (tok[1] == "ascii")
        h.format = encoding::ascii;
      else if (tok[1] == "binary_little_endian")
        h.format = encoding::binary_le;
      else if (tok[1] == "binary_big_endian")
        h.format = encoding::binary_be;
      else
        format_error(path, where, cat("unknown format '", tok[1], "'"));
      if (tok[2] != "1.0" && tok[2] != "1")
        format_error(path, where, cat("unsupported PLY version '", tok[2], "', expected 1.0"));
      have_format = true;
    } else if (kw == "element") {
      if (tok.size() != 3) format_error(path, where, "expected 'element <name> <count>'");
      const auto count = parse_number<std::uint64_t>(tok[2]);
      if (!count)
        format_error(path, where,
                     cat("element count '", tok[2], "' is not a non-negative integer"));
      h.elements.push_back({std::string(tok[1]), *count, {}, line_no});
    } else if (kw == "property") {
      if (h.elements.empty()) format_error(path, where, "property before any element");
      property p;
      if (tok.size() >= 2 && tok[1] == "list") {
        if (tok.size() != 5)
          format_error(path, where, "expected 'property list <count type> <item type> <name>'");
        const auto ct = parse_scalar(tok[2]);
        const auto it = parse_scalar(tok[3]);
        if (!ct || !it) format_error(path, where, cat("unknown type '", ct ? tok[3] : tok[2], "'"));
        if (!is_integer(*ct))
          format_error(path, where, "the count type of a list must be an integer type");
        p.is_list = true;
        p.count_type = *ct;
        p.type = *it;
        p.name = std::string(tok[4]);
      } else {
        if (tok.size() != 3) format_error(path, where, "expected 'property <type> <name>'");
        const auto t = parse_scalar(tok[1]);
        if (!t) format_error(path, where, cat("unknown type '", tok[1], "'"));
        p.type = *t;
        p.name = std::string(tok[2]);
      }
      h.elements.back().props.push_back(std::move(p));
    } else if (kw == "end_header") {
      ended = true;
      break;
    } else {
      format_error(path, where, cat("unknown header keyword '", printable_prefix(kw), "'"));
    }
  }
  if (!ended)
    format_error(path, cat("header line ", line_no + 1),
                 "the file ends before 'end_header' (truncated or not a PLY file)");
  if (!have_format) format_error(path, "header", "no 'format' line");
  h.data_begin = pos;
  h.first_data_line = line_no + 1;
  return h;
}

namespace {

slot vertex_role(const std::string& n) {
  if (n == "x") return slot::x;
  if (n == "y") return slot::y;
  if (n == "z") return slot::z;
  if (n == "nx" || n == "normal_x") return slot::nx;
  if (n == "ny" || n == "normal_y") return slot::ny;
  if (n == "nz" || n == "normal_z") return slot::nz;
  if (n == "red" || n == "r" || n == "diffuse_red") return slot::red;
  if (n == "green" || n == "g" || n == "diffuse_green") return slot::green;
  if (n == "blue" || n == "b" || n == "diffuse_blue") return slot::blue;
  if (n == "s" || n == "u" || n == "texture_u" || n == "texture_s") return slot::tu;
  if (n == "t" || n == "v" || n == "texture_v" || n == "texture_t") return slot::tv;
  return slot::skip;
}

}  // namespace

ply_plan plan_ply(const std::string& path, ply_header& h, read_report& report) {
  ply_plan pl;
  const auto warn = [&](const std::string& what) {
    report.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": ", what));
  };
  for (element& e : h.elements) {
    const std::string where = cat("header line ", e.header_line);
    // A row without properties takes no bytes: a huge count would loop for nothing.
    if (e.count > 0 && e.props.empty())
      format_error(path, where, cat("element ", e.name, " has rows but no properties"));
    if (e.name == "vertex") {
      if (pl.vertex != nullptr) format_error(path, where, "a second 'vertex' element");
      pl.vertex = &e;
      if (e.count > std::numeric_limits<std::uint32_t>::max())
        format_error(path, where,
                     cat(e.count, " vertices: more than 32-bit face indices can address"));
      for (property& p : e.props) {
        p.role = vertex_role(p.name);
        if (p.role != slot::skip && p.is_list)
          format_error(path, where, cat("vertex property '", p.name, "' must not be a list"));
      }
      const auto has = [&](slot s) {
        return std::any_of(e.props.begin(), e.props.end(),
                           [s](const property& p) { return p.role == s; });
      };
      if (!has(slot::x) || !has(slot::y) || !has(slot::z))
        format_error(path, where, "element vertex needs properties x, y and z");
      pl.has_normals = has(slot::nx) && has(slot::ny) && has(slot::nz);
      pl.has_colours = has(slot::red) && has(slot::green) && has(slot::blue);
      pl.has_vertex_tc = has(slot::tu) && has(slot::tv);
      if (!pl.has_normals && (has(slot::nx) || has(slot::ny) || has(slot::nz)))
        warn("vertex normals are incomplete (need nx, ny and nz) and were ignored");
      if (!pl.has_colours && (has(slot::red) || has(slot::green) || has(slot::blue)))
        warn("vertex colours are incomplete (need red, green and blue) and were ignored");
    } else if (e.name == "face") {
      if (pl.face != nullptr) format_error(path, where, "a second 'face' element");
      pl.face = &e;
      for (property& p : e.props) {
        if (p.is_list && (p.name == "vertex_indices" || p.name == "vertex_index")) {
          if (!is_integer(p.type))
            format_error(path, where, cat("'", p.name, "' must be a list of integers"));
          p.role = slot::indices;
        } else if (p.is_list && p.name == "texcoord") {
          p.role = slot::texcoords;
        }
      }
      const bool ok = std::any_of(e.props.begin(), e.props.end(),
                                  [](const property& p) { return p.role == slot::indices; });
      pl.has_face_tc = std::any_of(e.props.begin(), e.props.end(),
                                   [](const property& p) { return p.role == slot::texcoords; });
      if (!ok && e.count > 0)
        format_error(path, where, "element face has no 'vertex_indices' list");
    }
  }
  return pl;
}

// Checked before anything is allocated, so a lying count cannot make us reserve gigabytes.
std::uint64_t check_binary_size(const std::string& path, const ply_header& h,
                                std::uint64_t available) {
  std::uint64_t need = 0;
  for (const element& e : h.elements) {
    std::uint64_t row = 0;
    for (const property& p : e.props) row += scalar_size(p.is_list ? p.count_type : p.type);
    const auto bytes = mul_checked(e.count, row);
    const auto total = bytes ? add_checked(need, *bytes) : std::nullopt;
    if (!total)
      format_error(path, cat("header line ", e.header_line),
                   cat("element ", e.name, " count ", e.count, " is impossibly large"));
    need = *total;
  }
  if (need > available)
    format_error(path, "data",
                 cat("truncated: the header needs at least ", need,
                     " bytes of binary data, the file has ", available, " after the header"));
  return need;
}

std::uint64_t ascii_rows(const std::string& path, const ply_header& h) {
  std::uint64_t rows = 0;
  for (const element& e : h.elements) {
    const auto r = add_checked(rows, e.count);
    if (!r)
      format_error(path, cat("header line ", e.header_line),
                   cat("element ", e.name, " count ", e.count, " is impossibly large"));
    rows = *r;
  }
  return rows;
}

void ascii_truncated(const std::string& path, const ply_header& h, std::uint64_t rows,
                     std::uint64_t lines) {
  std::string promised;
  for (const element& e : h.elements)
    promised += cat(promised.empty() ? "" : ", ", e.count, " ", e.name);
  format_error(path, "data",
               cat("truncated: the header promises ", rows, " data lines (", promised,
                   ") but the file has only ", lines));
}

namespace {

class ply_parser {
 public:
  ply_parser(const std::string& path, read_report& report, ply_header& h)
      : path_(path), report_(report), h_(h), rows_(path, h.format) {}

  raw_geometry run(std::string_view bytes) {
    plan_ = plan_ply(path_, h_, report_);
    vertex_count_ = plan_.vertex ? plan_.vertex->count : 0;
    const std::string_view data = bytes.substr(h_.data_begin);
    if (h_.format == encoding::ascii) {
      check_ascii_lines(data);
      ascii_source src(data, h_.first_data_line);
      parse_all(src);
      std::size_t extra = 0;
      while (src.begin_row()) ++extra;
      if (extra > 0) warn(cat(extra, " non-empty lines after the last element were ignored"));
    } else {
      check_binary_size(path_, h_, data.size());
      const auto* b = reinterpret_cast<const unsigned char*>(data.data());
      const bool swap =
          (h_.format == encoding::binary_be) != (std::endian::native == std::endian::big);
      binary_source src(b, b + data.size(), swap);
      parse_all(src);
      if (src.remaining() > 0)
        warn(cat(src.remaining(), " bytes after the last element were ignored"));
    }
    finish();
    return std::move(g_);
  }

 private:
  // ASCII: one row per line, so there must be at least as many non-empty lines as rows.
  void check_ascii_lines(std::string_view data) const {
    const std::uint64_t rows = ascii_rows(path_, h_);
    std::uint64_t lines = 0;
    std::size_t pos = 0;
    while (pos < data.size() && lines < rows) {
      std::size_t nl = data.find('\n', pos);
      if (nl == std::string_view::npos) nl = data.size();
      for (std::size_t i = pos; i < nl; ++i)
        if (data[i] != ' ' && data[i] != '\t' && data[i] != '\r') {
          ++lines;
          break;
        }
      pos = nl + 1;
    }
    if (lines < rows) ascii_truncated(path_, h_, rows, lines);
  }

  template <class Src>
  void parse_all(Src& src) {
    for (const element& e : h_.elements) {
      if (&e == plan_.vertex) {
        g_.positions.reserve(e.count);
        if (plan_.has_normals) g_.normals.reserve(e.count);
        if (plan_.has_colours) g_.colours.reserve(e.count);
        if (plan_.has_vertex_tc) vertex_tc_.reserve(e.count);
      } else if (&e == plan_.face) {
        g_.faces.reserve(e.count);
        if (plan_.has_face_tc) face_tc_.reserve(e.count);
      }
      double v[16];
      for (std::uint64_t row = 0; row < e.count; ++row) {
        rows_.read(src, e, row, v);
        if (&e == plan_.vertex)
          add_vertex(make_ply_vertex(v));
        else if (&e == plan_.face)
          add_face(src, e, row);
      }
    }
  }

  void add_vertex(const ply_vertex& v) {
    g_.positions.push_back(v.position);
    if (plan_.has_normals) g_.normals.push_back(v.normal);
    if (plan_.has_colours) g_.colours.push_back(v.colour);
    if (plan_.has_vertex_tc) vertex_tc_.push_back(v.tc);
  }

  template <class Src>
  void add_face(const Src& src, const element& e, std::uint64_t row) {
    const std::vector<std::int64_t>& poly = rows_.poly;
    const std::vector<float>& tc = rows_.tc;
    for (const std::int64_t i : poly)
      if (i < 0 || static_cast<std::uint64_t>(i) >= vertex_count_)
        rows_.row_error(
            src, e, row,
            cat("vertex index ", i, " is out of range: the file has ", vertex_count_, " vertices"));
    const std::size_t n = poly.size();
    if (n < 3 || has_repeats()) {
      ++degenerate_;
      report_.faces_dropped += n < 3 ? 1 : n - 2;
      return;
    }
    const bool tc_ok = tc.size() == 2 * n;
    if (plan_.has_face_tc && !tc_ok) ++tc_mismatch_;
    if (tc_ok) any_face_tc_ = true;
    const auto corner = [&](std::size_t k) {
      return tc_ok ? vec2f(tc[2 * k], tc[2 * k + 1]) : vec2f::Zero();
    };
    for (std::size_t k = 1; k + 1 < n; ++k) {
      g_.faces.push_back({static_cast<std::uint32_t>(poly[0]), static_cast<std::uint32_t>(poly[k]),
                          static_cast<std::uint32_t>(poly[k + 1])});
      if (plan_.has_face_tc) face_tc_.push_back({corner(0), corner(k), corner(k + 1)});
    }
  }

  bool has_repeats() {
    const std::vector<std::int64_t>& poly = rows_.poly;
    const std::size_t n = poly.size();
    if (n == 3) return poly[0] == poly[1] || poly[1] == poly[2] || poly[0] == poly[2];
    sorted_.assign(poly.begin(), poly.end());  // O(n log n): a face may have millions of corners
    std::sort(sorted_.begin(), sorted_.end());
    return std::adjacent_find(sorted_.begin(), sorted_.end()) != sorted_.end();
  }

  void finish() {
    if (degenerate_ > 0)
      warn(cat("dropped ", degenerate_,
               " degenerate faces (fewer than 3 vertices or a repeated vertex)"));
    if (any_face_tc_) {
      g_.face_texcoords = std::move(face_tc_);
      if (tc_mismatch_ > 0)
        warn(cat(tc_mismatch_, " faces have a texcoord list of the wrong length; set to (0, 0)"));
    } else if (plan_.has_vertex_tc && !g_.faces.empty()) {
      // Per-vertex texture coordinates become per-corner ones (what triangle_mesh stores).
      g_.face_texcoords.reserve(g_.faces.size());
      for (const auto& f : g_.faces)
        g_.face_texcoords.push_back({vertex_tc_[f[0]], vertex_tc_[f[1]], vertex_tc_[f[2]]});
    }
    if (!h_.texture_file.empty()) {
      std::filesystem::path t(h_.texture_file);
      if (t.is_relative()) t = std::filesystem::path(path_).parent_path() / t;
      g_.texture_path = t.lexically_normal().string();
    }
    g_.origin_hint = h_.origin;
  }

  void warn(const std::string& what) {
    report_.warnings.push_back(cat(std::filesystem::path(path_).filename().string(), ": ", what));
  }

  const std::string& path_;
  read_report& report_;
  ply_header& h_;
  ply_row_reader rows_;
  ply_plan plan_;
  raw_geometry g_;
  std::uint64_t vertex_count_ = 0;
  bool any_face_tc_ = false;
  std::size_t degenerate_ = 0, tc_mismatch_ = 0;
  std::vector<std::int64_t> sorted_;
  std::vector<vec2f> vertex_tc_;
  std::vector<std::array<vec2f, 3>> face_tc_;
};

}  // namespace

raw_geometry read_ply_file(const std::string& path, read_report& report) {
  const std::string bytes = read_file_bytes(path);
  ply_header h = parse_ply_header(path, bytes);
  return ply_parser(path, report, h).run(bytes);
}

}  // namespace pbr_lod::detail
