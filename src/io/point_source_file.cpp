// pbr_lod — point files read in blocks (see include/pbr_lod/io/point_source_file.hpp).
//
// One class template, file_point_source<Codec>, does the streaming: the pass at open (box,
// finite count, index), the positioned block reads, and finish_mesh's per-point rules
// (choose_origin, normal_rule from common.cpp). A codec knows one format's layout and decodes
// one record with the same functions read_points uses (ply_format.hpp, point_formats.hpp). Two
// kinds of codec:
//  * fixed-size records (binary PLY, LAS, binary PCD): record i is at data_begin + i·record_size;
//  * lines (ASCII PLY and PCD): one record per non-empty line, found by reading on from a line
//    whose byte offset the index recorded.
#include "pbr_lod/io/point_source_file.hpp"

#include <algorithm>
#include <filesystem>
#include <mutex>

#include "io_internal.hpp"
#include "laz_decoder.hpp"
#include "ply_format.hpp"
#include "point_formats.hpp"

namespace pbr_lod {
namespace detail {
namespace {

/// An index entry every 2^run_bits kept points.
constexpr unsigned run_bits = 16;
/// The most bytes one positioned read asks for.
constexpr std::size_t block_bytes = std::size_t{4} << 20;

/// Where a record starts: its number, and for line formats its byte offset and line number.
struct record_at {
  std::uint64_t record = 0;
  std::uint64_t offset = 0;
  std::uint64_t line = 0;
};

/// A record as stored, before finish_mesh's rules.
struct raw_point {
  vec3d position;
  vec3f normal = vec3f::Zero();
  rgb8 colour{};
  std::uint16_t colour_top = 0;  ///< LAS: the largest 16-bit channel (decides the colour shift)
};

bool blank(std::string_view s) {
  return std::all_of(s.begin(), s.end(), [](char c) { return c == ' ' || c == '\t' || c == '\r'; });
}

/// The non-empty lines of a file from a given offset, read in growing blocks.
class line_cursor {
 public:
  /// Starts at byte `offset`, which begins line number `line` + 1.
  line_cursor(const posix_file& f, std::uint64_t offset, std::uint64_t line)
      : f_(f), buf_offset_(offset), line_(line) {}

  /// The next non-empty line (without its '\n'), its byte offset and line number; false at the
  /// end of the file. The view is valid until the next call.
  bool next(std::string_view& out, record_at& at) {
    for (;;) {
      const std::size_t nl = buf_.find('\n', pos_);
      if (nl == std::string::npos && !eof_) {
        refill();
        continue;
      }
      if (pos_ >= buf_.size()) return false;
      const std::size_t end = nl == std::string::npos ? buf_.size() : nl;
      const std::string_view line(buf_.data() + pos_, end - pos_);
      at.offset = buf_offset_ + pos_;
      at.line = ++line_;
      pos_ = end + 1;
      if (!blank(line)) {
        out = line;
        return true;
      }
    }
  }

 private:
  void refill() {
    buf_.erase(0, std::min(pos_, buf_.size()));
    buf_offset_ += pos_;
    pos_ = 0;
    // Small first reads (a read of a few points), then up to block_bytes; a line longer than
    // the buffer grows it.
    const std::size_t want = std::max(chunk_, buf_.size());
    chunk_ = std::min(chunk_ * 2, block_bytes);
    const std::size_t have = buf_.size();
    buf_.resize(have + want);
    const std::size_t got = f_.read_some(buf_offset_ + have, want, buf_.data() + have);
    buf_.resize(have + got);
    if (got < want) eof_ = true;
  }

  const posix_file& f_;
  std::string buf_;
  std::size_t pos_ = 0;
  std::uint64_t buf_offset_;
  std::uint64_t line_;
  std::size_t chunk_ = std::size_t{64} << 10;
  bool eof_ = false;
};

// --- codecs -----------------------------------------------------------------------------------
// Fixed:  static constexpr bool line_based = false; data_begin, record_size, records;
//         raw_point decode(const unsigned char* rec, std::uint64_t i, scratch&) const;
//         optionally read_records(file, first, n, out) when records are not stored as they are
//         (LAZ), else they are read at data_begin + first · record_size.
// Lines:  static constexpr bool line_based = true; records;
//         record_at start(const posix_file&) (the first record's line; FormatError when the file
//         ends first), raw_point decode(std::string_view line, i, line_no, scratch&) const,
//         [[noreturn]] truncated(std::uint64_t records_seen) (the file ends before them all),
//         after(const posix_file&, last record's record_at or the start) (lines beyond).
// Both:   observe(const raw_point&) during the pass at open, scanned(report) after it.

struct no_scratch {};

/// Binary PLY: fixed rows decoded by ply_row_reader.
struct ply_binary_codec {
  static constexpr bool line_based = false;
  using scratch = ply_row_reader;
  std::string path;
  ply_header h;
  std::size_t vertex = 0;  ///< index of the vertex element in h.elements
  bool swap = false;
  std::uint64_t data_begin = 0, record_size = 0, records = 0;

  [[nodiscard]] scratch make_scratch() const { return {path, h.format}; }
  raw_point decode(const unsigned char* rec, std::uint64_t i, scratch& rows) const {
    binary_source src(rec, rec + record_size, swap);
    double v[16];
    rows.read(src, h.elements[vertex], i, v);
    const ply_vertex q = make_ply_vertex(v);
    return {q.position, q.normal, q.colour};
  }
  void observe(const raw_point&) {}
  void scanned(read_report&) const {}
};

/// ASCII PLY: one vertex per non-empty line after the rows of the elements before it.
struct ply_ascii_codec {
  static constexpr bool line_based = true;
  struct scratch {
    ply_row_reader rows;
    ascii_source src;
  };
  std::string path;
  ply_header h;
  std::size_t vertex = 0;
  std::uint64_t records = 0;
  std::uint64_t rows_before = 0;  ///< rows of the elements before the vertex element
  std::uint64_t rows_total = 0;   ///< rows of all elements (= non-empty lines needed)

  [[nodiscard]] scratch make_scratch() const {
    return {ply_row_reader(path, h.format), ascii_source({}, 1)};
  }
  record_at start(const posix_file& f) const {
    line_cursor cur(f, h.data_begin, h.first_data_line - 1);
    std::string_view line;
    record_at at;
    for (std::uint64_t r = 0; r < rows_before; ++r)
      if (!cur.next(line, at)) ascii_truncated(path, h, rows_total, r);
    if (!cur.next(line, at)) {
      if (records > 0 || rows_before < rows_total)
        ascii_truncated(path, h, rows_total, rows_before);
      return {0, f.size(), at.line + 1};
    }
    at.record = 0;
    return at;
  }
  raw_point decode(std::string_view line, std::uint64_t i, std::uint64_t line_no,
                   scratch& s) const {
    s.src.reset(line, line_no);
    double v[16];
    s.rows.read(s.src, h.elements[vertex], i, v);
    const ply_vertex q = make_ply_vertex(v);
    return {q.position, q.normal, q.colour};
  }
  [[noreturn]] void truncated(std::uint64_t seen) const {
    ascii_truncated(path, h, rows_total, rows_before + seen);
  }
  /// The lines after the vertices: as many as the other elements need (FormatError otherwise,
  /// as read_points), and a warning for more.
  void after(const posix_file& f, const record_at& last, read_report& report) const {
    line_cursor cur(f, last.offset, last.line - 1);
    std::string_view line;
    record_at at;
    std::uint64_t lines = rows_before + records;
    if (records > 0) cur.next(line, at);  // the last vertex itself
    while (cur.next(line, at)) ++lines;
    if (lines < rows_total) ascii_truncated(path, h, rows_total, lines);
    if (lines > rows_total)
      report.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": ",
                                    lines - rows_total,
                                    " non-empty lines after the last element were ignored"));
  }
  void observe(const raw_point&) {}
  void scanned(read_report&) const {}
};

struct las_codec {
  static constexpr bool line_based = false;
  using scratch = no_scratch;
  std::string path;
  las_header h;
  std::shared_ptr<const laz_record_reader> laz;  ///< LAZ: decodes the records by chunk
  std::uint64_t data_begin = 0, record_size = 0, records = 0;
  int shift = 0;  ///< set once the pass at open has seen every colour
  std::uint16_t top = 0;
  std::uint64_t outside = 0;

  [[nodiscard]] scratch make_scratch() const { return {}; }
  void read_records(const posix_file& f, std::uint64_t first, std::uint64_t n,
                    unsigned char* out) const {
    if (laz)
      laz->read(first, n, out);
    else
      f.read_exact(data_begin + first * record_size, static_cast<std::size_t>(n * record_size),
                   out);
  }
  raw_point decode(const unsigned char* rec, std::uint64_t, scratch&) const {
    raw_point q{h.position(rec)};
    if (h.rgb_offset != 0) {
      const auto c = h.rgb16(rec);
      q.colour = las_header::colour(c, shift);
      q.colour_top = std::max({c[0], c[1], c[2]});
    }
    return q;
  }
  void observe(const raw_point& q) {
    top = std::max(top, q.colour_top);
    if (h.outside(q.position)) ++outside;
  }
  void scanned(read_report& report) {
    shift = las_header::colour_shift(top);
    las_outside_warning(path, outside, report);
  }
};

struct pcd_binary_codec {
  static constexpr bool line_based = false;
  using scratch = no_scratch;
  pcd_header h;
  pcd_wanted w;
  std::uint64_t data_begin = 0, record_size = 0, records = 0;

  [[nodiscard]] scratch make_scratch() const { return {}; }
  raw_point decode(const unsigned char* rec, std::uint64_t, scratch&) const {
    const pcd_point q = pcd_load_point(w, [&](const pcd_field& f) { return rec + f.offset; });
    return {q.position, q.normal, q.colour};
  }
  void observe(const raw_point&) {}
  void scanned(read_report&) const {}
};

struct pcd_ascii_codec {
  static constexpr bool line_based = true;
  using scratch = std::vector<std::string_view>;
  std::string path;
  pcd_header h;
  pcd_wanted w;
  std::uint64_t records = 0;

  [[nodiscard]] scratch make_scratch() const { return {}; }
  record_at start(const posix_file& f) const {
    line_cursor cur(f, h.data_begin, h.data_line - 1);
    std::string_view line;
    record_at at;
    if (!cur.next(line, at)) {
      if (records > 0) pcd_ascii_truncated(path, 0, records);
      return {0, f.size(), at.line + 1};
    }
    at.record = 0;
    return at;
  }
  raw_point decode(std::string_view line, std::uint64_t i, std::uint64_t line_no,
                   scratch& tok) const {
    split_ws(line, tok);
    const pcd_point q = pcd_parse_ascii_point(path, h, w, tok, i, line_no);
    return {q.position, q.normal, q.colour};
  }
  [[noreturn]] void truncated(std::uint64_t seen) const {
    pcd_ascii_truncated(path, seen, records);
  }
  void after(const posix_file&, const record_at&, read_report&) const {}
  void observe(const raw_point&) {}
  void scanned(read_report&) const {}
};

// --- the source -------------------------------------------------------------------------------

template <class Codec>
class file_point_source final : public point_source {
 public:
  /// Takes the open file and a codec whose header is parsed and checked; makes the pass that
  /// fills `report` and the index.
  file_point_source(std::unique_ptr<posix_file> file, Codec codec, attributes attrs,
                    std::optional<vec3d> origin_hint, std::optional<vec3d> sensor,
                    read_report& report)
      : file_(std::move(file)), codec_(std::move(codec)), attrs_(attrs), sensor_(sensor) {
    scan(origin_hint, report);
  }

  [[nodiscard]] attributes attrs() const override { return attrs_; }
  [[nodiscard]] vec3d origin() const override { return origin_; }
  [[nodiscard]] std::uint64_t size() const override { return size_; }
  [[nodiscard]] std::optional<vec3d> sensor() const override { return sensor_; }
  [[nodiscard]] std::string name() const override { return file_->path(); }

  void read(std::uint64_t first, std::size_t count, point_block& out) const override {
    if (first > size_ || count > size_ - first)
      throw InvalidArgument(
          cat(name(), ": points [", first, ", ", first + count, ") requested of ", size_));
    out.positions.resize(count);
    out.normals.resize(attrs_.normal ? count : 0);
    out.colours.resize(attrs_.colour ? count : 0);
    if (count == 0) return;
    auto [at, skip] = start_of(first);
    std::size_t k = 0;
    record_at last_at;
    normal_rule normal;  // the counts were reported at open
    const bool complete =
        for_records(at, skip + count, [&](const raw_point& q, const record_at& w) {
          if (!all_finite(q.position)) return true;
          if (skip > 0) {
            --skip;
            return true;
          }
          out.positions[k] = (q.position - origin_).cast<float>();
          if (attrs_.normal) out.normals[k] = normal(q.normal);
          if (attrs_.colour) out.colours[k] = q.colour;
          last_at = w;
          return ++k < count;
        });
    if (!complete || k < count)
      throw IoError(cat(name(), ": the file ends before point ", first + k,
                        " (it changed since it was opened)"));
    const std::lock_guard<std::mutex> lock(resume_mutex_);
    resume_ = {first + count - 1, last_at};
  }

 private:
  /// Calls visit(point, where) for the records from `at` on until it returns false; about
  /// `want` records are expected to be wanted (to size the first reads). False when a line
  /// file ends before its last record.
  template <class Visit>
  bool for_records(record_at at, std::uint64_t want, Visit&& visit) const {
    typename Codec::scratch scratch = codec_.make_scratch();
    if constexpr (!Codec::line_based) {
      const std::uint64_t size = codec_.record_size;
      const std::uint64_t per_block = std::max<std::uint64_t>(1, block_bytes / size);
      std::vector<unsigned char> buf;
      for (std::uint64_t r = at.record; r < codec_.records;) {
        const std::uint64_t n =
            std::min({per_block, codec_.records - r, std::max<std::uint64_t>(want, 1024)});
        want = want > n ? want - n : 0;
        buf.resize(static_cast<std::size_t>(n * size));
        if constexpr (requires { codec_.read_records(*file_, r, n, buf.data()); })
          codec_.read_records(*file_, r, n, buf.data());
        else
          file_->read_exact(codec_.data_begin + r * size, buf.size(), buf.data());
        for (std::uint64_t k = 0; k < n; ++k, ++r)
          if (!visit(codec_.decode(buf.data() + k * size, r, scratch), record_at{r})) return true;
      }
      return true;
    } else {
      line_cursor cur(*file_, at.offset, at.line - 1);
      std::string_view line;
      for (std::uint64_t r = at.record; r < codec_.records; ++r) {
        record_at here;
        if (!cur.next(line, here)) return false;
        here.record = r;
        if (!visit(codec_.decode(line, r, here.line, scratch), here)) return true;
      }
      return true;
    }
  }

  /// Where a read of kept point `first` starts: a record and how many kept points to skip from
  /// it. The run holding `first` gives one; inside a run that dropped nothing a fixed-size
  /// record is found by arithmetic alone; and a read that continues the last one starts where
  /// that ended. Without the last two, reading a file with dropped points (or any line-based
  /// file) a few points at a time would parse up to a run (2^run_bits records) per read — for a
  /// LAZ file, decode them.
  [[nodiscard]] std::pair<record_at, std::uint64_t> start_of(std::uint64_t first) const {
    const std::uint64_t run = first >> run_bits, run_first = run << run_bits;
    record_at at = index_[run];
    std::uint64_t skip = first - run_first;
    if constexpr (!Codec::line_based) {
      const std::uint64_t run_records =
          (run + 1 < index_.size() ? index_[run + 1].record : codec_.records) - at.record;
      const std::uint64_t run_kept = std::min(std::uint64_t{1} << run_bits, size_ - run_first);
      if (run_records == run_kept) return {record_at{at.record + skip}, 0};
    }
    const std::lock_guard<std::mutex> lock(resume_mutex_);
    // resume_.at holds kept point resume_.kept: from there, skip it and those up to `first`.
    if (resume_.kept < first && resume_.kept >= run_first)
      return {resume_.at, first - resume_.kept};
    return {at, skip};
  }

  // The pass at open: finish_mesh's bookkeeping (box, normals, report) and the index.
  void scan(const std::optional<vec3d>& origin_hint, read_report& report) {
    finite_box box;
    normal_rule normal;
    record_at first{};
    if constexpr (Codec::line_based) first = codec_.start(*file_);
    record_at last = first;
    const bool complete =
        for_records(first, codec_.records, [&](const raw_point& q, const record_at& at) {
          codec_.observe(q);
          last = at;
          if (!box.add(q.position)) return true;
          if (((box.finite - 1) & ((std::uint64_t{1} << run_bits) - 1)) == 0) index_.push_back(at);
          if (attrs_.normal) normal(q.normal);
          return true;
        });
    if constexpr (Codec::line_based) {
      if (!complete) codec_.truncated(box.total);
      codec_.after(*file_, last, report);
    }
    codec_.scanned(report);
    origin_ = choose_origin(box, origin_hint, file_->path(), report);
    normal.report_to(file_->path(), report);
    size_ = box.finite;
    index_.shrink_to_fit();
  }

  std::unique_ptr<posix_file> file_;
  Codec codec_;
  attributes attrs_;
  std::optional<vec3d> sensor_;
  vec3d origin_ = vec3d::Zero();
  std::uint64_t size_ = 0;
  std::vector<record_at> index_;  ///< index_[k]: where kept point k·2^run_bits is
  struct resume_point {
    /// The last point the last read gave; before any read, a value no point is above.
    std::uint64_t kept = ~std::uint64_t{0};
    record_at at;  ///< where it is
  };
  mutable std::mutex resume_mutex_;
  mutable resume_point resume_;
};

/// A file that cannot be read in parts (PCD binary_compressed), held in memory.
class memory_point_source final : public point_source {
 public:
  memory_point_source(point_cloud c, std::string name)
      : cloud_(std::move(c)), name_(std::move(name)), inner_(cloud_, name_) {}
  [[nodiscard]] attributes attrs() const override { return inner_.attrs(); }
  [[nodiscard]] vec3d origin() const override { return cloud_.origin; }
  [[nodiscard]] std::uint64_t size() const override { return cloud_.size(); }
  void read(std::uint64_t first, std::size_t count, point_block& out) const override {
    inner_.read(first, count, out);
  }
  [[nodiscard]] std::optional<vec3d> sensor() const override { return cloud_.sensor; }
  [[nodiscard]] std::string name() const override { return name_; }

 private:
  point_cloud cloud_;
  std::string name_;
  cloud_point_source inner_;
};

template <class Codec>
std::unique_ptr<point_source> make_source(std::unique_ptr<posix_file> f, Codec codec, attributes a,
                                          std::optional<vec3d> hint, std::optional<vec3d> sensor,
                                          read_report& r) {
  return std::make_unique<file_point_source<Codec>>(std::move(f), std::move(codec), a, hint, sensor,
                                                    r);
}

[[noreturn]] void cannot_stream(const std::string& path, const std::string& why) {
  format_error(path, "", cat(why, "; this cannot be read in blocks (read_points can load it)"));
}

std::unique_ptr<point_source> open_ply(std::unique_ptr<posix_file> f, read_report& r) {
  const std::string& path = f->path();
  const std::string head = read_header_lines(*f, "end_header");
  ply_header h = parse_ply_header(path, head);
  const ply_plan plan = plan_ply(path, h, r);
  const attributes a{.normal = plan.has_normals, .colour = plan.has_colours};
  const std::optional<vec3d> hint = h.origin;
  if (plan.vertex == nullptr) {
    // No vertices, so nothing to stream: read_points' checks and report, and no points.
    r = read_report{};
    return std::make_unique<memory_point_source>(read_points(path, &r), path);
  }
  const auto vertex = static_cast<std::size_t>(plan.vertex - h.elements.data());
  if (h.format == encoding::ascii) {
    ply_ascii_codec c{.path = path, .h = {}, .vertex = vertex, .records = plan.vertex->count};
    c.rows_total = ascii_rows(path, h);
    for (std::size_t e = 0; e < vertex; ++e) c.rows_before += h.elements[e].count;
    c.h = std::move(h);
    return make_source(std::move(f), std::move(c), a, hint, std::nullopt, r);
  }
  const std::uint64_t need = check_binary_size(path, h, f->size() - h.data_begin);
  const auto has_list = [](const element& e) {
    return std::any_of(e.props.begin(), e.props.end(), [](const property& p) { return p.is_list; });
  };
  const auto row_size = [](const element& e) {
    std::uint64_t s = 0;
    for (const property& p : e.props) s += scalar_size(p.type);
    return s;
  };
  if (has_list(*plan.vertex))
    cannot_stream(path, "binary vertex rows with a list property have no fixed size");
  ply_binary_codec c{.path = path, .h = {}, .vertex = vertex};
  c.swap = (h.format == encoding::binary_be) != (std::endian::native == std::endian::big);
  c.data_begin = h.data_begin;
  for (std::size_t e = 0; e < vertex; ++e) {
    if (has_list(h.elements[e]))
      cannot_stream(path, cat("element ", h.elements[e].name,
                              " comes before the vertices and has rows of varying size"));
    c.data_begin += h.elements[e].count * row_size(h.elements[e]);  // ≤ need: no overflow
  }
  c.record_size = row_size(*plan.vertex);
  c.records = plan.vertex->count;
  // With fixed rows throughout, `need` is the exact data size: read_points' warning about
  // trailing bytes can be given without reading the other elements.
  const std::uint64_t available = f->size() - h.data_begin;
  if (std::none_of(h.elements.begin(), h.elements.end(), has_list) && available > need)
    r.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": ",
                             available - need, " bytes after the last element were ignored"));
  c.h = std::move(h);
  return make_source(std::move(f), std::move(c), a, hint, std::nullopt, r);
}

std::unique_ptr<point_source> open_las(std::unique_ptr<posix_file> f, read_report& r) {
  std::vector<unsigned char> head(
      static_cast<std::size_t>(std::min<std::uint64_t>(f->size(), 375)));
  f->read_exact(0, head.size(), head.data());
  las_codec c{.path = f->path(),
              .h = parse_las_header(f->path(), head.data(), f->size(), r),
              .laz = nullptr};
  if (c.h.compressed) {
    const posix_file& file = *f;
    c.laz = std::make_shared<const laz_record_reader>(
        file, read_laz_layout(file.path(), c.h, file.size(),
                              [&](std::uint64_t at, std::size_t n, unsigned char* out) {
                                file.read_exact(at, n, out);
                              }));
  }
  c.data_begin = c.h.data_offset;
  c.record_size = c.h.record_length;
  c.records = c.h.count;
  const attributes a{.normal = false, .colour = c.h.rgb_offset != 0};
  return make_source(std::move(f), std::move(c), a, std::nullopt, std::nullopt, r);
}

std::unique_ptr<point_source> open_pcd(std::unique_ptr<posix_file> f, read_report& r) {
  const std::string& path = f->path();
  const std::string head = read_header_lines(*f, "DATA");
  pcd_header h = parse_pcd_header(path, head);
  if (h.data == pcd_header::data_kind::compressed) {
    // One LZF block for the whole file: it is read whole (see the header comment).
    r = read_report{};
    point_cloud c = std::move(finish_mesh(read_pcd_file(path, r), path, r).vertices);
    return std::make_unique<memory_point_source>(std::move(c), path);
  }
  const pcd_wanted w = pcd_fields(path, h, r);
  const attributes a{.normal = w.normal[0] != nullptr, .colour = w.rgb != nullptr};
  // The points are in the sensor's frame (the pose is not applied), as read_points says.
  const std::optional<vec3d> sensor = vec3d::Zero();
  (void)pcd_data_bytes(path, h);
  if (h.data == pcd_header::data_kind::ascii) {
    pcd_ascii_codec c{.path = path, .h = {}, .w = {}, .records = h.points};
    // w points into h.fields, whose storage moves with h.
    c.h = std::move(h);
    c.w = w;
    return make_source(std::move(f), std::move(c), a, std::nullopt, sensor, r);
  }
  pcd_check_binary_size(path, h, f->size() - h.data_begin, r);
  pcd_binary_codec c{};
  c.data_begin = h.data_begin;
  c.record_size = h.point_size;
  c.records = h.points;
  c.h = std::move(h);
  c.w = w;
  return make_source(std::move(f), std::move(c), a, std::nullopt, sensor, r);
}

}  // namespace
}  // namespace detail

std::unique_ptr<point_source> open_point_source(const std::string& path, read_report* report) {
  read_report local;
  read_report& r = report ? *report : local;
  r = read_report{};
  const std::string ext = detail::lower_extension(path);
  if (ext != ".ply" && ext != ".las" && ext != ".laz" && ext != ".pcd")
    detail::format_error(path, "",
                         detail::cat(ext.empty() ? std::string("no file extension")
                                                 : detail::cat("extension '", ext, "'"),
                                     ": open_point_source streams .ply, .las, .laz and .pcd files "
                                     "(read_points also reads .obj and .off)"));
  auto f = std::make_unique<detail::posix_file>(path);
  if (ext == ".ply") return detail::open_ply(std::move(f), r);
  if (ext == ".las" || ext == ".laz") return detail::open_las(std::move(f), r);
  return detail::open_pcd(std::move(f), r);
}

}  // namespace pbr_lod
