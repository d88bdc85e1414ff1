// pbr_lod — the .spz reader (Niantic's packed Gaussians). The layout was learnt from the
// reference implementation, github.com/nianticlabs/spz (src/cc/load-spz.cc, splat-utils.h); the
// code is ours.
//
//   versions 1–3: one gzip stream holding a 16-byte header
//     u32 magic 0x5053474e ("NGSP"), u32 version, u32 numPoints, u8 shDegree,
//     u8 fractionalBits, u8 flags, u8 reserved
//   then the attributes, each for all points in turn:
//     positions  3 × 24-bit signed fixed point / 2^fractionalBits (v1: 3 × float16)
//     alphas     1 byte: opacity · 255
//     colours    3 bytes: 0.5·255 + dc · 0.15·255 (the DC coefficient, rescaled)
//     scales     3 bytes: (log scale + 10) · 16
//     rotations  v1–2: 3 bytes x y z as (b / 127.5 − 1), w = √(1 − x² − y² − z²) ≥ 0;
//                v3+: 4 bytes "smallest three" (2 bits: the largest component's index; three
//                10-bit sign + magnitude values scaled by 1/√2; the largest is ≥ 0)
//     sh         (degree-1..d coefficients) × 3 bytes, coefficient-major, RGB interleaved,
//                value (b − 128) / 128
//   and, when flags bit 1 is set, extension records (ignored here, with a warning).
//   version 4: the same 16 bytes unpacked (plus numStreams, u32 tocByteOffset, 12 reserved
//     bytes: a 32-byte header), a table of contents at tocByteOffset (per stream: u64
//     compressed size, u64 uncompressed size), then one zstd frame per non-empty attribute, in
//     the order above.
// Quaternion component order in the file is x y z w; ours is w x y z.
//
// Memory: nothing is allocated on the header's word alone. A gzip stream expands at most
// 1032:1 (deflate's limit), so a count needing more bytes than that is refused at once; a zstd
// stream is held to the reference's own bound (1024 bytes out per byte in); and the output
// buffers grow only as decompressed bytes actually arrive, so a small file claiming a large
// count costs what it decompresses to, no more.
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>

#include "gaussian_internal.hpp"

namespace pbr_lod::detail {
namespace {

constexpr std::uint32_t spz_magic = 0x5053474e;
constexpr std::uint64_t deflate_max_ratio = 1032;
constexpr std::uint64_t zstd_max_ratio = 1024;
constexpr double spz_colour_scale = 0.15;
constexpr int spz_latest_version = 4;

struct spz_header {
  std::uint32_t version = 0, count = 0;
  int degree = 0, fractional_bits = 0, flags = 0;
};

/// Bytes per attribute, in file order.
struct spz_layout {
  std::uint64_t sizes[6] = {};  // positions, alphas, colours, scales, rotations, sh
  static constexpr const char* names[6] = {"positions", "alphas",    "colours",
                                           "scales",    "rotations", "sh"};
  [[nodiscard]] std::uint64_t total() const {
    std::uint64_t t = 0;
    for (const std::uint64_t s : sizes) t += s;
    return t;
  }
  /// The attribute the byte at `offset` (into the attributes) belongs to.
  [[nodiscard]] const char* name_at(std::uint64_t offset) const {
    for (int k = 0; k < 6; ++k) {
      if (offset < sizes[k]) return names[k];
      offset -= sizes[k];
    }
    return "extensions";
  }
};

spz_layout layout_of(const spz_header& h) {
  const std::uint64_t n = h.count;
  const std::uint64_t dim = static_cast<std::uint64_t>(sh_coefficients(h.degree) - 1);
  spz_layout l;
  l.sizes[0] = n * (h.version == 1 ? 6 : 9);
  l.sizes[1] = n;
  l.sizes[2] = n * 3;
  l.sizes[3] = n * 3;
  l.sizes[4] = n * (h.version >= 3 ? 4 : 3);
  l.sizes[5] = n * dim * 3;
  return l;  // n < 2³², every factor ≤ 45: no overflow
}

void check_header(const std::string& path, const spz_header& h) {
  if (h.version < 1 || h.version > static_cast<std::uint32_t>(spz_latest_version))
    format_error(path, "header",
                 cat("SPZ version ", h.version, " is not supported (this reader knows 1–",
                     spz_latest_version, ")"));
  if (h.degree > max_sh_degree)
    format_error(
        path, "header",
        cat("SH degree ", h.degree, ": degrees above ", max_sh_degree, " are not supported"));
}

/// IEEE half → float (SPZ version 1 positions).
float half_to_float(std::uint16_t h) {
  const int sign = (h >> 15) & 1, exponent = (h >> 10) & 0x1f, mantissa = h & 0x3ff;
  float v = 0;
  if (exponent == 0)
    v = std::ldexp(static_cast<float>(mantissa), -24);
  else if (exponent == 31)
    v = mantissa == 0 ? std::numeric_limits<float>::infinity()
                      : std::numeric_limits<float>::quiet_NaN();
  else
    v = std::ldexp(static_cast<float>(mantissa | 0x400), exponent - 25);
  return sign ? -v : v;
}

/// Rotation (w, x, y, z) of a v1–2 record: x y z stored, w ≥ 0 from unit length.
vec4d first_three(const unsigned char* r) {
  const vec3d xyz(r[0] / 127.5 - 1.0, r[1] / 127.5 - 1.0, r[2] / 127.5 - 1.0);
  return {std::sqrt(std::max(0.0, 1.0 - xyz.squaredNorm())), xyz.x(), xyz.y(), xyz.z()};
}

/// Rotation (w, x, y, z) of a v3+ record ("smallest three", components x y z w in the file).
vec4d smallest_three(const unsigned char* r) {
  std::uint32_t comp = static_cast<std::uint32_t>(r[0]) | static_cast<std::uint32_t>(r[1]) << 8 |
                       static_cast<std::uint32_t>(r[2]) << 16 |
                       static_cast<std::uint32_t>(r[3]) << 24;
  const int largest = static_cast<int>(comp >> 30);
  double xyzw[4] = {};
  double sum = 0;
  for (int i = 3; i >= 0; --i) {  // the last-packed component sits in the low bits
    if (i == largest) continue;
    const double mag = std::sqrt(0.5) * static_cast<double>(comp & 511u) / 511.0;
    xyzw[i] = ((comp >> 9) & 1u) ? -mag : mag;
    comp >>= 10;
    sum += xyzw[i] * xyzw[i];
  }
  xyzw[largest] = std::sqrt(std::max(0.0, 1.0 - sum));
  return {xyzw[3], xyzw[0], xyzw[1], xyzw[2]};
}

/// Decodes the attribute bytes (layout `l`) into the collector.
gaussian_cloud decode(const std::string& path, read_report& report, const spz_header& h,
                      const spz_layout& l, const unsigned char* data) {
  const unsigned char* pos = data;
  const unsigned char* alpha = pos + l.sizes[0];
  const unsigned char* colour = alpha + l.sizes[1];
  const unsigned char* scale = colour + l.sizes[2];
  const unsigned char* rot = scale + l.sizes[3];
  const unsigned char* sh = rot + l.sizes[4];
  const int dim = sh_coefficients(h.degree) - 1;
  const double unit = std::ldexp(1.0, -h.fractional_bits);
  gaussian_collector out(path, report, h.degree);
  out.reserve(h.count);
  std::vector<float> coeffs(static_cast<std::size_t>(dim + 1) * 3);
  for (std::size_t i = 0; i < h.count; ++i) {
    vec3d p;
    for (int k = 0; k < 3; ++k) {
      if (h.version == 1) {
        p[k] = half_to_float(load_le<std::uint16_t>(pos + 6 * i + 2 * k));
      } else {
        const unsigned char* b = pos + 9 * i + 3 * k;
        std::int32_t v = b[0] | b[1] << 8 | b[2] << 16;
        if (v & 0x800000) v -= 0x1000000;  // sign of the 24-bit value
        p[k] = v * unit;
      }
    }
    vec3d s;
    for (int k = 0; k < 3; ++k) s[k] = std::exp(scale[3 * i + k] / 16.0 - 10.0);
    const vec4d q = h.version >= 3 ? smallest_three(rot + 4 * i) : first_three(rot + 3 * i);
    for (int c = 0; c < 3; ++c)
      coeffs[static_cast<std::size_t>(c)] =
          static_cast<float>((colour[3 * i + c] / 255.0 - 0.5) / spz_colour_scale);
    for (int j = 0; j < dim * 3; ++j)
      coeffs[static_cast<std::size_t>(3 + j)] =
          static_cast<float>((sh[(i * dim * 3) + static_cast<std::size_t>(j)] - 128.0) / 128.0);
    out.add(p, s, q, alpha[i] / 255.0, coeffs.data());
  }
  return out.finish(std::nullopt);
}

// --- versions 1–3: one gzip stream ---------------------------------------------------------------

/// Inflates a gzip stream piece by piece into a buffer that grows with what arrives.
class inflater {
 public:
  inflater(const std::string& path, std::string_view in) : path_(path) {
    if (inflateInit2(&z_, 16 + MAX_WBITS) != Z_OK) throw IoError(path + ": cannot initialise zlib");
    z_.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(in.data()));
    z_.avail_in = static_cast<uInt>(std::min<std::size_t>(in.size(), 1u << 30));
    rest_ = in.size() - z_.avail_in;
  }
  ~inflater() { inflateEnd(&z_); }
  inflater(const inflater&) = delete;
  inflater& operator=(const inflater&) = delete;

  /// Appends up to n more bytes to out; returns how many arrived (fewer: the stream ended).
  std::size_t read(std::vector<unsigned char>& out, std::size_t n) {
    std::size_t got = 0;
    while (got < n && !ended_) {
      const std::size_t piece = std::min<std::size_t>(n - got, std::size_t{1} << 22);
      const std::size_t at = out.size();
      out.resize(at + piece);
      z_.next_out = out.data() + at;
      z_.avail_out = static_cast<uInt>(piece);
      if (z_.avail_in == 0 && rest_ > 0) {  // inputs over 1 GiB are fed in pieces
        const auto more = static_cast<uInt>(std::min<std::size_t>(rest_, 1u << 30));
        z_.avail_in = more;
        rest_ -= more;
      }
      const int rc = inflate(&z_, Z_NO_FLUSH);
      const std::size_t produced = piece - z_.avail_out;
      out.resize(at + produced);
      got += produced;
      if (rc == Z_STREAM_END) {
        ended_ = true;
      } else if (rc == Z_BUF_ERROR && z_.avail_in == 0 && rest_ == 0) {
        format_error(path_, "gzip stream", "the compressed data ends early (truncated)");
      } else if (rc != Z_OK && rc != Z_BUF_ERROR) {
        format_error(path_, "gzip stream",
                     cat("corrupt compressed data (zlib: ", z_.msg ? z_.msg : "error", ")"));
      }
    }
    return got;
  }

 private:
  const std::string& path_;
  z_stream z_{};
  std::size_t rest_ = 0;
  bool ended_ = false;
};

gaussian_cloud read_gzip_spz(const std::string& path, read_report& report,
                             const std::string& bytes) {
  inflater z(path, bytes);
  std::vector<unsigned char> head;
  if (z.read(head, 16) < 16)
    format_error(path, "header", "the stream ends inside the 16-byte header");
  if (load_le<std::uint32_t>(head.data()) != spz_magic)
    format_error(path, "header",
                 cat("bad magic 0x", std::hex, load_le<std::uint32_t>(head.data()),
                     " (expected 0x5053474e, \"NGSP\")"));
  spz_header h;
  h.version = load_le<std::uint32_t>(head.data() + 4);
  h.count = load_le<std::uint32_t>(head.data() + 8);
  h.degree = head[12];
  h.fractional_bits = head[13];
  h.flags = head[14];
  check_header(path, h);
  if (h.version >= 4)
    format_error(path, "header",
                 cat("SPZ version ", h.version,
                     " inside a gzip stream (version 4 "
                     "files are zstd streams behind a plain header)"));
  const spz_layout l = layout_of(h);
  const std::uint64_t need = l.total();
  if (need / deflate_max_ratio > bytes.size())
    format_error(path, "header",
                 cat(h.count, " Gaussians need ", need, " bytes, more than a ", bytes.size(),
                     "-byte gzip stream can hold"));
  std::vector<unsigned char> data;
  const std::size_t got = z.read(data, static_cast<std::size_t>(need));
  if (got < need)
    format_error(path, l.name_at(got),
                 cat("the data ends (truncated): ", got, " of ", need, " bytes for ", h.count,
                     " Gaussians"));
  std::vector<unsigned char> extra;
  if (z.read(extra, 1) > 0)
    report.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": ",
                                  (h.flags & 2) ? "extension records" : "trailing data",
                                  " after the Gaussians were ignored"));
  return decode(path, report, h, l, data.data());
}

// --- version 4: zstd streams behind a plain header
// -------------------------------------------------

/// Decompresses one zstd stream of exactly `want` bytes, growing the buffer as data arrives.
void unzstd(const std::string& path, const char* what, std::string_view in, std::uint64_t want,
            std::vector<unsigned char>& out) {
  std::unique_ptr<ZSTD_DStream, decltype(&ZSTD_freeDStream)> z(ZSTD_createDStream(),
                                                               &ZSTD_freeDStream);
  if (!z) throw IoError(path + ": cannot initialise zstd");
  ZSTD_initDStream(z.get());
  ZSTD_inBuffer ib{in.data(), in.size(), 0};
  std::size_t rc = 1;
  while (out.size() < want) {
    const std::size_t at = out.size();
    const std::size_t piece =
        static_cast<std::size_t>(std::min<std::uint64_t>(want - at, std::uint64_t{1} << 22));
    out.resize(at + piece);
    ZSTD_outBuffer ob{out.data() + at, piece, 0};
    const std::size_t consumed = ib.pos;
    rc = ZSTD_decompressStream(z.get(), &ob, &ib);
    out.resize(at + ob.pos);
    if (ZSTD_isError(rc))
      format_error(path, what, cat("corrupt zstd stream (", ZSTD_getErrorName(rc), ")"));
    if (ob.pos == 0 && (rc == 0 || ib.pos == ib.size || ib.pos == consumed))
      break;  // no progress: the stream ended
  }
  if (out.size() < want)
    format_error(path, what,
                 cat("the stream holds ", out.size(), " bytes, the table of contents says ", want,
                     " (truncated)"));
}

gaussian_cloud read_zstd_spz(const std::string& path, read_report& report,
                             const std::string& bytes) {
  if (bytes.size() < 32) format_error(path, "header", "the file ends inside the 32-byte header");
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  spz_header h;
  h.version = load_le<std::uint32_t>(b + 4);
  h.count = load_le<std::uint32_t>(b + 8);
  h.degree = b[12];
  h.fractional_bits = b[13];
  h.flags = b[14];
  const int streams = b[15];
  const std::uint32_t toc = load_le<std::uint32_t>(b + 16);
  check_header(path, h);
  if (h.version < 4)
    format_error(path, "header",
                 cat("SPZ version ", h.version,
                     " behind a plain header (versions 1–3 are one "
                     "gzip stream)"));
  const spz_layout l = layout_of(h);
  const int want_streams = l.sizes[5] > 0 ? 6 : (l.sizes[0] > 0 ? 5 : 0);
  if (streams != want_streams)
    format_error(path, "header",
                 cat(streams, " streams; ", h.count, " Gaussians of SH degree ", h.degree, " need ",
                     want_streams));
  if (l.sizes[0] / zstd_max_ratio > bytes.size())
    format_error(path, "header",
                 cat(h.count, " Gaussians: more than a ", bytes.size(), "-byte file can hold"));
  const std::uint64_t toc_end = std::uint64_t{toc} + 16u * static_cast<std::uint64_t>(streams);
  if (toc < 32 || toc_end > bytes.size())
    format_error(path, "table of contents",
                 cat("offset ", toc, " with ", streams, " entries is outside the file (",
                     bytes.size(), " bytes)"));
  if (toc > 32 && !(h.flags & 2))
    report.warnings.push_back(cat(std::filesystem::path(path).filename().string(), ": ", toc - 32,
                                  " bytes before the table of contents were ignored"));
  std::vector<unsigned char> data;
  data.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(l.total(), bytes.size())));
  std::uint64_t at = toc_end;
  for (int k = 0; k < streams; ++k) {
    const std::uint64_t packed = load_le<std::uint64_t>(b + toc + 16 * k);
    const std::uint64_t plain = load_le<std::uint64_t>(b + toc + 16 * k + 8);
    if (plain != l.sizes[k])
      format_error(path, spz_layout::names[k],
                   cat("uncompressed size ", plain, ", expected ", l.sizes[k], " for ", h.count,
                       " Gaussians"));
    if (packed > bytes.size() - at)
      format_error(path, spz_layout::names[k],
                   cat("compressed size ", packed, " runs past the end of the file (truncated)"));
    unzstd(path, spz_layout::names[k],
           std::string_view(bytes).substr(static_cast<std::size_t>(at),
                                          static_cast<std::size_t>(packed)),
           data.size() + plain, data);
    at += packed;
  }
  if (h.flags & 2)
    report.warnings.push_back(
        cat(std::filesystem::path(path).filename().string(), ": extension records were ignored"));
  return decode(path, report, h, l, data.data());
}

}  // namespace

gaussian_cloud read_spz_file(const std::string& path, read_report& report) {
  const std::string bytes = read_file_bytes(path);
  if (bytes.size() >= 4 &&
      load_le<std::uint32_t>(reinterpret_cast<const unsigned char*>(bytes.data())) == spz_magic)
    return read_zstd_spz(path, report, bytes);
  if (bytes.size() >= 2 && static_cast<unsigned char>(bytes[0]) == 0x1f &&
      static_cast<unsigned char>(bytes[1]) == 0x8b)
    return read_gzip_spz(path, report, bytes);
  format_error(path, "header",
               bytes.empty() ? std::string("the file is empty")
                             : "not an SPZ file: neither a gzip stream nor the \"NGSP\" magic");
}

}  // namespace pbr_lod::detail
