// pbr_lod — our PCD reader (Point Cloud Library format v0.5–0.7; PCL itself is not used).
//
// Header: VERSION FIELDS SIZE TYPE COUNT WIDTH HEIGHT VIEWPOINT POINTS DATA, one per line, '#'
// comments. DATA ascii (one point per line), binary (points one after another, fields in header
// order) or binary_compressed (uint32 compressed size, uint32 uncompressed size, LZF data that
// decompresses to one array per field: all x, then all y, ... — structure of arrays).
//
// Read: x y z (required, any numeric type), normal_x normal_y normal_z, rgb or rgba (the 32-bit
// value, stored as a float or an integer, packs 0x00RRGGBB / 0xAARRGGBB). Other fields are
// skipped. Organised scans store NaN for "no return": those points are dropped and counted.
// VIEWPOINT is PCL's sensor pose (translation, quaternion); points are returned as stored, in
// the sensor frame, as PCL does — a warning says so when the pose is not the identity.
//
// Checked: every header line and field description, POINTS == WIDTH·HEIGHT, binary data long
// enough, compressed size within the file, uncompressed size equal to POINTS × point size and to
// what LZF actually produced.
#include <lzf.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>

#include "point_formats.hpp"

namespace pbr_lod::detail {

pcd_header parse_pcd_header(const std::string& path, std::string_view bytes) {
  if (bytes.empty()) format_error(path, "", "the file is empty; expected a PCD header");
  pcd_header h;
  std::vector<std::string_view> tok;
  std::vector<std::string> names;
  std::vector<std::string> size_store, type_store, count_store;
  bool have_width = false, have_height = false, have_points = false, have_data = false;
  std::size_t pos = 0, line_no = 0;
  while (pos < bytes.size() && !have_data) {
    std::size_t nl = bytes.find('\n', pos);
    if (nl == std::string_view::npos) nl = bytes.size();
    const std::string_view line = bytes.substr(pos, nl - pos);
    pos = std::min(nl + 1, bytes.size());
    ++line_no;
    const std::string where = cat("header line ", line_no);
    if (split_ws(line, tok) == 0 || tok[0].front() == '#') continue;
    const std::string_view key = tok[0];
    const auto one_int = [&](std::uint64_t& out) {
      if (tok.size() != 2 || !parse_number<std::uint64_t>(tok[1]))
        format_error(path, where, cat("expected '", key, " <non-negative integer>'"));
      out = *parse_number<std::uint64_t>(tok[1]);
    };
    if (key == "VERSION") {
      // 0.5, 0.6, .7, 0.7: all share the layout we read.
    } else if (key == "FIELDS" || key == "COLUMNS") {
      names.assign(tok.begin() + 1, tok.end());
      if (names.empty()) format_error(path, where, "FIELDS lists no fields");
    } else if (key == "SIZE") {
      size_store.assign(tok.begin() + 1, tok.end());
    } else if (key == "TYPE") {
      type_store.assign(tok.begin() + 1, tok.end());
    } else if (key == "COUNT") {
      count_store.assign(tok.begin() + 1, tok.end());
    } else if (key == "WIDTH") {
      one_int(h.width);
      have_width = true;
    } else if (key == "HEIGHT") {
      one_int(h.height);
      have_height = true;
    } else if (key == "POINTS") {
      one_int(h.points);
      have_points = true;
    } else if (key == "VIEWPOINT") {
      if (tok.size() != 8) format_error(path, where, "expected 'VIEWPOINT tx ty tz qw qx qy qz'");
      for (int i = 0; i < 7; ++i) {
        const auto v = parse_number<double>(tok[static_cast<std::size_t>(i) + 1]);
        if (!v || !std::isfinite(*v))
          format_error(path, where,
                       cat("'", tok[static_cast<std::size_t>(i) + 1], "' is not a finite number"));
        h.viewpoint[i] = *v;
      }
    } else if (key == "DATA") {
      if (tok.size() != 2)
        format_error(path, where, "expected 'DATA ascii|binary|binary_compressed'");
      if (tok[1] == "ascii")
        h.data = pcd_header::data_kind::ascii;
      else if (tok[1] == "binary")
        h.data = pcd_header::data_kind::binary;
      else if (tok[1] == "binary_compressed")
        h.data = pcd_header::data_kind::compressed;
      else
        format_error(path, where, cat("unknown DATA encoding '", tok[1], "'"));
      have_data = true;
      h.data_begin = nl == bytes.size() ? bytes.size() : nl + 1;
      h.data_line = line_no + 1;
    } else {
      format_error(path, where,
                   line_no == 1 ? "not a PCD file (expected header keys such as VERSION, FIELDS)"
                                : cat("unknown header key '", key.substr(0, 24), "'"));
    }
  }
  if (!have_data) format_error(path, "header", "no DATA line (truncated or not a PCD file)");
  if (names.empty()) format_error(path, "header", "no FIELDS line");
  if (!have_width) format_error(path, "header", "no WIDTH line");
  if (!have_height) h.height = 1;  // PCD 0.5 had no HEIGHT: unorganised
  const auto nfields = names.size();
  if (size_store.size() != nfields || type_store.size() != nfields)
    format_error(path, "header",
                 cat("FIELDS names ", nfields, " fields but SIZE has ", size_store.size(),
                     " and TYPE ", type_store.size(), " entries"));
  if (!count_store.empty() && count_store.size() != nfields)
    format_error(path, "header",
                 cat("FIELDS names ", nfields, " fields but COUNT has ", count_store.size()));
  const auto wh = mul_checked(h.width, h.height);
  if (!wh) format_error(path, "header", "WIDTH × HEIGHT overflows");
  if (!have_points) h.points = *wh;
  if (h.points != *wh)
    format_error(path, "header",
                 cat("POINTS is ", h.points, " but WIDTH × HEIGHT = ", h.width, " × ", h.height,
                     " = ", *wh));

  for (std::size_t i = 0; i < nfields; ++i) {
    pcd_field f;
    f.name = names[i];
    const auto size = parse_number<std::uint64_t>(size_store[i]);
    const std::string t = type_store[i];
    const auto count = count_store.empty() ? std::optional<std::uint64_t>(1)
                                           : parse_number<std::uint64_t>(count_store[i]);
    const std::string what = cat("field ", f.name);
    if (!size || t.size() != 1)
      format_error(path, what, cat("bad SIZE '", size_store[i], "' or TYPE '", t, "'"));
    f.size = *size;
    f.type = t[0];
    const bool ok = (f.type == 'F' && (f.size == 4 || f.size == 8)) ||
                    ((f.type == 'U' || f.type == 'I') &&
                     (f.size == 1 || f.size == 2 || f.size == 4 || f.size == 8));
    if (!ok)
      format_error(path, what,
                   cat("unsupported TYPE ", f.type, " with SIZE ", f.size,
                       " (expected F 4|8, U or I 1|2|4|8)"));
    if (!count || *count == 0 || *count > (1u << 20))
      format_error(path, what, cat("bad COUNT '", count_store.empty() ? "1" : count_store[i], "'"));
    f.count = *count;
    f.offset = h.point_size;
    f.value_index = h.values_per_point;
    h.point_size += f.size * f.count;
    h.values_per_point += f.count;
    h.fields.push_back(std::move(f));
  }
  return h;
}

double pcd_load_value(const unsigned char* p, const pcd_field& f) {
  switch (f.type) {
    case 'F':
      return f.size == 4 ? load_le<float>(p) : load_le<double>(p);
    case 'U':
      switch (f.size) {
        case 1:
          return *p;
        case 2:
          return load_le<std::uint16_t>(p);
        case 4:
          return load_le<std::uint32_t>(p);
        default:
          return static_cast<double>(load_le<std::uint64_t>(p));
      }
    default:
      switch (f.size) {
        case 1:
          return static_cast<std::int8_t>(*p);
        case 2:
          return load_le<std::int16_t>(p);
        case 4:
          return load_le<std::int32_t>(p);
        default:
          return static_cast<double>(load_le<std::int64_t>(p));
      }
  }
}

rgb8 pcd_unpack_rgb(std::uint32_t v) {
  return {static_cast<std::uint8_t>((v >> 16) & 255u), static_cast<std::uint8_t>((v >> 8) & 255u),
          static_cast<std::uint8_t>(v & 255u)};
}

pcd_wanted pcd_fields(const std::string& path, const pcd_header& h, read_report& report) {
  pcd_wanted w;
  const auto find = [&](std::string_view n) -> const pcd_field* {
    for (const pcd_field& f : h.fields)
      if (f.name == n) return &f;
    return nullptr;
  };
  w.xyz[0] = find("x");
  w.xyz[1] = find("y");
  w.xyz[2] = find("z");
  if (!w.xyz[0] || !w.xyz[1] || !w.xyz[2])
    format_error(path, "header", "FIELDS must include x, y and z");
  w.normal[0] = find("normal_x");
  w.normal[1] = find("normal_y");
  w.normal[2] = find("normal_z");
  if (!w.normal[0] || !w.normal[1] || !w.normal[2])
    w.normal[0] = w.normal[1] = w.normal[2] = nullptr;
  w.rgb = find("rgb");
  if (!w.rgb) w.rgb = find("rgba");
  if (w.rgb && w.rgb->size != 4) {
    report.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": field ",
                                  w.rgb->name, " has SIZE ", w.rgb->size,
                                  ", expected 4 (packed colour); colours ignored"));
    w.rgb = nullptr;
  }
  const double* vp = h.viewpoint;
  if (vp[0] != 0 || vp[1] != 0 || vp[2] != 0 || vp[3] != 1 || vp[4] != 0 || vp[5] != 0 ||
      vp[6] != 0)
    report.warnings.push_back(cat(std::filesystem::path(path).filename().string(),
                                  ": VIEWPOINT is not the identity; points are returned as "
                                  "stored (in the sensor frame), the pose is not applied"));
  return w;
}

namespace {

/// Fills g from point i whose field f starts at addr(f, i).
template <class Addr>
void gather(raw_geometry& g, const pcd_wanted& w, std::uint64_t n, Addr addr) {
  g.positions.resize(n);
  if (w.normal[0]) g.normals.resize(n);
  if (w.rgb) g.colours.resize(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    const pcd_point q = pcd_load_point(w, [&](const pcd_field& f) { return addr(f, i); });
    g.positions[i] = q.position;
    if (w.normal[0]) g.normals[i] = q.normal;
    if (w.rgb) g.colours[i] = q.colour;
  }
}

void read_ascii(const std::string& path, std::string_view data, const pcd_header& h,
                const pcd_wanted& w, raw_geometry& g) {
  std::vector<std::string_view> tok;
  std::size_t pos = 0, line_no = h.data_line - 1;
  // Reserve only what the file can hold (one point per line, at least 2 bytes each).
  const std::uint64_t n = h.points;
  const std::uint64_t cap = std::min<std::uint64_t>(n, data.size() / 2 + 1);
  g.positions.reserve(cap);
  if (w.normal[0]) g.normals.reserve(cap);
  if (w.rgb) g.colours.reserve(cap);
  for (std::uint64_t i = 0; i < n; ++i) {
    std::size_t found = 0;
    while (pos < data.size() && found == 0) {
      std::size_t nl = data.find('\n', pos);
      if (nl == std::string_view::npos) nl = data.size();
      found = split_ws(data.substr(pos, nl - pos), tok);
      pos = nl + 1;
      ++line_no;
    }
    if (found == 0) pcd_ascii_truncated(path, i, n);
    const pcd_point q = pcd_parse_ascii_point(path, h, w, tok, i, line_no);
    g.positions.push_back(q.position);
    if (w.normal[0]) g.normals.push_back(q.normal);
    if (w.rgb) g.colours.push_back(q.colour);
  }
}

}  // namespace

pcd_point pcd_parse_ascii_point(const std::string& path, const pcd_header& h, const pcd_wanted& w,
                                const std::vector<std::string_view>& tok, std::uint64_t i,
                                std::size_t line_no) {
  const std::string where = cat("point ", i, " (line ", line_no, ")");
  if (tok.size() != h.values_per_point)
    format_error(path, where, cat("expected ", h.values_per_point, " values, found ", tok.size()));
  const auto value = [&](const pcd_field& f) -> double {
    const std::string_view s = tok[f.value_index];
    std::optional<double> v;
    if (f.type == 'F') {
      v = parse_number<double>(s);
    } else if (const auto iv = parse_number<std::int64_t>(s)) {
      v = static_cast<double>(*iv);
    }
    if (!v) format_error(path, where, cat("'", s, "' in field ", f.name, " is not a number"));
    return *v;
  };
  pcd_point q;
  for (int a = 0; a < 3; ++a) q.position[a] = value(*w.xyz[a]);
  if (w.normal[0])
    q.normal =
        vec3f(static_cast<float>(value(*w.normal[0])), static_cast<float>(value(*w.normal[1])),
              static_cast<float>(value(*w.normal[2])));
  if (w.rgb) {
    // The packed value is written as the float whose bits it is (TYPE F) or as an integer.
    const std::string_view s = tok[w.rgb->value_index];
    std::uint32_t bits = 0;
    if (w.rgb->type == 'F') {
      const auto f = parse_number<float>(s);
      if (!f)
        format_error(path, where, cat("'", s, "' in field ", w.rgb->name, " is not a number"));
      bits = std::bit_cast<std::uint32_t>(*f);
    } else {
      const auto u = parse_number<std::int64_t>(s);
      if (!u || *u < std::numeric_limits<std::int32_t>::min() ||
          *u > std::numeric_limits<std::uint32_t>::max())
        format_error(path, where,
                     cat("'", s, "' in field ", w.rgb->name, " is not a 32-bit integer"));
      bits = static_cast<std::uint32_t>(*u);
    }
    q.colour = pcd_unpack_rgb(bits);
  }
  return q;
}

void pcd_ascii_truncated(const std::string& path, std::uint64_t i, std::uint64_t n) {
  format_error(path, cat("point ", i), cat("the file ends (truncated: POINTS promises ", n, ")"));
}

std::uint64_t pcd_data_bytes(const std::string& path, const pcd_header& h) {
  const auto total = mul_checked(h.points, h.point_size);
  if (!total) format_error(path, "header", "POINTS × point size overflows");
  return *total;
}

void pcd_check_binary_size(const std::string& path, const pcd_header& h, std::uint64_t available,
                           read_report& report) {
  const std::uint64_t total = pcd_data_bytes(path, h);
  if (available < total)
    format_error(path, "data",
                 cat("truncated: ", h.points, " points of ", h.point_size, " bytes need ", total,
                     " bytes, the file has ", available, " after the header"));
  if (available > total)
    report.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": ",
                                  available - total, " bytes after the last point were ignored"));
}

raw_geometry read_pcd_file(const std::string& path, read_report& report) {
  const std::string bytes = read_file_bytes(path);
  const pcd_header h = parse_pcd_header(path, bytes);
  const pcd_wanted w = pcd_fields(path, h, report);

  const std::string_view data = std::string_view(bytes).substr(h.data_begin);
  const auto* base = reinterpret_cast<const unsigned char*>(data.data());
  raw_geometry g;
  g.sensor = vec3d::Zero();  // the points are in the sensor's frame (the pose is not applied)
  const std::uint64_t total = pcd_data_bytes(path, h);

  switch (h.data) {
    case pcd_header::data_kind::ascii:
      read_ascii(path, data, h, w, g);
      break;
    case pcd_header::data_kind::binary: {
      pcd_check_binary_size(path, h, data.size(), report);
      gather(g, w, h.points, [&](const pcd_field& f, std::uint64_t i) {
        return base + i * h.point_size + f.offset;
      });
      break;
    }
    case pcd_header::data_kind::compressed: {
      if (data.size() < 8)
        format_error(path, "data", "truncated: expected the compressed and uncompressed sizes");
      const std::uint32_t csize = load_le<std::uint32_t>(base);
      const std::uint32_t usize = load_le<std::uint32_t>(base + 4);
      if (csize > data.size() - 8)
        format_error(path, "data",
                     cat("compressed size ", csize, " runs past the end of the file (",
                         data.size() - 8, " bytes follow)"));
      if (usize != total)
        format_error(path, "data",
                     cat("uncompressed size ", usize, " does not match POINTS × point size = ",
                         h.points, " × ", h.point_size, " = ", total));
      // LZF expands at most ~88:1 (a 3-byte back reference yields 264 bytes); a larger claim
      // is a lie, and must not make us allocate it.
      if (usize > std::uint64_t{csize} * 90 + 64)
        format_error(
            path, "data",
            cat("uncompressed size ", usize, " is impossible for ", csize, " compressed bytes"));
      std::vector<unsigned char> raw(usize);
      if (usize > 0) {
        const unsigned int got = lzf_decompress(base + 8, csize, raw.data(), usize);
        if (got != usize)
          format_error(path, "data",
                       got == 0
                           ? std::string("LZF data is corrupt or decompresses to more than "
                                         "the stated uncompressed size")
                           : cat("LZF data decompressed to ", got, " bytes, expected ", usize));
      }
      // Structure of arrays: field f occupies points × size × count bytes starting at the sum
      // of the earlier fields' blocks.
      std::vector<std::uint64_t> block(h.fields.size());
      for (std::size_t k = 1; k < h.fields.size(); ++k)
        block[k] = block[k - 1] + h.points * h.fields[k - 1].size * h.fields[k - 1].count;
      const pcd_field* first = h.fields.data();
      gather(g, w, h.points, [&](const pcd_field& f, std::uint64_t i) {
        return raw.data() + block[static_cast<std::size_t>(&f - first)] + i * f.size * f.count;
      });
      break;
    }
  }
  return g;
}

}  // namespace pbr_lod::detail
