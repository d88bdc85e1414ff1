// Tests for io/gaussians.hpp: hand-built 3DGS PLY, .splat and .spz files whose values are worked
// out by hand in the comments (not by re-running the reader's arithmetic), the bad-value rule,
// malformed files, and write → read round trips.
#include <gtest/gtest.h>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <random>

#include "gaussian_fixtures.hpp"
#include "io_test_util.hpp"
#include "pbr_lod/io/gaussians.hpp"

namespace pbr_lod::test {
namespace {

constexpr double C0 = 0.28209479177387814;
constexpr float inf = std::numeric_limits<float>::infinity();
constexpr float nan = std::numeric_limits<float>::quiet_NaN();

// --- building 3DGS PLY files ---------------------------------------------------------------------

/// One Gaussian as a 3DGS file stores it (log scales, logit opacity, raw quaternion).
struct gs_row {
  double x = 0, y = 0, z = 0;
  float dc[3] = {0, 0, 0};
  std::vector<float> rest;  ///< channel-major, 3 × (coefficients − 1)
  float opacity = 0;
  float scale[3] = {0, 0, 0};
  float rot[4] = {1, 0, 0, 0};
};

struct ply_prop {
  std::string name;
  bool is_double = false;
  std::function<double(const gs_row&)> get;
};

/// The properties of a 3DGS PLY of SH degree d (plus nx ny nz), in the standard order.
std::vector<ply_prop> standard_props(int degree) {
  std::vector<ply_prop> p;
  p.push_back({"x", false, [](const gs_row& r) { return r.x; }});
  p.push_back({"y", false, [](const gs_row& r) { return r.y; }});
  p.push_back({"z", false, [](const gs_row& r) { return r.z; }});
  for (const char* n : {"nx", "ny", "nz"})
    p.push_back({n, false, [](const gs_row&) { return 0.0; }});
  for (int c = 0; c < 3; ++c)
    p.push_back({"f_dc_" + std::to_string(c), false, [c](const gs_row& r) { return r.dc[c]; }});
  const int rest = 3 * ((degree + 1) * (degree + 1) - 1);
  for (int k = 0; k < rest; ++k)
    p.push_back({"f_rest_" + std::to_string(k), false,
                 [k](const gs_row& r) { return static_cast<double>(r.rest.at(k)); }});
  p.push_back({"opacity", false, [](const gs_row& r) { return r.opacity; }});
  for (int a = 0; a < 3; ++a)
    p.push_back({"scale_" + std::to_string(a), false, [a](const gs_row& r) { return r.scale[a]; }});
  for (int a = 0; a < 4; ++a)
    p.push_back({"rot_" + std::to_string(a), false, [a](const gs_row& r) { return r.rot[a]; }});
  return p;
}

std::string make_gs_ply(const std::vector<gs_row>& rows, const std::vector<ply_prop>& props,
                        bool ascii = false, std::uint64_t claimed = ~std::uint64_t{0}) {
  std::string s = "ply\nformat ";
  s += ascii ? "ascii 1.0\n" : "binary_little_endian 1.0\n";
  s += "element vertex " + std::to_string(claimed == ~std::uint64_t{0} ? rows.size() : claimed) +
       "\n";
  for (const auto& p : props)
    s += std::string("property ") + (p.is_double ? "double " : "float ") + p.name + "\n";
  s += "end_header\n";
  for (const auto& r : rows) {
    for (const auto& p : props) {
      const double v = p.get(r);
      if (ascii) {
        s += std::to_string(v) + " ";
      } else if (p.is_double) {
        put_le<double>(s, v);
      } else {
        put_le<float>(s, static_cast<float>(v));
      }
    }
    if (ascii) s += "\n";
  }
  return s;
}

/// A row with recognisable values: position (1, 2, 3), f_dc (0.1, 0.2, 0.3), f_rest_k = k + 1,
/// opacity logit ln 3 (→ 0.75), log scales ln 2, ln 0.5, 0 (→ 2, 0.5, 1), rot (0, 0, 3, 4)
/// (→ (0, 0, 0.6, 0.8)).
gs_row sample_row(int degree) {
  gs_row r;
  r.x = 1;
  r.y = 2;
  r.z = 3;
  r.dc[0] = 0.1f;
  r.dc[1] = 0.2f;
  r.dc[2] = 0.3f;
  r.rest.resize(static_cast<std::size_t>(3 * ((degree + 1) * (degree + 1) - 1)));
  std::iota(r.rest.begin(), r.rest.end(), 1.0f);
  r.opacity = static_cast<float>(std::log(3.0));
  r.scale[0] = static_cast<float>(std::log(2.0));
  r.scale[1] = static_cast<float>(std::log(0.5));
  r.scale[2] = 0;
  r.rot[0] = 0;
  r.rot[1] = 0;
  r.rot[2] = 3;
  r.rot[3] = 4;
  return r;
}

void expect_sample(const gaussian_cloud& g, std::size_t i, int degree) {
  ASSERT_EQ(g.sh_degree, degree);
  const vec3d w = g.world(i);
  EXPECT_NEAR(w.x(), 1, 1e-6);
  EXPECT_NEAR(w.y(), 2, 1e-6);
  EXPECT_NEAR(w.z(), 3, 1e-6);
  EXPECT_NEAR(g.opacities[i], 0.75f, 1e-6f);
  EXPECT_NEAR(g.scales[i].x(), 2.0f, 1e-6f);
  EXPECT_NEAR(g.scales[i].y(), 0.5f, 1e-6f);
  EXPECT_NEAR(g.scales[i].z(), 1.0f, 1e-6f);
  EXPECT_NEAR(g.rotations[i][0], 0.0f, 1e-7f);
  EXPECT_NEAR(g.rotations[i][1], 0.0f, 1e-7f);
  EXPECT_NEAR(g.rotations[i][2], 0.6f, 1e-7f);
  EXPECT_NEAR(g.rotations[i][3], 0.8f, 1e-7f);
  EXPECT_FLOAT_EQ(g.sh[g.sh_index(i, 0, 0)], 0.1f);
  EXPECT_FLOAT_EQ(g.sh[g.sh_index(i, 0, 1)], 0.2f);
  EXPECT_FLOAT_EQ(g.sh[g.sh_index(i, 0, 2)], 0.3f);
  // colour = 0.5 + C0 · dc
  EXPECT_NEAR(g.base_colour(i).x(), 0.5 + C0 * 0.1, 1e-6);
  if (degree >= 1) {
    // f_rest_0..8 = 1..9 channel-major with 3 coefficients per channel: R = 1 2 3, G = 4 5 6,
    // B = 7 8 9; coefficient 1 is (1, 4, 7), coefficient 3 is (3, 6, 9) — when degree is 1.
    const float m = static_cast<float>((degree + 1) * (degree + 1) - 1);
    EXPECT_EQ(g.sh[g.sh_index(i, 1, 0)], 1.0f);
    EXPECT_EQ(g.sh[g.sh_index(i, 1, 1)], 1.0f + m);
    EXPECT_EQ(g.sh[g.sh_index(i, 1, 2)], 1.0f + 2 * m);
    EXPECT_EQ(g.sh[g.sh_index(i, 3, 2)], 3.0f + 2 * m);
  }
  if (degree == 1) {
    const float want[12] = {0.1f, 0.2f, 0.3f, 1, 4, 7, 2, 5, 8, 3, 6, 9};
    for (int j = 0; j < 12; ++j) EXPECT_EQ(g.sh[i * 12 + static_cast<std::size_t>(j)], want[j]);
  }
  if (degree == 3) {
    // 15 coefficients per channel: f_rest_15 (16) is G's first, f_rest_44 (45) B's last.
    EXPECT_EQ(g.sh[g.sh_index(i, 1, 1)], 16.0f);
    EXPECT_EQ(g.sh[g.sh_index(i, 15, 2)], 45.0f);
    EXPECT_EQ(g.sh[g.sh_index(i, 15, 0)], 15.0f);
  }
}

using GaussianPly = scratch_dir;

TEST_F(GaussianPly, EveryDegreeReadsHandCheckedValues) {
  for (int d = 0; d <= 3; ++d) {
    SCOPED_TRACE(d);
    const std::string p =
        write("d.ply", make_gs_ply({sample_row(d), sample_row(d)}, standard_props(d)));
    read_report r;
    const gaussian_cloud g = read_gaussians(p, &r);
    ASSERT_EQ(g.size(), 2u);
    EXPECT_EQ(r.points_read, 2u);
    expect_sample(g, 0, d);
    expect_sample(g, 1, d);
    EXPECT_NO_THROW(g.validate());
    EXPECT_TRUE(r.warnings.empty());
  }
}

TEST_F(GaussianPly, ShuffledDoubleAsciiAndExtraPropertiesReadTheSame) {
  std::mt19937 rng(42);  // any permutation must do: the order is the file's business
  for (int d : {1, 3}) {
    auto props = standard_props(d);
    props.push_back({"foo", false, [](const gs_row&) { return 7.0; }});
    std::shuffle(props.begin(), props.end(), rng);
    for (std::size_t k = 0; k < props.size(); k += 2) props[k].is_double = true;
    for (bool ascii : {false, true}) {
      SCOPED_TRACE(ascii);
      const std::string p = write("s.ply", make_gs_ply({sample_row(d)}, props, ascii));
      const gaussian_cloud g = read_gaussians(p);
      ASSERT_EQ(g.size(), 1u);
      expect_sample(g, 0, d);
    }
  }
}

TEST_F(GaussianPly, OtherElementsAndListsAreReadPast) {
  // An element before the vertices and a list property inside them: the whole-file path.
  auto props = standard_props(0);
  std::string s =
      "ply\nformat binary_little_endian 1.0\nelement camera 1\nproperty int id\n"
      "element vertex 1\n";
  for (const auto& p : props) s += "property float " + p.name + "\n";
  s += "property list uchar int junk\nend_header\n";
  put_le<std::int32_t>(s, 5);
  for (const auto& p : props) put_le<float>(s, static_cast<float>(p.get(sample_row(0))));
  s.push_back(2);
  put_le<std::int32_t>(s, 1);
  put_le<std::int32_t>(s, 2);
  const gaussian_cloud g = read_gaussians(write("e.ply", s));
  ASSERT_EQ(g.size(), 1u);
  expect_sample(g, 0, 0);
}

TEST_F(GaussianPly, FarFromTheOriginKeepsPrecision) {
  // Double positions 10⁷ away: the origin is the box centre, offsets exact in float.
  gs_row a = sample_row(0), b = sample_row(0);
  a.x = 1e7 + 0.125;
  b.x = 1e7 + 2.125;
  auto props = standard_props(0);
  for (auto& p : props) p.is_double = true;
  const gaussian_cloud g = read_gaussians(write("far.ply", make_gs_ply({a, b}, props)));
  EXPECT_EQ(g.origin.x(), 1e7 + 1.125);
  EXPECT_EQ(g.positions[0].x(), -1.0f);
  EXPECT_EQ(g.positions[1].x(), 1.0f);
}

TEST_F(GaussianPly, TheBadValueRule) {
  std::vector<gs_row> rows(9, sample_row(1));
  rows[0].opacity = inf;                // → opacity 1, clamped
  rows[1].opacity = -inf;               // → opacity 0, clamped
  rows[2].opacity = nan;                // → dropped
  rows[3].rot[2] = rows[3].rot[3] = 0;  // zero quaternion → identity
  rows[4].rot[1] = nan;                 // non-finite quaternion → identity
  rows[5].x = nan;                      // → dropped (position)
  rows[6].scale[1] = 1000;              // exp overflows → dropped
  rows[7].rest[4] = inf;                // → 0, clamped
  rows[8].scale[0] = -inf;              // exp(−inf) = 0: a finite, degenerate scale, kept
  read_report r;
  const gaussian_cloud g =
      read_gaussians(write("bad.ply", make_gs_ply(rows, standard_props(1))), &r);
  EXPECT_NO_THROW(g.validate());
  ASSERT_EQ(g.size(), 6u);  // rows 0 1 3 4 7 8
  EXPECT_EQ(r.points_read, 9u);
  EXPECT_EQ(r.dropped_non_finite, 1u);
  EXPECT_EQ(r.dropped_bad_gaussians, 2u);
  EXPECT_EQ(r.rotations_reset, 2u);
  EXPECT_EQ(r.values_clamped, 3u);
  EXPECT_EQ(g.opacities[0], 1.0f);
  EXPECT_EQ(g.opacities[1], 0.0f);
  EXPECT_EQ(g.rotations[2], vec4f(1, 0, 0, 0));
  EXPECT_EQ(g.rotations[3], vec4f(1, 0, 0, 0));
  // f_rest_4 is G's second coefficient (3 per channel): coefficient 2, channel 1.
  EXPECT_EQ(g.sh[g.sh_index(4, 2, 1)], 0.0f);
  EXPECT_EQ(g.scales[5].x(), 0.0f);
  EXPECT_EQ(r.warnings.size(), 4u);
}

TEST_F(GaussianPly, MalformedFilesGiveFormatErrors) {
  const auto props = standard_props(1);
  const std::string good = make_gs_ply({sample_row(1), sample_row(1)}, props);
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("t.ply", good.substr(0, good.size() - 3))),
                           FormatError, "truncated");
  PBR_LOD_EXPECT_THROW_MSG(
      read_gaussians(write("c.ply", make_gs_ply({sample_row(1)}, props, false, 1000))), FormatError,
      "truncated");
  PBR_LOD_EXPECT_THROW_MSG(
      read_gaussians(write("c2.ply", make_gs_ply({sample_row(1)}, props, true, 5))), FormatError,
      "c2.ply");
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("m.ply", "plx\n" + good.substr(4))), FormatError,
                           "magic");
  auto missing = props;
  missing.erase(std::remove_if(missing.begin(), missing.end(),
                               [](const ply_prop& p) { return p.name == "rot_3"; }),
                missing.end());
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("r.ply", make_gs_ply({sample_row(1)}, missing))),
                           FormatError, "'rot_3'");
  auto ten = props;
  ten.push_back({"f_rest_9", false, [](const gs_row&) { return 0.0; }});
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("f.ply", make_gs_ply({sample_row(1)}, ten))),
                           FormatError, "must be 0, 9, 24 or 45");
  auto four = standard_props(3);
  for (int k = 45; k < 72; ++k)
    four.push_back({"f_rest_" + std::to_string(k), false, [](const gs_row&) { return 0.0; }});
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("d4.ply", make_gs_ply({sample_row(3)}, four))),
                           FormatError, "degree 4");
  auto gap = props;
  gap.erase(std::remove_if(gap.begin(), gap.end(),
                           [](const ply_prop& p) { return p.name == "f_rest_3"; }),
            gap.end());
  gap.push_back({"f_rest_8", false, [](const gs_row&) { return 0.0; }});
  // f_rest_8 twice, f_rest_3 missing
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("g.ply", make_gs_ply({sample_row(1)}, gap))),
                           FormatError, "appears twice");
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("x.gsplat", good)), FormatError,
                           "unsupported extension");
  EXPECT_THROW((void)read_gaussians(path("none.ply")), IoError);
  // No vertices at all: an empty cloud, not an error.
  EXPECT_TRUE(read_gaussians(write("z.ply", make_gs_ply({}, props))).empty());
}

// --- .splat
// ---------------------------------------------------------------------------------------

std::string splat_record(const float pos[3], const float scale[3], const std::uint8_t rgba[4],
                         const std::uint8_t rot[4]) {
  std::string s;
  for (int k = 0; k < 3; ++k) put_le<float>(s, pos[k]);
  for (int k = 0; k < 3; ++k) put_le<float>(s, scale[k]);
  for (int k = 0; k < 4; ++k) s.push_back(static_cast<char>(rgba[k]));
  for (int k = 0; k < 4; ++k) s.push_back(static_cast<char>(rot[k]));
  return s;
}

using GaussianSplat = scratch_dir;

TEST_F(GaussianSplat, RecordsReadHandCheckedValues) {
  const float pos[3] = {1, 2, 3}, scale[3] = {0.5f, 1, 2}, neg[3] = {-0.5f, 1, 2};
  const std::uint8_t rgba[4] = {255, 0, 51, 51};
  const std::uint8_t rot_a[4] = {192, 128, 128, 128};  // (0.5, 0, 0, 0) → identity
  const std::uint8_t rot_b[4] = {128, 128, 224, 128};  // (0, 0, 0.75, 0) → (0, 0, 1, 0)
  const std::uint8_t rot_0[4] = {128, 128, 128, 128};  // zero → identity, counted
  read_report r;
  const gaussian_cloud g = read_gaussians(
      write("a.splat", splat_record(pos, scale, rgba, rot_a) + splat_record(pos, neg, rgba, rot_b) +
                           splat_record(pos, scale, rgba, rot_0)),
      &r);
  ASSERT_EQ(g.size(), 3u);
  EXPECT_EQ(g.sh_degree, 0);
  EXPECT_EQ(g.world(0), vec3d(1, 2, 3));
  EXPECT_EQ(g.scales[0], vec3f(0.5f, 1, 2));
  EXPECT_EQ(g.scales[1], vec3f(0.5f, 1, 2));  // −0.5 → 0.5, clamped
  EXPECT_NEAR(g.opacities[0], 0.2f, 1e-7f);   // 51 / 255
  // colour bytes 255, 0, 51 are 0.5 + C0·dc times 255: dc = (1 − 0.5) / C0 etc.
  EXPECT_NEAR(g.sh[0], 0.5 / C0, 1e-5);
  EXPECT_NEAR(g.sh[1], -0.5 / C0, 1e-5);
  EXPECT_NEAR(g.sh[2], (0.2 - 0.5) / C0, 1e-5);
  EXPECT_NEAR(g.base_colour(0).z(), 0.2f, 1e-6f);
  EXPECT_EQ(g.rotations[0], vec4f(1, 0, 0, 0));
  EXPECT_EQ(g.rotations[1], vec4f(0, 0, 1, 0));
  EXPECT_EQ(g.rotations[2], vec4f(1, 0, 0, 0));
  EXPECT_EQ(r.rotations_reset, 1u);
  EXPECT_EQ(r.values_clamped, 1u);

  const float bad[3] = {nan, 0, 0};
  read_report r2;
  EXPECT_EQ(read_gaussians(write("n.splat", splat_record(bad, scale, rgba, rot_a) +
                                                splat_record(pos, scale, rgba, rot_a)),
                           &r2)
                .size(),
            1u);
  EXPECT_EQ(r2.dropped_non_finite, 1u);
  PBR_LOD_EXPECT_THROW_MSG(
      read_gaussians(write("t.splat", splat_record(pos, scale, rgba, rot_a) + "x")), FormatError,
      "multiple of the 32-byte record");
  EXPECT_TRUE(read_gaussians(write("e.splat", "")).empty());
}

// --- .spz
// -----------------------------------------------------------------------------------------

/// The uncompressed SPZ payload of two Gaussians, attribute by attribute (values in the test).
struct spz_spec {
  std::uint32_t version = 2;
  std::uint32_t count = 2;  ///< what the header claims
  int degree = 1;
  int fractional_bits = 12;
  int points = 2;  ///< how many are written
};

std::string spz_attributes(const spz_spec& s) {
  std::string d;
  // Positions. v1: float16 (1, −2, 0.5) and (0, 0, 0); v2+: 24-bit fixed point, 12 fractional
  // bits: 4096 → 1, −2048 (0xFFF800) → −0.5, 6144 → 1.5.
  for (int i = 0; i < s.points; ++i) {
    if (s.version == 1) {
      const std::uint16_t h[3] = {0x3C00, 0xC000, 0x3800};
      for (int k = 0; k < 3; ++k) put_le<std::uint16_t>(d, i == 0 ? h[k] : 0);
    } else {
      const std::int32_t v[3] = {4096, -2048, 6144};
      for (int k = 0; k < 3; ++k) {
        const std::int32_t x = i == 0 ? v[k] : 0;
        d.push_back(static_cast<char>(x & 0xff));
        d.push_back(static_cast<char>((x >> 8) & 0xff));
        d.push_back(static_cast<char>((x >> 16) & 0xff));
      }
    }
  }
  for (int i = 0; i < s.points; ++i) d.push_back(static_cast<char>(51));  // alpha 0.2
  for (int i = 0; i < s.points; ++i)  // colour bytes: dc = (b / 255 − 0.5) / 0.15
    for (int c = 0; c < 3; ++c) d.push_back(static_cast<char>(c == 0 ? 255 : 0));
  for (int i = 0; i < s.points; ++i) {  // scales: b / 16 − 10 = log scale: 160 → 0, 176 → 1
    d.push_back(static_cast<char>(160));
    d.push_back(static_cast<char>(176));
    d.push_back(static_cast<char>(144));  // → −1
  }
  for (int i = 0; i < s.points; ++i) {
    if (s.version >= 3) {
      // Gaussian 0: largest = w (index 3), the rest 0 → identity: 0xC0000000.
      // Gaussian 1: largest = x (index 0); y = √½·511/511, z = w = 0. Packed low bits first from
      // index 3 down: w (bits 0–9), z (10–19), y (20–29) → y's magnitude 511 << 20.
      const std::uint32_t comp = i == 0 ? 0xC0000000u : 511u << 20;
      put_le<std::uint32_t>(d, comp);
    } else {
      // x y z as b / 127.5 − 1, w = √(1 − |xyz|²). Gaussian 0: bytes (128, 128, 128) → x = y =
      // z = 1/255, w ≈ 1. Gaussian 1: bytes (255, 128, 128) → x = 1, y = z = 1/255, w = 0.
      const std::uint8_t b = i == 0 ? 128 : 255;
      d.push_back(static_cast<char>(b));
      d.push_back(static_cast<char>(128));
      d.push_back(static_cast<char>(128));
    }
  }
  const int dim = (s.degree + 1) * (s.degree + 1) - 1;
  for (int i = 0; i < s.points; ++i)
    for (int j = 0; j < dim * 3; ++j)  // (b − 128) / 128: 192 → 0.5, 128 → 0, 64 → −0.5
      d.push_back(static_cast<char>(j % 3 == 0 ? 192 : j % 3 == 1 ? 128 : 64));
  return d;
}

std::string spz_header16(const spz_spec& s, std::uint32_t magic = 0x5053474e) {
  std::string h;
  put_le<std::uint32_t>(h, magic);
  put_le<std::uint32_t>(h, s.version);
  put_le<std::uint32_t>(h, s.count);
  h.push_back(static_cast<char>(s.degree));
  h.push_back(static_cast<char>(s.fractional_bits));
  h.push_back(0);
  h.push_back(0);
  return h;
}

std::string gzip(const std::string& raw) {
  z_stream z{};
  EXPECT_EQ(deflateInit2(&z, 9, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(deflateBound(&z, raw.size()) + 64, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(raw.data()));
  z.avail_in = static_cast<uInt>(raw.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

std::string zstd(const std::string& raw) {
  std::string out(ZSTD_compressBound(raw.size()), '\0');
  const std::size_t n = ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), 3);
  EXPECT_FALSE(ZSTD_isError(n));
  out.resize(n);
  return out;
}

/// A version-4 file: 32-byte header, table of contents, one zstd frame per attribute.
std::string spz_v4(const spz_spec& s) {
  const std::string d = spz_attributes(s);
  const std::uint64_t n = static_cast<std::uint64_t>(s.points);
  const int dim = (s.degree + 1) * (s.degree + 1) - 1;
  std::vector<std::uint64_t> sizes = {9 * n, n, 3 * n, 3 * n, 4 * n};
  if (dim > 0) sizes.push_back(n * static_cast<std::uint64_t>(dim) * 3);
  std::string h;
  put_le<std::uint32_t>(h, 0x5053474e);
  put_le<std::uint32_t>(h, 4);
  put_le<std::uint32_t>(h, s.count);
  h.push_back(static_cast<char>(s.degree));
  h.push_back(static_cast<char>(s.fractional_bits));
  h.push_back(0);
  h.push_back(static_cast<char>(sizes.size()));
  put_le<std::uint32_t>(h, 32);
  h.append(12, '\0');
  std::string streams;
  std::size_t at = 0;
  for (const std::uint64_t size : sizes) {
    const std::string z = zstd(d.substr(at, size));
    at += size;
    put_le<std::uint64_t>(h, z.size());
    put_le<std::uint64_t>(h, size);
    streams += z;
  }
  return h + streams;
}

void expect_spz_values(const gaussian_cloud& g, const spz_spec& s) {
  ASSERT_EQ(g.size(), 2u);
  ASSERT_EQ(g.sh_degree, s.degree);
  if (s.version == 1) {
    EXPECT_EQ(g.world(0), vec3d(1, -2, 0.5));
  } else {
    EXPECT_EQ(g.world(0), vec3d(1, -0.5, 1.5));
  }
  EXPECT_EQ(g.world(1), vec3d(0, 0, 0));
  EXPECT_NEAR(g.opacities[0], 0.2f, 1e-7f);
  EXPECT_NEAR(g.sh[0], 0.5 / 0.15, 1e-5);   // colour byte 255
  EXPECT_NEAR(g.sh[1], -0.5 / 0.15, 1e-5);  // colour byte 0
  EXPECT_NEAR(g.scales[0].x(), 1.0f, 1e-6f);
  EXPECT_NEAR(g.scales[0].y(), std::exp(1.0f), 1e-6f);
  EXPECT_NEAR(g.scales[0].z(), std::exp(-1.0f), 1e-6f);
  if (s.version >= 3) {
    EXPECT_EQ(g.rotations[0], vec4f(1, 0, 0, 0));
    EXPECT_NEAR(g.rotations[1][0], 0.0f, 1e-7f);
    EXPECT_NEAR(g.rotations[1][1], std::sqrt(0.5f), 1e-6f);
    EXPECT_NEAR(g.rotations[1][2], std::sqrt(0.5f), 1e-6f);
    EXPECT_NEAR(g.rotations[1][3], 0.0f, 1e-7f);
  } else {
    // 128 / 127.5 − 1 = 1/255: w = √(1 − 3/255²).
    const double e = 1.0 / 255;
    EXPECT_NEAR(g.rotations[0][0], std::sqrt(1 - 3 * e * e), 1e-6);
    EXPECT_NEAR(g.rotations[0][1], e, 1e-6);
    // Gaussian 1: x = 1, y = z = 1/255, w = 0; normalised by √(1 + 2/255²).
    const double len = std::sqrt(1 + 2 * e * e);
    EXPECT_NEAR(g.rotations[1][0], 0.0, 1e-7);
    EXPECT_NEAR(g.rotations[1][1], 1 / len, 1e-6);
    EXPECT_NEAR(g.rotations[1][2], e / len, 1e-6);
  }
  if (s.degree >= 1) {
    // Coefficient-major, RGB interleaved in the file too: every coefficient is (0.5, 0, −0.5).
    for (int k = 1; k < sh_coefficients(s.degree); ++k) {
      EXPECT_EQ(g.sh[g.sh_index(1, k, 0)], 0.5f);
      EXPECT_EQ(g.sh[g.sh_index(1, k, 1)], 0.0f);
      EXPECT_EQ(g.sh[g.sh_index(1, k, 2)], -0.5f);
    }
  }
  EXPECT_NO_THROW(g.validate());
}

using GaussianSpz = scratch_dir;

TEST_F(GaussianSpz, GzipVersionsOneToThreeEveryDegree) {
  for (std::uint32_t v : {1u, 2u, 3u})
    for (int d = 0; d <= 3; ++d) {
      SCOPED_TRACE(testing::Message() << "version " << v << " degree " << d);
      const spz_spec s{.version = v, .degree = d};
      const std::string p = write("a.spz", gzip(spz_header16(s) + spz_attributes(s)));
      read_report r;
      expect_spz_values(read_gaussians(p, &r), s);
      EXPECT_TRUE(r.warnings.empty());
    }
}

TEST_F(GaussianSpz, ZstdVersionFour) {
  for (int d = 0; d <= 3; ++d) {
    SCOPED_TRACE(d);
    const spz_spec s{.version = 4, .degree = d};
    expect_spz_values(read_gaussians(write("b.spz", spz_v4(s))), s);
  }
}

TEST_F(GaussianSpz, MalformedFilesGiveFormatErrors) {
  const spz_spec s{.version = 3, .degree = 1};
  const std::string data = spz_attributes(s);
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("m.spz", gzip(spz_header16(s, 0x12345678) + data))),
                           FormatError, "bad magic");
  spz_spec v5 = s;
  v5.version = 5;
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("v.spz", gzip(spz_header16(v5) + data))),
                           FormatError, "SPZ version 5 is not supported");
  spz_spec d4 = s;
  d4.degree = 4;
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("d.spz", gzip(spz_header16(d4) + data))),
                           FormatError, "SH degree 4");
  spz_spec lying = s;
  lying.count = 1000;  // the data holds 2
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("l.spz", gzip(spz_header16(lying) + data))),
                           FormatError, "truncated");
  spz_spec huge = s;
  huge.count = 4'000'000'000u;  // would need ~10¹¹ bytes: refused before allocating
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("h.spz", gzip(spz_header16(huge) + data))),
                           FormatError, "can hold");
  const std::string z = gzip(spz_header16(s) + data);
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("t.spz", z.substr(0, z.size() / 2))), FormatError,
                           "t.spz");
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("g.spz", "hello world")), FormatError,
                           "not an SPZ file");
  // Version 4: a lying table of contents, a cut file.
  spz_spec s4{.version = 4, .degree = 1};
  std::string f4 = spz_v4(s4);
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("c4.spz", f4.substr(0, f4.size() - 4))),
                           FormatError, "runs past the end");
  poke_le<std::uint64_t>(f4, 32 + 8, 1000);  // positions' uncompressed size
  PBR_LOD_EXPECT_THROW_MSG(read_gaussians(write("u4.spz", f4)), FormatError,
                           "uncompressed size 1000");
}

// --- files from another encoder
// -------------------------------------------------------------------

using GaussianFixtures = scratch_dir;

// PlayCanvas splat-transform's fixtures (tests/data/gaussians/PROVENANCE.md): 4 Gaussians on a
// 2 × 2 grid, i → (gx, gz) = (i % 2, i / 2), made from position (gx − 1, 0, gz − 1), scale 0.1,
// opacity 0.9, colour ((gx + 1)/3, (gz + 1)/3, 0.5) and the identity rotation.
TEST_F(GaussianFixtures, ReadWhatTheirSourceValuesSay) {
  const auto bytes = [](const unsigned char* b, unsigned n) {
    return std::string(reinterpret_cast<const char*>(b), n);
  };
  using namespace fixtures;
  const struct {
    const char* name;
    std::string data;
    bool stored_rub;  ///< packed from RDF: y and z negated in the file (read as stored)
  } files[] = {{"v2.spz", bytes(minimal_v2_spz, minimal_v2_spz_len), false},
               {"v3.spz", bytes(minimal_v3_spz, minimal_v3_spz_len), true},
               {"v4.spz", bytes(minimal_v4_spz, minimal_v4_spz_len), true},
               {"m.splat", bytes(minimal_splat, minimal_splat_len), false}};
  for (const auto& f : files) {
    SCOPED_TRACE(f.name);
    read_report r;
    const gaussian_cloud g = read_gaussians(write(f.name, f.data), &r);
    ASSERT_EQ(g.size(), 4u);
    EXPECT_EQ(r.points_read, 4u);
    EXPECT_TRUE(r.warnings.empty());
    EXPECT_NO_THROW(g.validate());
    const bool splat = std::string(f.name) == "m.splat";
    for (std::size_t i = 0; i < 4; ++i) {
      const double gx = static_cast<double>(i % 2), gz = static_cast<double>(i / 2);
      // Positions are exact: 12 (v3, v4) or 8 (v2) fractional bits, or floats.
      EXPECT_EQ(g.world(i), vec3d(gx - 1, 0, (f.stored_rub ? -1 : 1) * (gz - 1)));
      // Opacity 0.9 quantised to 230/255.
      EXPECT_NEAR(g.opacities[i], 230.0 / 255, 1e-6);
      // Scale 0.1: exact in .splat; SPZ's log byte round((ln 0.1 + 10)·16) = 123.
      const double s = splat ? 0.1 : std::exp(123.0 / 16 - 10);
      EXPECT_NEAR(g.scales[i].x(), s, 1e-6);
      EXPECT_EQ(g.scales[i].x(), g.scales[i].z());
      // Colour to within the 8-bit quantisation: .splat's step is 1/255; SPZ's 0.15·255 steps of
      // dc, i.e. C0 / 38.25 = 0.0074 of colour, rounded to half that.
      const vec3f c = g.base_colour(i);
      const float tol = splat ? 0.5f / 255 + 1e-6f : 0.0037f + 1e-6f;
      if (!splat && !f.stored_rub) {
        // v2 was packed by hand with the colour bytes round(255·(gx + 1)/3): decoded as SPZ
        // colour bytes, dc = (b/255 − 0.5)/0.15.
        EXPECT_NEAR(g.sh[g.sh_index(i, 0, 0)], (std::round(255 * (gx + 1) / 3) / 255 - 0.5) / 0.15,
                    1e-5);
      } else {
        EXPECT_NEAR(c.x(), (gx + 1) / 3, tol);
        EXPECT_NEAR(c.y(), (gz + 1) / 3, tol);
        EXPECT_NEAR(c.z(), 0.5, tol);
      }
      if (splat) {
        // Rotation bytes (128, 128, 128, 255): w x y z as (b − 128)/128 (antimatter15, also
        // PlayCanvas's reader: byte 28 is rot_0 = w) give (0, 0, 0, 127/128) → (0, 0, 0, 1), a
        // half turn about z. (The fixture's comment meant x y z w; the format is w first.)
        EXPECT_EQ(g.rotations[i], vec4f(0, 0, 0, 1));
      } else if (f.stored_rub) {
        EXPECT_EQ(g.rotations[i], vec4f(1, 0, 0, 0));  // smallest three, exact
      } else {
        EXPECT_NEAR(g.rotations[i][0], 1.0f, 1e-4f);  // x y z bytes 128: 1/255 each
        EXPECT_NEAR(g.rotations[i][1], 1.0f / 255, 1e-6f);
      }
    }
  }
}

// --- write → read
// ---------------------------------------------------------------------------------

gaussian_cloud random_cloud(int degree, std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1, 1), pos(0.5f, 1);
  gaussian_cloud g;
  g.origin = vec3d(100, -200, 1e6);
  g.sh_degree = degree;
  for (std::size_t i = 0; i < n; ++i) {
    g.positions.emplace_back(u(rng), u(rng), u(rng));
    g.scales.emplace_back(pos(rng), pos(rng) * 0.01f, pos(rng) * 10);
    g.rotations.push_back(vec4f(u(rng), u(rng), u(rng), u(rng)).normalized());
    g.opacities.push_back(pos(rng) - 0.5f);
    for (std::size_t j = 0; j < g.sh_stride(); ++j) g.sh.push_back(u(rng));
  }
  return g;
}

using GaussianWrite = scratch_dir;

TEST_F(GaussianWrite, RoundTripEveryDegree) {
  for (int d = 0; d <= 3; ++d) {
    SCOPED_TRACE(d);
    gaussian_cloud g = random_cloud(d, 50, 7 + static_cast<std::uint32_t>(d));
    g.opacities[0] = 1.0f;   // clamped to 1 − 10⁻⁷ on writing
    g.opacities[1] = 0.0f;   // and 10⁻⁷
    g.scales[2].x() = 0.0f;  // written as log(smallest denormal)
    const std::string p = path("rt.ply");
    write_gaussians_ply(g, p);
    const gaussian_cloud h = read_gaussians(p);
    ASSERT_EQ(h.size(), g.size());
    EXPECT_EQ(h.origin, g.origin);  // from the comment
    EXPECT_EQ(h.sh, g.sh);          // copied, only reordered
    for (std::size_t i = 0; i < g.size(); ++i) {
      // x y z are float world coordinates: 10⁶ + 1 has a float spacing of 1/16.
      EXPECT_NEAR((h.world(i) - g.world(i)).norm(), 0, 0.07);
      for (int a = 0; a < 3; ++a)
        EXPECT_NEAR(h.scales[i][a], g.scales[i][a], 1e-6 * g.scales[i][a] + 1e-40);
      EXPECT_NEAR(h.opacities[i], g.opacities[i], 2e-7);
      EXPECT_NEAR((h.rotations[i] - g.rotations[i]).norm(), 0, 2e-7);
    }
    EXPECT_NO_THROW(h.validate());
  }
}

TEST_F(GaussianWrite, TheFileIsTheStandardLayout) {
  // One Gaussian of degree 1 with f_rest recognisable: the bytes after the header are
  // x y z nx ny nz f_dc_0..2 f_rest_0..8 (channel-major) opacity scale_0..2 rot_0..3.
  gaussian_cloud g;
  g.sh_degree = 1;
  g.positions = {vec3f(1, 2, 3)};
  g.scales = {vec3f(1, 2, 4)};
  g.rotations = {vec4f(0, 1, 0, 0)};
  g.opacities = {0.5f};
  // coefficient k, channel c → 10·k + c
  for (int k = 0; k < 4; ++k)
    for (int c = 0; c < 3; ++c) g.sh.push_back(static_cast<float>(10 * k + c));
  const std::string p = path("one.ply");
  write_gaussians_ply(g, p);
  const std::string bytes = slurp(p);
  const std::size_t at = bytes.find("end_header\n") + 11;
  ASSERT_EQ(bytes.size() - at, 4u * (9 + 9 + 8));
  std::vector<float> v(26);
  std::memcpy(v.data(), bytes.data() + at, 4 * 26);
  const std::vector<float> want = {1,
                                   2,
                                   3,
                                   0,
                                   0,
                                   0,
                                   0,
                                   1,
                                   2,  // x..f_dc
                                   10,
                                   20,
                                   30,
                                   11,
                                   21,
                                   31,
                                   12,
                                   22,
                                   32,  // f_rest
                                   0,
                                   0,
                                   std::log(2.0f),
                                   std::log(4.0f),
                                   0,
                                   1,
                                   0,
                                   0};  // opacity..rot
  for (int k = 0; k < 26; ++k)
    EXPECT_NEAR(v[static_cast<std::size_t>(k)], want[static_cast<std::size_t>(k)], 1e-6) << k;
  // A hierarchy's merged opacity above 1 is written as 1 (a logit cannot exceed it); a
  // negative one is refused.
  gaussian_cloud merged = g;
  merged.opacities[0] = 2;
  write_gaussians_ply(merged, p);
  EXPECT_NEAR(read_gaussians(p).opacities[0], 1.0f, 1e-6);
  gaussian_cloud bad = g;
  bad.opacities[0] = -0.5f;
  EXPECT_THROW(write_gaussians_ply(bad, p), InvalidArgument);
}

// --- damaged files
// ----------------------------------------------------------------------------------

using GaussianDamage = scratch_dir;

// Every prefix and random byte flips of a valid file of each format: each must read into a
// cloud that passes validate() or throw a pbr_lod::Error; never crash or throw anything else
// (tests/io/mutation_test.cpp does the same for the mesh and point readers).
TEST_F(GaussianDamage, EveryCutAndFlipReadsOrThrows) {
  const spz_spec s3{.version = 3, .degree = 2};
  const spz_spec s4{.version = 4, .degree = 1};
  const float pos[3] = {1, 2, 3}, scale[3] = {0.5f, 1, 2};
  const std::uint8_t rgba[4] = {1, 2, 3, 4}, rot[4] = {200, 100, 128, 128};
  const std::vector<std::pair<std::string, std::string>> files = {
      {"a.ply", make_gs_ply({sample_row(2), sample_row(2)}, standard_props(2))},
      {"b.ply", make_gs_ply({sample_row(1)}, standard_props(1), true)},
      {"c.splat", splat_record(pos, scale, rgba, rot) + splat_record(scale, pos, rgba, rot)},
      {"d.spz", gzip(spz_header16(s3) + spz_attributes(s3))},
      {"e.spz", spz_v4(s4)}};
  std::mt19937 rng(42);  // any flips will do: each file must survive all of them
  std::size_t read = 0, refused = 0;
  const auto attempt = [&](const std::string& name, const std::string& bytes) {
    const std::string p = write(name, bytes);
    try {
      read_gaussians(p).validate();
      ++read;
    } catch (const InvalidArgument& e) {
      ADD_FAILURE() << name << ": a cloud that fails validate(): " << e.what();
    } catch (const Error&) {
      ++refused;
    }
  };
  for (const auto& [name, bytes] : files) {
    for (std::size_t n = 0; n < bytes.size(); ++n) attempt(name, bytes.substr(0, n));
    for (int k = 0; k < 100; ++k) {
      std::string b = bytes;
      for (int f = 0; f < 3; ++f) b[rng() % b.size()] = static_cast<char>(rng() & 0xff);
      attempt(name, b);
    }
  }
  EXPECT_GT(read, 0u);
  EXPECT_GT(refused, 0u);
}

}  // namespace
}  // namespace pbr_lod::test
