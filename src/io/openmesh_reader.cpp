// pbr_lod — OBJ and OFF through OpenMesh, with our own validation around it.
//
// OpenMesh parses; we check. Its readers trust the file: OFF face counts drive loops with no end
// check (a header claiming 4·10⁹ faces loops for minutes, a corner count of 4·10⁹ allocates
// 16 GB), an OBJ vertex line it cannot parse ("nan", "1e39") is skipped silently and shifts
// every later index. So before OpenMesh sees a file we scan its structure (every vertex line,
// every face and each index against the vertex count), and afterwards we compare what OpenMesh
// produced with what the scan counted.
//
// OpenMesh's own TriMesh is not used as the target: it duplicates the vertices of non-manifold
// faces (happy_vrip_res3: +12,840 vertices) to keep its half-edge structure valid. We give the
// reader an importer that collects a triangle soup — vertices exactly as in the file, polygons
// fan-triangulated the way TriMesh does — which is what the builders want.
//
// Precision: OpenMesh's OBJ and OFF readers parse coordinates as float, so OBJ/OFF positions
// carry float precision before the origin is subtracted (use PLY or LAS for georeferenced data).
//
// Thread safety: OpenMesh's reader modules are global objects with per-read state (the OBJ
// reader's material list and folder, the OFF reader's options), so reads are serialised.
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/IO/importer/BaseImporter.hh>
#include <OpenMesh/Core/System/omstream.hh>
#include <algorithm>
#include <filesystem>
#include <map>
#include <mutex>

#include "io_internal.hpp"

namespace pbr_lod::detail {
namespace {

namespace omio = OpenMesh::IO;
using OpenMesh::EdgeHandle;
using OpenMesh::FaceHandle;
using OpenMesh::HalfedgeHandle;
using OpenMesh::VertexHandle;
using StatusInfo = OpenMesh::Attributes::StatusInfo;

std::mutex& openmesh_mutex() {
  static std::mutex m;
  return m;
}

std::string file_name(const std::string& path) {
  return std::filesystem::path(path).filename().string();
}

/// Receives what an OpenMesh reader emits and keeps it as a triangle soup. Errors (an index out
/// of range) are recorded, not thrown: exceptions should not unwind through OpenMesh's frames.
class soup_importer final : public omio::BaseImporter {
 public:
  explicit soup_importer(bool one_based) : one_based_(one_based) {}

  // --- vertices
  VertexHandle add_vertex(const OpenMesh::Vec3f& p) override {
    return add_vertex(OpenMesh::Vec3d(p[0], p[1], p[2]));
  }
  VertexHandle add_vertex(const OpenMesh::Vec3d& p) override {
    positions_.emplace_back(p[0], p[1], p[2]);
    normals_.emplace_back(vec3f::Zero());
    colours_.push_back({});
    has_normal_.push_back(0);
    has_colour_.push_back(0);
    return VertexHandle(static_cast<int>(positions_.size() - 1));
  }
  VertexHandle add_vertex() override { return add_vertex(OpenMesh::Vec3d(0, 0, 0)); }
  void set_point(VertexHandle vh, const OpenMesh::Vec3f& p) override {
    if (valid(vh)) positions_[idx(vh)] = vec3d(p[0], p[1], p[2]);
  }
  void set_normal(VertexHandle vh, const OpenMesh::Vec3f& n) override {
    if (!valid(vh)) return;
    normals_[idx(vh)] = vec3f(n[0], n[1], n[2]);
    has_normal_[idx(vh)] = 1;
  }
  void set_normal(VertexHandle vh, const OpenMesh::Vec3d& n) override {
    set_normal(vh, OpenMesh::Vec3f(static_cast<float>(n[0]), static_cast<float>(n[1]),
                                   static_cast<float>(n[2])));
  }
  void set_color(VertexHandle vh, const OpenMesh::Vec3uc& c) override {
    if (!valid(vh)) return;
    colours_[idx(vh)] = {c[0], c[1], c[2]};
    has_colour_[idx(vh)] = 1;
  }
  void set_color(VertexHandle vh, const OpenMesh::Vec4uc& c) override {
    set_color(vh, OpenMesh::Vec3uc(c[0], c[1], c[2]));
  }
  void set_color(VertexHandle vh, const OpenMesh::Vec3f& c) override {
    set_color(vh, OpenMesh::Vec3uc(unit_to_u8(c[0]), unit_to_u8(c[1]), unit_to_u8(c[2])));
  }
  void set_color(VertexHandle vh, const OpenMesh::Vec4f& c) override {
    set_color(vh, OpenMesh::Vec3uc(unit_to_u8(c[0]), unit_to_u8(c[1]), unit_to_u8(c[2])));
  }

  // --- faces
  FaceHandle add_face(const VHandles& ids) override {
    ++polygons_;
    last_first_ = -1;
    if (!error_.empty()) return FaceHandle();
    for (const VertexHandle& v : ids)
      if (!valid(v)) {
        error_ = cat("face ", polygons_ - 1, ": vertex index ", v.idx() + (one_based_ ? 1 : 0),
                     " is out of range: the file has ", positions_.size(), " vertices");
        return FaceHandle();
      }
    const std::size_t n = ids.size();
    // Sorted copy, not pairwise comparison: one face may have a million corners.
    sorted_.resize(n);
    std::transform(ids.begin(), ids.end(), sorted_.begin(), [](VertexHandle v) { return v.idx(); });
    std::sort(sorted_.begin(), sorted_.end());
    if (n < 3 || std::adjacent_find(sorted_.begin(), sorted_.end()) != sorted_.end()) {
      ++degenerate_;
      degenerate_triangles_ += n < 3 ? 1 : n - 2;  // read_report counts triangles
      return FaceHandle();
    }
    last_first_ = static_cast<int>(faces_.size());
    last_size_ = n;
    for (std::size_t k = 1; k + 1 < n; ++k) {  // a fan, as OpenMesh's TriMesh splits polygons
      faces_.push_back({idx(ids[0]), idx(ids[k]), idx(ids[k + 1])});
      texcoords_.push_back({vec2f::Zero(), vec2f::Zero(), vec2f::Zero()});
      has_texcoords_.push_back(0);
      texindex_.push_back(0);
    }
    return FaceHandle(last_first_);
  }
  FaceHandle add_face(HalfedgeHandle) override { return FaceHandle(); }
  void add_face_texcoords(FaceHandle fh, VertexHandle,
                          const std::vector<OpenMesh::Vec2f>& tc) override {
    if (tc.empty()) return;
    if (fh.idx() != last_first_ || last_first_ < 0 || tc.size() != last_size_) {
      ++texcoord_mismatch_;
      return;
    }
    const auto corner = [&](std::size_t k) { return vec2f(tc[k][0], tc[k][1]); };
    for (std::size_t k = 1; k + 1 < last_size_; ++k) {
      const std::size_t t = static_cast<std::size_t>(last_first_) + k - 1;
      texcoords_[t] = {corner(0), corner(k), corner(k + 1)};
      has_texcoords_[t] = 1;
    }
  }
  void add_face_texcoords(FaceHandle, VertexHandle, const std::vector<OpenMesh::Vec3f>&) override {}
  void set_face_texindex(FaceHandle fh, int id) override {
    if (fh.idx() >= 0 && static_cast<std::size_t>(fh.idx()) < texindex_.size())
      texindex_[static_cast<std::size_t>(fh.idx())] = id;
  }
  void add_texture_information(int id, std::string name) override { textures_[id] = name; }

  // --- what a triangle soup has no use for
  HalfedgeHandle add_edge(VertexHandle, VertexHandle) override { return HalfedgeHandle(); }
  void set_halfedge(VertexHandle, HalfedgeHandle) override {}
  void set_texcoord(VertexHandle, const OpenMesh::Vec2f&) override {}
  void set_texcoord(HalfedgeHandle, const OpenMesh::Vec2f&) override {}
  void set_texcoord(VertexHandle, const OpenMesh::Vec3f&) override {}
  void set_texcoord(HalfedgeHandle, const OpenMesh::Vec3f&) override {}
  void set_status(VertexHandle, const StatusInfo&) override {}
  void set_status(HalfedgeHandle, const StatusInfo&) override {}
  void set_status(EdgeHandle, const StatusInfo&) override {}
  void set_status(FaceHandle, const StatusInfo&) override {}
  void set_next(HalfedgeHandle, HalfedgeHandle) override {}
  void set_face(HalfedgeHandle, FaceHandle) override {}
  void request_face_texcoords2D() override {}
  void set_color(EdgeHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(EdgeHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(EdgeHandle, const OpenMesh::Vec3f&) override {}
  void set_color(EdgeHandle, const OpenMesh::Vec4f&) override {}
  void set_normal(FaceHandle, const OpenMesh::Vec3f&) override {}
  void set_normal(FaceHandle, const OpenMesh::Vec3d&) override {}
  void set_color(FaceHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(FaceHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(FaceHandle, const OpenMesh::Vec3f&) override {}
  void set_color(FaceHandle, const OpenMesh::Vec4f&) override {}
  bool is_triangle_mesh() const override { return true; }
  // A hostile count must not make us reserve; the pre-scan bounds everything anyway.
  void reserve(unsigned int, unsigned int, unsigned int) override {}

  std::size_t n_vertices() const override { return positions_.size(); }
  std::size_t n_faces() const override { return faces_.size(); }
  std::size_t n_edges() const override { return 0; }

  [[nodiscard]] const std::string& error() const { return error_; }
  [[nodiscard]] std::size_t polygons() const { return polygons_; }

  /// Moves the collected data out; `dir` resolves texture names, `name` prefixes warnings.
  raw_geometry take(const std::string& dir, const std::string& name, read_report& report) {
    raw_geometry g;
    const std::size_t nv = positions_.size(), nf = faces_.size();
    const auto count = [](const std::vector<char>& v) {
      return static_cast<std::size_t>(std::count(v.begin(), v.end(), 1));
    };
    const std::size_t with_normal = count(has_normal_), with_colour = count(has_colour_),
                      with_tc = count(has_texcoords_);
    g.positions = std::move(positions_);
    if (with_normal > 0) {
      g.normals = std::move(normals_);
      if (with_normal < nv)
        report.warnings.push_back(
            cat(name, ": ", nv - with_normal, " vertices have no normal (set to zero)"));
    }
    if (with_colour > 0) {
      g.colours = std::move(colours_);
      if (with_colour < nv)
        report.warnings.push_back(
            cat(name, ": ", nv - with_colour, " vertices have no colour (set to black)"));
    }
    g.faces = std::move(faces_);
    if (with_tc > 0) {
      g.face_texcoords = std::move(texcoords_);
      if (with_tc < nf)
        report.warnings.push_back(cat(name, ": ", nf - with_tc,
                                      " triangles have no texture coordinates (set to (0, 0))"));
    }
    if (texcoord_mismatch_ > 0)
      report.warnings.push_back(cat(name, ": ", texcoord_mismatch_,
                                    " faces have texture coordinates that do not match their "
                                    "vertices and were ignored"));
    if (degenerate_ > 0) {
      report.faces_dropped += degenerate_triangles_;
      report.warnings.push_back(cat(name, ": dropped ", degenerate_,
                                    " degenerate faces (fewer than 3 vertices or a repeated "
                                    "vertex)"));
    }
    g.texture_path = pick_texture(dir, name, report);
    return g;
  }

 private:
  bool valid(VertexHandle v) const {
    return v.idx() >= 0 && static_cast<std::size_t>(v.idx()) < positions_.size();
  }
  static std::uint32_t idx(VertexHandle v) { return static_cast<std::uint32_t>(v.idx()); }

  // triangle_mesh has one texture: the one most faces use (else the only one defined).
  std::string pick_texture(const std::string& dir, const std::string& name,
                           read_report& report) const {
    if (textures_.empty()) return {};
    std::map<int, std::size_t> uses;
    for (const int t : texindex_)
      if (t > 0 && textures_.count(t)) ++uses[t];
    int chosen = textures_.begin()->first;
    if (!uses.empty()) {
      chosen = std::max_element(uses.begin(), uses.end(), [](const auto& a, const auto& b) {
                 return a.second < b.second;
               })->first;
      if (uses.size() > 1)
        report.warnings.push_back(cat(name, ": faces use ", uses.size(),
                                      " textures; only the most used one, ", textures_.at(chosen),
                                      ", is kept"));
    } else if (textures_.size() > 1) {
      report.warnings.push_back(cat(name, ": ", textures_.size(),
                                    " textures are defined but no face selects one; keeping ",
                                    textures_.at(chosen)));
    }
    std::filesystem::path p(textures_.at(chosen));
    if (p.is_relative()) p = std::filesystem::path(dir) / p;
    p = p.lexically_normal();
    std::error_code ec;
    if (!std::filesystem::exists(p, ec))
      report.warnings.push_back(cat(name, ": texture image ", p.string(), " does not exist"));
    return p.string();
  }

  bool one_based_;
  std::vector<vec3d> positions_;
  std::vector<vec3f> normals_;
  std::vector<rgb8> colours_;
  std::vector<char> has_normal_, has_colour_;
  std::vector<std::array<std::uint32_t, 3>> faces_;
  std::vector<std::array<vec2f, 3>> texcoords_;
  std::vector<char> has_texcoords_;
  std::vector<int> texindex_;
  std::map<int, std::string> textures_;
  int last_first_ = -1;
  std::size_t last_size_ = 0;
  std::size_t polygons_ = 0, degenerate_ = 0, degenerate_triangles_ = 0, texcoord_mismatch_ = 0;
  std::vector<int> sorted_;
  std::string error_;
};

/// Runs OpenMesh's reader for `path` into `imp`, asking for normals, colours and per-corner
/// texture coordinates (without the flags OpenMesh's readers skip those values).
void run_openmesh(const std::string& path, soup_importer& imp) {
  omio::Options opt =
      omio::Options::VertexNormal | omio::Options::VertexColor | omio::Options::FaceTexCoord;
  bool ok = false;
  {
    // OpenMesh writes its complaints (a missing material file, a bad texture index) to omerr;
    // the reader reports through read_report and exceptions instead, so a library call prints
    // nothing.
    const std::lock_guard<std::mutex> lock(openmesh_mutex());
    const bool err_on = ::omerr().is_enabled(), log_on = ::omlog().is_enabled();
    ::omerr().disable();
    ::omlog().disable();
    ok = omio::IOManager().read(path, imp, opt);
    if (err_on) ::omerr().enable();
    if (log_on) ::omlog().enable();
  }
  if (!imp.error().empty()) format_error(path, "", imp.error());
  if (!ok) format_error(path, "", "OpenMesh's reader rejected the file");
}

// --- OBJ ----------------------------------------------------------------------------------------

constexpr std::size_t max_obj_corners = 10000;

/// Whitespace as OpenMesh's OBJ reader sees it: it splits with `istream >>`, i.e. the C locale's
/// isspace, which includes '\v' and '\f'. The scan must split the same way, or a line such as
/// "f\v…" is an unknown keyword to the scan and a face to OpenMesh, which then asserts on it
/// (found by fuzz_obj).
bool obj_space(char c) {
  return c == ' ' || c == '\t' || c == '\n' || c == '\v' || c == '\f' || c == '\r';
}

/// Splits on obj_space into `out` (cleared first).
void split_obj(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && obj_space(line[i])) ++i;
    const std::size_t b = i;
    while (i < line.size() && !obj_space(line[i])) ++i;
    if (i > b) out.push_back(line.substr(b, i - b));
  }
}

struct obj_scan {
  std::size_t v = 0, vt = 0, vn = 0, f = 0;
  std::vector<std::string> mtllibs;
};

/// One pass over the OBJ the way OpenMesh reads it (trimmed lines, '#' comments, keyword first):
/// every v/vt/vn line must hold numbers OpenMesh can parse, every face index must be in range.
obj_scan scan_obj(const std::string& path, std::string_view text) {
  obj_scan s;
  std::vector<std::string_view> tok;
  // First pass: counts, so face indices can be checked against vertices defined later (OpenMesh
  // reads all vertices before any face).
  std::size_t total_v = 0, total_vt = 0, total_vn = 0;
  for (int pass = 0; pass < 2; ++pass) {
    std::size_t pos = 0, line_no = 0;
    while (pos < text.size()) {
      std::size_t nl = text.find('\n', pos);
      if (nl == std::string_view::npos) nl = text.size();
      const std::string_view line = trim(text.substr(pos, nl - pos));
      pos = nl + 1;
      ++line_no;
      split_obj(line, tok);
      if (tok.empty() || tok[0][0] == '#') continue;
      const std::string_view kw = tok[0];
      if (pass == 0) {
        total_v += kw == "v";
        total_vt += kw == "vt";
        total_vn += kw == "vn";
        continue;
      }
      const auto where = [&](const char* what, std::size_t i) {
        return cat("line ", line_no, " (", what, " ", i, ")");
      };
      const auto numbers = [&](std::size_t need, const char* what, std::size_t i) {
        if (tok.size() < need + 1)
          format_error(path, where(what, i), cat("expected ", need, " numbers"));
        for (std::size_t k = 1; k <= need; ++k) {
          const auto x = parse_number<float>(tok[k]);
          if (!x || !std::isfinite(*x))
            format_error(path, where(what, i),
                         cat("'", tok[k], "' is not a finite number (float range)"));
        }
      };
      if (kw == "v") {
        numbers(3, "vertex", s.v++);
      } else if (kw == "vt") {
        numbers(2, "texture coordinate", s.vt++);
      } else if (kw == "vn") {
        numbers(3, "normal", s.vn++);
      } else if (kw == "f") {
        const std::size_t face = s.f++;
        if (tok.size() < 2) format_error(path, where("face", face), "a face without vertices");
        // OpenMesh removes repeated corners with a quadratic loop: a face with 10⁶ corners
        // would take minutes. Real OBJ polygons have a handful.
        if (tok.size() - 1 > max_obj_corners)
          format_error(path, where("face", face),
                       cat(tok.size() - 1, " corners; faces with more than ", max_obj_corners,
                           " are not supported (OpenMesh's OBJ reader is quadratic in them)"));
        for (std::size_t k = 1; k < tok.size(); ++k) {
          // v, v/t, v//n or v/t/n; each part an index counted from 1, or from the end if < 0.
          std::string_view rest = tok[k];
          const std::size_t counts_so_far[3] = {s.v, s.vt, s.vn};
          const std::size_t totals[3] = {total_v, total_vt, total_vn};
          const char* names[3] = {"vertex", "texture coordinate", "normal"};
          for (int part = 0; part < 3 && !rest.empty(); ++part) {
            const std::size_t slash = rest.find('/');
            const std::string_view item = rest.substr(0, slash);
            rest = slash == std::string_view::npos ? std::string_view() : rest.substr(slash + 1);
            if (item.empty() && part > 0) continue;
            const auto i = parse_number<std::int64_t>(item);
            if (!i || *i == 0)
              format_error(path, where("face", face),
                           cat("'", tok[k], "' is not a valid vertex reference"));
            const std::int64_t limit =
                static_cast<std::int64_t>(*i > 0 ? totals[part] : counts_so_far[part]);
            if ((*i > 0 && *i > limit) || (*i < 0 && -*i > limit))
              format_error(path, where("face", face),
                           cat(names[part], " index ", *i,
                               " is out of range: ", *i > 0 ? "the file has " : "only ", limit, " ",
                               names[part], "s", *i > 0 ? "" : " precede it"));
          }
        }
      } else if (kw == "mtllib" && tok.size() >= 2) {
        s.mtllibs.emplace_back(trim(line.substr(6)));
      }
    }
  }
  return s;
}

}  // namespace

raw_geometry read_obj_file(const std::string& path, read_report& report) {
  const std::string text = read_file_bytes(path);
  if (text.empty()) format_error(path, "", "the file is empty");
  const obj_scan s = scan_obj(path, text);
  const std::string name = file_name(path);
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  // OpenMesh opens every material library itself, at its directory prefix + the name as written
  // ("../../dev/zero" included) and reads it to the end: a device or a FIFO would never end.
  // So only regular files may be named; a missing one is a warning (OpenMesh skips it).
  const std::size_t slash = path.find_last_of("\\/");
  const std::string prefix = slash == std::string::npos ? "./" : path.substr(0, slash + 1);
  for (const std::string& lib : s.mtllibs) {
    std::error_code ec;
    const auto st = std::filesystem::status(prefix + lib, ec);
    if (!std::filesystem::exists(st))
      report.warnings.push_back(cat(name, ": material library ", prefix + lib, " does not exist"));
    else if (!std::filesystem::is_regular_file(st))
      format_error(path, "mtllib",
                   cat("the material library ", prefix + lib,
                       " is not a regular file (a device, a pipe or a folder)"));
  }

  soup_importer imp(/*one_based=*/true);
  run_openmesh(path, imp);
  if (imp.n_vertices() != s.v)
    format_error(path, "",
                 cat("OpenMesh read ", imp.n_vertices(), " vertices, the file has ", s.v));
  if (imp.polygons() < s.f) {
    // OpenMesh skips faces with fewer than 3 distinct vertices before they reach the importer.
    const std::size_t skipped = s.f - imp.polygons();
    report.faces_dropped += skipped;
    report.warnings.push_back(
        cat(name, ": dropped ", skipped, " faces with fewer than 3 distinct vertices"));
  }
  return imp.take(dir.string(), name, report);
}

// --- OFF ----------------------------------------------------------------------------------------

namespace {

struct off_layout {
  bool binary = false, normals = false, colours = false, texcoords = false;
  std::size_t header_end = 0;  ///< byte after the first line
};

off_layout parse_off_keyword(const std::string& path, std::string_view text) {
  off_layout L;
  const std::size_t nl = text.find('\n');
  if (nl == std::string_view::npos) format_error(path, "line 1", "expected an OFF header line");
  L.header_end = nl + 1;
  std::vector<std::string_view> tok;
  split_ws(text.substr(0, nl), tok);
  if (tok.empty()) format_error(path, "line 1", "expected 'OFF'");
  std::string_view kw = tok[0];
  const auto eat = [&](std::string_view pre) {
    if (kw.substr(0, pre.size()) != pre) return false;
    kw.remove_prefix(pre.size());
    return true;
  };
  L.texcoords = eat("ST");
  L.colours = eat("C");
  L.normals = eat("N");
  if (kw == "4OFF" || kw == "nOFF" || kw == "4nOFF")
    format_error(path, "line 1", "4D and nD OFF files are not supported");
  if (kw != "OFF")
    format_error(path, "line 1", cat("expected the magic '[ST][C][N]OFF', found '", tok[0], "'"));
  if (tok.size() == 2 && tok[1] == "BINARY")
    L.binary = true;
  else if (tok.size() > 1)
    format_error(path, "line 1",
                 "expected the counts on the next line (OpenMesh reads them from line 2)");
  if (L.binary && (L.texcoords || L.colours || L.normals))
    format_error(path, "line 1",
                 "binary OFF with colours, normals or texture coordinates is not "
                 "supported");
  return L;
}

/// Returns {vertices, faces}; throws on anything OpenMesh would misread.
std::pair<std::size_t, std::size_t> scan_off_ascii(const std::string& path, std::string_view text,
                                                   const off_layout& L) {
  std::vector<std::string_view> tok;
  std::size_t pos = L.header_end, line_no = 1;
  // Next non-empty line split into tok; false at the end of the file.
  const auto next = [&]() {
    while (pos < text.size()) {
      std::size_t nl = text.find('\n', pos);
      if (nl == std::string_view::npos) nl = text.size();
      const std::string_view line = text.substr(pos, nl - pos);
      pos = nl + 1;
      ++line_no;
      if (split_ws(line, tok) == 0) continue;
      if (tok[0].front() == '#')
        format_error(path, cat("line ", line_no),
                     "comments after the first line are not supported (OpenMesh's OFF reader "
                     "cannot skip them)");
      return true;
    }
    return false;
  };
  // Exactly three: OpenMesh reads the counts as tokens, so a fourth value on the line would be
  // read as the next count, shifting every later one (fuzz_off: "0 5 4 6" made it take a
  // trailing number as a face's corner count and allocate gigabytes).
  if (!next() || tok.size() != 3)
    format_error(path, cat("line ", line_no), "expected exactly '<vertices> <faces> <edges>'");
  const auto nv = parse_number<std::uint32_t>(tok[0]);
  const auto nf = parse_number<std::uint32_t>(tok[1]);
  if (!nv || !nf || !parse_number<std::uint64_t>(tok[2]))
    format_error(path, cat("line ", line_no),
                 "expected three non-negative integers '<vertices> <faces> <edges>'");
  const std::size_t need = 3 + (L.normals ? 3 : 0) + (L.texcoords ? 2 : 0);
  for (std::size_t v = 0; v < *nv; ++v) {
    if (!next())
      format_error(path, cat("vertex ", v),
                   cat("the file ends (truncated: the header promises ", *nv, " vertices)"));
    const std::string where = cat("vertex ", v, " (line ", line_no, ")");
    if (tok.size() < need) format_error(path, where, cat("expected at least ", need, " numbers"));
    for (std::size_t k = 0; k < 3 + (L.normals ? 3u : 0u); ++k) {
      const auto x = parse_number<float>(tok[k]);
      if (!x || !std::isfinite(*x))
        format_error(path, where, cat("'", tok[k], "' is not a finite number (float range)"));
    }
  }
  for (std::size_t f = 0; f < *nf; ++f) {
    if (!next())
      format_error(path, cat("face ", f),
                   cat("the file ends (truncated: the header promises ", *nf, " faces)"));
    const std::string where = cat("face ", f, " (line ", line_no, ")");
    const auto n = parse_number<std::uint32_t>(tok[0]);
    if (!n) format_error(path, where, cat("'", tok[0], "' is not a vertex count"));
    // Without colours OpenMesh reads faces as a token stream: extra values would be taken as the
    // next face, so the line must hold exactly the count and the indices.
    if (tok.size() - 1 < *n || (!L.colours && tok.size() - 1 != *n))
      format_error(path, where,
                   cat("expected ", *n, " vertex indices, found ", tok.size() - 1, " values"));
    for (std::size_t k = 1; k <= *n; ++k) {
      const auto i = parse_number<std::int64_t>(tok[k]);
      if (!i || *i < 0 || static_cast<std::uint64_t>(*i) >= *nv)
        format_error(
            path, where,
            cat("vertex index ", tok[k], " is out of range: the file has ", *nv, " vertices"));
    }
  }
  return {*nv, *nf};
}

std::pair<std::size_t, std::size_t> scan_off_binary(const std::string& path, std::string_view text,
                                                    const off_layout& L) {
  const auto* p = reinterpret_cast<const unsigned char*>(text.data()) + L.header_end;
  const auto* end = reinterpret_cast<const unsigned char*>(text.data()) + text.size();
  const auto left = [&]() { return static_cast<std::uint64_t>(end - p); };
  if (left() < 12) format_error(path, "header", "truncated: expected three 32-bit counts");
  const std::uint32_t nv = load_le<std::uint32_t>(p), nf = load_le<std::uint32_t>(p + 4);
  p += 12;
  if (left() < std::uint64_t{nv} * 12)
    format_error(path, "vertices",
                 cat("truncated: ", nv, " vertices need ", std::uint64_t{nv} * 12,
                     " bytes, the file has ", left()));
  for (std::uint64_t i = 0; i < std::uint64_t{nv} * 3; ++i, p += 4)
    if (!std::isfinite(load_le<float>(p)))
      format_error(path, cat("vertex ", i / 3), "a coordinate is not finite");
  for (std::uint32_t f = 0; f < nf; ++f) {
    if (left() < 4) format_error(path, cat("face ", f), "the file ends (truncated)");
    const std::uint32_t n = load_le<std::uint32_t>(p);
    p += 4;
    if (left() < std::uint64_t{n} * 4)
      format_error(path, cat("face ", f), cat(n, " vertex indices run past the end of the file"));
    for (std::uint32_t k = 0; k < n; ++k, p += 4)
      if (load_le<std::uint32_t>(p) >= nv)
        format_error(path, cat("face ", f),
                     cat("vertex index ", load_le<std::uint32_t>(p),
                         " is out of range: the file has ", nv, " vertices"));
  }
  return {nv, nf};
}

}  // namespace

raw_geometry read_off_file(const std::string& path, read_report& report) {
  const std::string text = read_file_bytes(path);
  if (text.empty()) format_error(path, "", "the file is empty");
  const off_layout L = parse_off_keyword(path, text);
  const auto [nv, nf] = L.binary ? scan_off_binary(path, text, L) : scan_off_ascii(path, text, L);

  soup_importer imp(/*one_based=*/false);
  run_openmesh(path, imp);
  if (imp.n_vertices() != nv || imp.polygons() != nf)
    format_error(path, "",
                 cat("OpenMesh read ", imp.n_vertices(), " vertices and ", imp.polygons(),
                     " faces, the header promises ", nv, " and ", nf));
  return imp.take(std::filesystem::path(path).parent_path().string(), file_name(path), report);
}

}  // namespace pbr_lod::detail
