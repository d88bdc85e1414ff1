// pbr_lod — read_gaussians: the 3DGS PLY and .splat readers, and the bad-value rule they share
// with the .spz reader (spz_reader.cpp). Formats and rules: io/gaussians.hpp.
//
// The PLY goes through the same header parser and row decoders as read_mesh (ply_format.hpp):
// one header grammar, one set of count checks. A binary file whose vertex element (and every
// element before it) has no lists is streamed in blocks of rows, so a 1.5 GB scene is never held
// in memory twice; other files (ASCII, lists) are read whole.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>

#include "gaussian_internal.hpp"
#include "pbr_lod/core/gaussian_source.hpp"
#include "pbr_lod/io/gaussians.hpp"
#include "ply_format.hpp"

namespace pbr_lod::detail {

// --- the bad-value rule -------------------------------------------------------------------------

gaussian_collector::gaussian_collector(const std::string& path, read_report& report, int sh_degree)
    : path_(path), report_(report) {
  c_.sh_degree = sh_degree;
}

void gaussian_collector::reserve(std::size_t n) {
  world_.reserve(n);
  c_.scales.reserve(n);
  c_.rotations.reserve(n);
  c_.opacities.reserve(n);
  c_.sh.reserve(n * c_.sh_stride());
}

double gaussian_collector::opacity_from_logit(double logit) {
  if (std::isinf(logit)) {
    ++report_.values_clamped;
    return logit > 0 ? 1.0 : 0.0;
  }
  return 1.0 / (1.0 + std::exp(-logit));  // NaN stays NaN: add() drops it
}

void gaussian_collector::add(const vec3d& position, const vec3d& scale, const vec4d& wxyz,
                             double opacity, const float* sh) {
  ++total_;
  if (!all_finite(position)) {
    ++bad_position_;
    return;
  }
  vec3f s;
  for (int k = 0; k < 3; ++k) {
    double v = scale[k];
    if (v < 0) {
      v = -v;
      ++report_.values_clamped;
    }
    s[k] = static_cast<float>(v);  // a double beyond FLT_MAX becomes inf: dropped below
  }
  if (!all_finite(s) || std::isnan(opacity)) {
    ++bad_shape_;
    return;
  }
  // Normalise after dividing by the largest component, so huge finite components (a double
  // PLY) cannot overflow the norm.
  vec4f q(1, 0, 0, 0);
  const double big = wxyz.cwiseAbs().maxCoeff();
  if (all_finite(wxyz) && big > 0) {
    const vec4d u = wxyz / big;
    q = (u / u.norm()).cast<float>();
  } else {
    ++report_.rotations_reset;
  }
  if (count_only_) {
    ++kept_;
    box_.add(position);
    for (std::size_t j = 0; j < c_.sh_stride(); ++j)
      report_.values_clamped += !std::isfinite(sh[j]);
    return;
  }
  world_.push_back(position);
  c_.scales.push_back(s);
  c_.rotations.push_back(q);
  c_.opacities.push_back(static_cast<float>(std::clamp(opacity, 0.0, 1.0)));
  const std::size_t m = c_.sh_stride();
  for (std::size_t j = 0; j < m; ++j) {
    if (std::isfinite(sh[j])) {
      c_.sh.push_back(sh[j]);
    } else {
      c_.sh.push_back(0.0f);
      ++report_.values_clamped;
    }
  }
}

gaussian_cloud gaussian_collector::finish(const std::optional<vec3d>& hint) {
  finite_box box;
  for (const vec3d& p : world_) box.add(p);
  const vec3d origin = choose_origin(box, hint, path_, report_);
  gaussian_cloud out = take(origin);
  report_counts();
  return out;
}

vec3d gaussian_collector::finish_counting(const std::optional<vec3d>& hint) {
  const vec3d origin = choose_origin(box_, hint, path_, report_);
  report_counts();
  return origin;
}

gaussian_cloud gaussian_collector::take(const vec3d& origin) {
  c_.origin = origin;
  c_.positions.resize(world_.size());
  for (std::size_t i = 0; i < world_.size(); ++i)
    c_.positions[i] = (world_[i] - origin).cast<float>();
  world_ = {};
  gaussian_cloud out = std::move(c_);
  c_ = gaussian_cloud{};
  c_.sh_degree = out.sh_degree;
  return out;
}

void gaussian_collector::report_counts() {
  report_.points_read = total_;
  report_.dropped_non_finite = bad_position_;
  report_.dropped_bad_gaussians = bad_shape_;
  const std::string name = std::filesystem::path(path_).filename().string();
  const auto warn = [&](std::size_t n, const char* what) {
    if (n > 0) report_.warnings.push_back(cat(name, ": ", n, " ", what));
  };
  warn(bad_position_, "Gaussians with a non-finite position were dropped");
  warn(bad_shape_, "Gaussians with a non-finite scale or a NaN opacity were dropped");
  warn(report_.rotations_reset, "zero or non-finite rotations were set to the identity");
  warn(report_.values_clamped,
       "values were clamped (±inf opacity, non-finite SH coefficients, negative scales)");
}

namespace {

// --- the 3DGS PLY -------------------------------------------------------------------------------

// Where each vertex property goes in the decoded row (`v` below).
constexpr int at_x = 0, at_dc = 3, at_opacity = 6, at_scale = 7, at_rot = 10, at_rest = 14;
constexpr int max_rest = 3 * (sh_coefficients(max_sh_degree) - 1);  // 45
constexpr int row_slots = at_rest + max_rest;                       // 59
constexpr int at_skip = row_slots;                                  // scratch slot
constexpr int slots = row_slots + 1;

}  // namespace

struct gs_plan {
  const element* vertex = nullptr;
  std::vector<int> role;  ///< per vertex property: its slot
  int degree = 0;
};

namespace {

/// "f_rest_17" → 17; nullopt for anything else.
std::optional<int> rest_index(const std::string& n) {
  constexpr std::string_view prefix = "f_rest_";
  if (n.size() <= prefix.size() || n.compare(0, prefix.size(), prefix) != 0) return std::nullopt;
  const std::string_view digits = std::string_view(n).substr(prefix.size());
  if (digits.size() > 1 && digits[0] == '0') return std::nullopt;
  const auto v = parse_number<int>(digits);
  if (!v || *v < 0) return std::nullopt;
  return v;
}

gs_plan plan_gaussian_ply(const std::string& path, const ply_header& h) {
  gs_plan pl;
  for (const element& e : h.elements) {
    if (e.count > 0 && e.props.empty())
      format_error(path, cat("header line ", e.header_line),
                   cat("element ", e.name, " has rows but no properties"));
    if (e.name != "vertex") continue;
    if (pl.vertex != nullptr)
      format_error(path, cat("header line ", e.header_line), "a second 'vertex' element");
    pl.vertex = &e;
  }
  if (pl.vertex == nullptr) format_error(path, "header", "no 'vertex' element");
  const element& e = *pl.vertex;
  const std::string where = cat("header line ", e.header_line);
  static const std::pair<const char*, int> named[] = {{"x", at_x},
                                                      {"y", at_x + 1},
                                                      {"z", at_x + 2},
                                                      {"f_dc_0", at_dc},
                                                      {"f_dc_1", at_dc + 1},
                                                      {"f_dc_2", at_dc + 2},
                                                      {"opacity", at_opacity},
                                                      {"scale_0", at_scale},
                                                      {"scale_1", at_scale + 1},
                                                      {"scale_2", at_scale + 2},
                                                      {"rot_0", at_rot},
                                                      {"rot_1", at_rot + 1},
                                                      {"rot_2", at_rot + 2},
                                                      {"rot_3", at_rot + 3}};
  std::vector<int> seen(row_slots, 0);
  int n_rest = 0;
  for (const property& p : e.props) {
    int role = at_skip;
    for (const auto& [name, slot_of] : named)
      if (p.name == name) role = slot_of;
    if (const auto k = rest_index(p.name)) {
      n_rest = std::max(n_rest, *k + 1);
      role = *k < max_rest ? at_rest + *k : at_skip;
    }
    if (role != at_skip) {
      if (p.is_list) format_error(path, where, cat("vertex property '", p.name, "' is a list"));
      if (seen[role]++ > 0)
        format_error(path, where, cat("vertex property '", p.name, "' appears twice"));
    }
    pl.role.push_back(role);
  }
  for (const auto& [name, slot_of] : named)
    if (seen[slot_of] == 0)
      format_error(path, where,
                   cat("not a 3DGS PLY: element vertex has no property '", name,
                       "' (needs x y z, f_dc_0..2, opacity, scale_0..2, rot_0..3)"));
  if (n_rest == 72)
    format_error(path, where,
                 "72 f_rest_* properties (SH degree 4): degrees above 3 are not "
                 "supported");
  if (n_rest != 0 && n_rest != 9 && n_rest != 24 && n_rest != 45)
    format_error(path, where,
                 cat("f_rest_* up to f_rest_", n_rest - 1,
                     ": the count must be 0, 9, 24 or 45 (SH degree 0–3)"));
  for (int k = 0; k < n_rest; ++k)
    if (seen[at_rest + k] == 0) format_error(path, where, cat("f_rest_", k, " is missing"));
  pl.degree = n_rest == 0 ? 0 : n_rest == 9 ? 1 : n_rest == 24 ? 2 : 3;
  return pl;
}

/// Decodes the vertex rows and feeds the collector.
class gs_ply_parser {
 public:
  gs_ply_parser(const std::string& path, const ply_header& h, const gs_plan& pl,
                gaussian_collector& out)
      : pl_(pl),
        out_(out),
        rows_(path, h.format),
        sh_(static_cast<std::size_t>(sh_coefficients(pl.degree)) * 3) {}

  /// One vertex row from `src` (any element's row for the other elements).
  template <class Src>
  void row(Src& src, const element& e, std::uint64_t r) {
    if (&e != pl_.vertex) {
      double scratch[16];
      rows_.read(src, e, r, scratch);
      return;
    }
    if (!src.begin_row()) rows_.row_error(src, e, r, "the file ends (truncated)");
    for (std::size_t k = 0; k < e.props.size(); ++k) {
      const property& p = e.props[k];
      if (!p.is_list) {
        if (!src.real(p.type, v_[pl_.role[k]])) rows_.row_error(src, e, r, src.truncated_what());
        continue;
      }
      std::int64_t n = 0;
      if (!src.integer(p.count_type, n)) rows_.row_error(src, e, r, src.truncated_what());
      if (n < 0 || !src.list_fits(static_cast<std::uint64_t>(n), p.type))
        rows_.row_error(src, e, r, cat("list ", p.name, " of length ", n, " does not fit"));
      double x = 0;
      for (std::int64_t j = 0; j < n; ++j)
        if (!src.real(p.type, x)) rows_.row_error(src, e, r, src.truncated_what());
    }
    if (!src.end_row())
      rows_.row_error(src, e, r, "more values on the line than the header declares");
    emit();
  }

 private:
  void emit() {
    const int m = sh_coefficients(pl_.degree) - 1;  // non-DC coefficients per channel
    for (int c = 0; c < 3; ++c) {
      sh_[static_cast<std::size_t>(c)] = static_cast<float>(v_[at_dc + c]);
      // f_rest is channel-major: f_rest_{c·m + (k − 1)} is coefficient k of channel c.
      for (int k = 1; k <= m; ++k)
        sh_[static_cast<std::size_t>(k * 3 + c)] = static_cast<float>(v_[at_rest + c * m + k - 1]);
    }
    const vec3d pos(v_[at_x], v_[at_x + 1], v_[at_x + 2]);
    const vec3d scale(std::exp(v_[at_scale]), std::exp(v_[at_scale + 1]),
                      std::exp(v_[at_scale + 2]));
    const vec4d q(v_[at_rot], v_[at_rot + 1], v_[at_rot + 2], v_[at_rot + 3]);
    out_.add(pos, scale, q, out_.opacity_from_logit(v_[at_opacity]), sh_.data());
  }

  const gs_plan& pl_;
  gaussian_collector& out_;
  ply_row_reader rows_;
  std::vector<float> sh_;
  double v_[slots] = {};
};

/// Binary, no lists up to the vertex element: rows have one size, read in blocks from the file.
bool streamable(const ply_header& h, const gs_plan& pl) {
  if (h.format == encoding::ascii) return false;
  for (const element& e : h.elements) {
    for (const property& p : e.props)
      if (p.is_list) return false;
    if (&e == pl.vertex) return true;
  }
  return true;
}

std::uint64_t row_bytes(const element& e) {
  std::uint64_t b = 0;
  for (const property& p : e.props) b += scalar_size(p.type);
  return b;
}

}  // namespace

// --- files of fixed-size rows -------------------------------------------------------------------

gaussian_rows::gaussian_rows(const std::string& path) : path_(path), file_(path) {}
gaussian_rows::~gaussian_rows() = default;

std::unique_ptr<gaussian_rows> gaussian_rows::open(const std::string& path) {
  const std::string ext = lower_extension(path);
  std::unique_ptr<gaussian_rows> r(new gaussian_rows(path));
  if (ext == ".splat") {
    constexpr std::uint64_t record = 32;
    if (r->file_.size() % record != 0)
      format_error(path, "data",
                   cat("size ", r->file_.size(),
                       " bytes is not a multiple of the 32-byte record "
                       "(truncated, or not a .splat file)"));
    r->row_bytes_ = record;
    r->rows_ = r->file_.size() / record;
    return r;
  }
  if (ext != ".ply") return nullptr;
  r->header_ = std::make_unique<ply_header>(
      parse_ply_header(path, read_header_lines(r->file_, "end_header")));
  const ply_header& h = *r->header_;
  r->plan_ = std::make_unique<gs_plan>(plan_gaussian_ply(path, h));
  if (!streamable(h, *r->plan_)) return nullptr;
  // Every element up to the vertex one has fixed-size rows: the vertex rows start after them.
  check_binary_size(path, h, r->file_.size() - h.data_begin);
  r->offset_ = h.data_begin;
  for (const element& e : h.elements) {
    if (&e == r->plan_->vertex) break;
    r->offset_ += e.count * row_bytes(e);  // no overflow: check_binary_size summed these
  }
  r->row_bytes_ = row_bytes(*r->plan_->vertex);
  r->rows_ = r->plan_->vertex->count;
  r->swap_ = (h.format == encoding::binary_be) != (std::endian::native == std::endian::big);
  return r;
}

int gaussian_rows::degree() const {
  return plan_ ? plan_->degree : 0;
}

std::optional<vec3d> gaussian_rows::origin_hint() const {
  return header_ ? header_->origin : std::nullopt;
}

void gaussian_rows::decode(std::uint64_t first, std::uint64_t n, gaussian_collector& out,
                           const std::function<bool(std::uint64_t)>& more) const {
  const std::uint64_t per_block = std::max<std::uint64_t>(1, (std::uint64_t{1} << 20) / row_bytes_);
  std::vector<unsigned char> buf;
  std::optional<gs_ply_parser> parser;
  if (plan_) parser.emplace(path_, *header_, *plan_, out);
  for (std::uint64_t r = first; r < first + n;) {
    const std::uint64_t m = std::min(per_block, first + n - r);
    buf.resize(static_cast<std::size_t>(m * row_bytes_));
    file_.read_exact(offset_ + r * row_bytes_, buf.size(), buf.data());
    binary_source src(buf.data(), buf.data() + buf.size(), swap_);
    for (std::uint64_t k = 0; k < m; ++k, ++r) {
      if (more && !more(r)) return;
      if (parser)
        parser->row(src, *plan_->vertex, r);
      else
        splat_row(buf.data() + k * row_bytes_, out);
    }
  }
}

/// One 32-byte .splat record: float x y z, float linear scales, uint8 RGBA (colour = 0.5 +
/// C0·dc, stored as colour · 255; alpha = opacity), uint8 quaternion w x y z as (b − 128)/128.
void gaussian_rows::splat_row(const unsigned char* p, gaussian_collector& out) {
  const auto fl = [&](int j) { return static_cast<double>(load_le<float>(p + 4 * j)); };
  float sh[3];
  for (int c = 0; c < 3; ++c) sh[c] = static_cast<float>((p[24 + c] / 255.0 - 0.5) / sh_c0);
  const auto quat = [&](int j) { return (p[28 + j] - 128.0) / 128.0; };
  out.add(vec3d(fl(0), fl(1), fl(2)), vec3d(fl(3), fl(4), fl(5)),
          vec4d(quat(0), quat(1), quat(2), quat(3)), p[27] / 255.0, sh);
}

gaussian_cloud read_gaussian_ply(const std::string& path, read_report& report) {
  if (const auto rows = gaussian_rows::open(path)) {
    // A 1.5 GB scene is streamed in blocks of rows, never held in memory twice.
    gaussian_collector out(path, report, rows->degree());
    out.reserve(static_cast<std::size_t>(rows->rows()));
    rows->decode(0, rows->rows(), out);
    return out.finish(rows->origin_hint());
  }
  const posix_file f(path);
  const std::string head = read_header_lines(f, "end_header");
  ply_header h = parse_ply_header(path, head);
  const gs_plan pl = plan_gaussian_ply(path, h);
  gaussian_collector out(path, report, pl.degree);
  gs_ply_parser parser(path, h, pl, out);
  const bool swap = (h.format == encoding::binary_be) != (std::endian::native == std::endian::big);
  const std::string bytes = read_file_bytes(path);
  const std::string_view data = std::string_view(bytes).substr(h.data_begin);
  if (h.format == encoding::ascii) {
    // At least 2 bytes per row ("0\n"): a count the file cannot hold reserves nothing big.
    out.reserve(
        static_cast<std::size_t>(std::min<std::uint64_t>(pl.vertex->count, data.size() / 2)));
    ascii_source src(data, h.first_data_line);
    for (const element& e : h.elements)
      for (std::uint64_t r = 0; r < e.count; ++r) parser.row(src, e, r);
  } else {
    check_binary_size(path, h, data.size());
    out.reserve(static_cast<std::size_t>(pl.vertex->count));
    const auto* b = reinterpret_cast<const unsigned char*>(data.data());
    binary_source src(b, b + data.size(), swap);
    for (const element& e : h.elements)
      for (std::uint64_t r = 0; r < e.count; ++r) parser.row(src, e, r);
  }
  return out.finish(h.origin);
}

// --- .splat -------------------------------------------------------------------------------------

gaussian_cloud read_splat_file(const std::string& path, read_report& report) {
  const auto rows = gaussian_rows::open(path);
  gaussian_collector out(path, report, 0);
  out.reserve(static_cast<std::size_t>(rows->rows()));
  rows->decode(0, rows->rows(), out);
  return out.finish(std::nullopt);
}

}  // namespace pbr_lod::detail

namespace pbr_lod {

bool is_gaussian_file(const std::string& path) {
  const std::string ext = detail::lower_extension(path);
  if (ext == ".splat" || ext == ".spz") return true;
  if (ext != ".ply") return false;
  const detail::posix_file f(path);
  const detail::ply_header h =
      detail::parse_ply_header(path, detail::read_header_lines(f, "end_header"));
  for (const detail::element& e : h.elements) {
    if (e.name != "vertex") continue;
    int found = 0;
    for (const auto& p : e.props)
      for (const char* name : {"f_dc_0", "opacity", "scale_0", "rot_0"})
        if (p.name == name) ++found;
    return found == 4;
  }
  return false;
}

gaussian_cloud read_gaussians(const std::string& path, read_report* report) {
  read_report local;
  read_report& r = report ? *report : local;
  r = read_report{};
  const std::string ext = detail::lower_extension(path);
  if (ext == ".ply") return detail::read_gaussian_ply(path, r);
  if (ext == ".splat") return detail::read_splat_file(path, r);
  if (ext == ".spz") return detail::read_spz_file(path, r);
  detail::format_error(path, "",
                       ext.empty() ? "no file extension; read_gaussians reads .ply, .splat and .spz"
                                   : detail::cat("unsupported extension '", ext,
                                                 "'; read_gaussians reads .ply, .splat and .spz"));
}

namespace {

/// A file of fixed-size rows as a gaussian_source: a first pass applies the bad-value rule to
/// every row (the report, the origin, the rows it drops), then read() decodes just the rows asked
/// for, as read_gaussians would have decoded them.
class file_gaussian_source final : public gaussian_source {
 public:
  file_gaussian_source(std::unique_ptr<detail::gaussian_rows> rows, std::string path,
                       read_report& report)
      : rows_(std::move(rows)), path_(std::move(path)) {
    detail::gaussian_collector c(path_, report, rows_->degree());
    c.count_only();
    std::size_t before = 0;
    const auto kept_last = [&](std::uint64_t r) {  // before row r: was row r − 1 kept?
      if (r > 0 && c.kept() == before) dropped_.push_back(r - 1);
      before = c.kept();
      return true;
    };
    rows_->decode(0, rows_->rows(), c, kept_last);
    kept_last(rows_->rows());
    kept_ = c.kept();
    origin_ = c.finish_counting(rows_->origin_hint());
  }
  [[nodiscard]] int sh_degree() const override { return rows_->degree(); }
  [[nodiscard]] vec3d origin() const override { return origin_; }
  [[nodiscard]] std::uint64_t size() const override { return kept_; }
  void read(std::uint64_t first, std::size_t count, gaussian_cloud& out) const override {
    if (first > kept_ || count > kept_ - first)
      throw InvalidArgument(path_ + ": Gaussians [" + std::to_string(first) + ", " +
                            std::to_string(first + count) + ") beyond its " +
                            std::to_string(kept_));
    // The row of the first Gaussian wanted: each dropped row at or before it pushes it on.
    std::uint64_t r = first;
    for (const std::uint64_t d : dropped_) {
      if (d > r) break;
      ++r;
    }
    read_report scratch;
    detail::gaussian_collector c(path_, scratch, rows_->degree());
    c.reserve(count);
    rows_->decode(r, rows_->rows() - r, c, [&](std::uint64_t) { return c.kept() < count; });
    if (c.kept() != count) throw IoError(path_ + ": the file changed since it was opened");
    out = c.take(origin_);
  }
  [[nodiscard]] std::string name() const override { return path_; }

 private:
  std::unique_ptr<detail::gaussian_rows> rows_;
  std::string path_;
  std::vector<std::uint64_t> dropped_;  // rows the bad-value rule drops, ascending
  std::uint64_t kept_ = 0;
  vec3d origin_ = vec3d::Zero();
};

}  // namespace

std::unique_ptr<gaussian_source> open_gaussian_source(const std::string& path,
                                                      read_report* report) {
  read_report local;
  read_report& r = report ? *report : local;
  r = read_report{};
  const std::string ext = detail::lower_extension(path);
  if (ext == ".ply" || ext == ".splat")
    if (auto rows = detail::gaussian_rows::open(path))
      return std::make_unique<file_gaussian_source>(std::move(rows), path, r);
  return std::make_unique<cloud_gaussian_source>(read_gaussians(path, &r), path);
}

}  // namespace pbr_lod
