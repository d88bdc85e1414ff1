// LAZ decoding against real files written by other tools: twins holding the same points as LAS
// and as LAZ (tests/data/laz/PROVENANCE.md). Every decoded record must equal the LAS record byte
// for byte — intensity, return bits, classification, GPS time, colour and extra bytes, not only
// the positions read_points keeps — and read_points and the streaming point source must give
// for the LAZ exactly what they give for the LAS. Files of several chunks are made from a real
// one-chunk file by repeating its chunk under a chunk table we encode (the twins are small, so
// each is one chunk); damaged chunks and tables must give a FormatError naming what is wrong.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <tuple>

#include "io/laz_codec.hpp"
#include "io/laz_decoder.hpp"
#include "io/laz_encoder.hpp"
#include "io_test_util.hpp"
#include "laz_test_util.hpp"
#include "pbr_lod/io/point_source_file.hpp"
#include "pbr_lod/io/read.hpp"
#include "support/data.hpp"

namespace {

using pbr_lod::FormatError;
using pbr_lod::read_points;
using pbr_lod::detail::cat;
using pbr_lod::test::fetch_from;
using pbr_lod::test::header_of;
using pbr_lod::test::layout_of;
using pbr_lod::test::laz_records;
using pbr_lod::test::poke_le;
using pbr_lod::test::put_le;
using pbr_lod::test::slurp;
namespace detail = pbr_lod::detail;

using Laz = pbr_lod::test::scratch_dir;

std::string twin(const std::string& name) {
  return pbr_lod::test::repository_file("laz/" + name);
}

template <class T>
T peek_le(const std::string& b, std::size_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof(T));
  return v;
}

/// The records of the LAS file at `path`, as stored.
std::string las_records(const std::string& path) {
  const std::string bytes = slurp(path);
  const detail::las_header h = header_of(path, bytes);
  return bytes.substr(h.data_offset, static_cast<std::size_t>(h.count * h.record_length));
}

/// The whole cloud from a point source, read in blocks of `block` points.
pbr_lod::point_cloud stream(const std::string& path, std::size_t block) {
  const auto src = pbr_lod::open_point_source(path);
  pbr_lod::point_cloud c;
  c.origin = src->origin();
  pbr_lod::point_block b;
  for (std::uint64_t first = 0; first < src->size(); first += block) {
    src->read(first, static_cast<std::size_t>(std::min<std::uint64_t>(block, src->size() - first)),
              b);
    c.positions.insert(c.positions.end(), b.positions.begin(), b.positions.end());
    c.colours.insert(c.colours.end(), b.colours.begin(), b.colours.end());
  }
  return c;
}

void expect_same_cloud(const pbr_lod::point_cloud& a, const pbr_lod::point_cloud& b,
                       const std::string& what) {
  EXPECT_EQ(a.origin, b.origin) << what;
  EXPECT_EQ(a.positions, b.positions) << what;
  EXPECT_EQ(a.colours, b.colours) << what;
}

/// Index of the first differing record (for a readable failure), or -1.
long first_difference(const std::string& a, const std::string& b, std::size_t record_length) {
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    if (a[i] != b[i]) return static_cast<long>(i / record_length);
  return a.size() == b.size() ? -1
                              : static_cast<long>(std::min(a.size(), b.size()) / record_length);
}

struct twin_case {
  const char* name;
  unsigned format;
  unsigned record_length;
  std::uint64_t points;
};
// point10, point-time, point-color, extra-bytes: laz-rs's test set (LASzip 2.2); simple: PDAL's
// (LASzip 3.4). Formats 0–3; extra-bytes has 27 extra bytes per record (a BYTE item).
const twin_case twins[] = {{"point10", 0, 20, 1065},
                           {"point-time", 1, 28, 1065},
                           {"point-color", 2, 26, 1065},
                           {"simple", 3, 34, 1065},
                           {"extra-bytes", 3, 61, 1065}};

// The heart of it: the decoder gives the LAS records, every byte of every field.
TEST(LazTwins, RecordsEqualTheLasRecordsByteForByte) {
  for (const twin_case& t : twins) {
    const std::string laz = twin(std::string(t.name) + ".laz");
    const std::string las = twin(std::string(t.name) + ".las");
    const std::string bytes = slurp(laz);
    const detail::las_header h = header_of(laz, bytes);
    EXPECT_TRUE(h.compressed) << t.name;
    EXPECT_EQ(h.format, t.format) << t.name;
    EXPECT_EQ(h.record_length, t.record_length) << t.name;
    EXPECT_EQ(h.count, t.points) << t.name;
    const std::string got = laz_records(laz), want = las_records(las);
    ASSERT_EQ(got.size(), want.size()) << t.name;
    EXPECT_EQ(first_difference(got, want, t.record_length), -1) << t.name << ": first bad record";
  }
}

TEST(LazTwins, ReadPointsGivesTheLasCloud) {
  for (const twin_case& t : twins) {
    pbr_lod::read_report rz, rs;
    const auto z = read_points(twin(std::string(t.name) + ".laz"), &rz);
    const auto s = read_points(twin(std::string(t.name) + ".las"), &rs);
    ASSERT_EQ(z.size(), t.points) << t.name;
    expect_same_cloud(z, s, t.name);
    EXPECT_EQ(rz.points_read, rs.points_read) << t.name;
    EXPECT_EQ(rz.warnings.size(), rs.warnings.size()) << t.name;
  }
}

// Blocks of 7 start reads inside the chunk; blocks of 4096 cover it whole.
TEST(LazTwins, PointSourceGivesWhatReadPointsGives) {
  for (const twin_case& t : twins) {
    const std::string laz = twin(std::string(t.name) + ".laz");
    const auto whole = read_points(laz);
    for (const std::size_t block : {std::size_t{7}, std::size_t{4096}})
      expect_same_cloud(stream(laz, block), whole, cat(t.name, " in blocks of ", block));
  }
}

// --- files of several chunks ------------------------------------------------------------------

/// The LAZ twin `name` with its chunk repeated `copies` times (laz_test_util.hpp), and the LAS
/// twin with its records repeated to match.
std::pair<std::string, std::string> repeat_chunk(const std::string& name, std::uint32_t copies,
                                                 bool variable) {
  const std::string laz =
      pbr_lod::test::laz_repeat_chunk(slurp(twin(name + ".laz")), copies, variable);
  const std::string las = slurp(twin(name + ".las"));
  const detail::las_header hs = header_of(name, las);
  std::string las_out = las.substr(0, hs.data_offset);
  pbr_lod::test::las_multiply_count(las_out, copies);
  const std::string records = las_records(twin(name + ".las"));
  for (std::uint32_t i = 0; i < copies; ++i) las_out += records;
  return {laz, las_out};
}

TEST_F(Laz, SeveralFixedChunks) {
  const auto [laz, las] = repeat_chunk("simple", 3, false);
  const std::string zp = write("three.laz", laz), sp = write("three.las", las);
  EXPECT_EQ(layout_of(zp, laz).chunks.size(), 3u);
  EXPECT_EQ(first_difference(laz_records(zp), las_records(sp), 34), -1);
  const auto whole = read_points(zp);
  ASSERT_EQ(whole.size(), 3u * 1065u);
  expect_same_cloud(whole, read_points(sp), "read_points");
  for (const std::size_t block : {std::size_t{7}, std::size_t{1000}, std::size_t{5000}})
    expect_same_cloud(stream(zp, block), whole, cat("blocks of ", block));
}

TEST_F(Laz, SeveralVariableChunksWithExtraBytes) {
  const auto [laz, las] = repeat_chunk("extra-bytes", 4, true);
  const std::string zp = write("four.laz", laz), sp = write("four.las", las);
  const detail::laz_layout L = layout_of(zp, laz);
  ASSERT_EQ(L.chunks.size(), 4u);
  EXPECT_EQ(L.chunks[3].first, 3u * 1065u);
  EXPECT_EQ(L.chunks[3].count, 1065u);
  EXPECT_EQ(first_difference(laz_records(zp), las_records(sp), 61), -1);
  expect_same_cloud(read_points(zp), read_points(sp), "read_points");
  expect_same_cloud(stream(zp, 333), read_points(sp), "blocks of 333");
}

TEST_F(Laz, SeveralLayeredChunks) {
  for (const bool variable : {false, true}) {
    const auto [laz, las] = repeat_chunk("1_4_w_evlr", 3, variable);
    const std::string zp = write("six.laz", laz), sp = write("six.las", las);
    EXPECT_EQ(layout_of(zp, laz).chunks.size(), 3u);
    EXPECT_EQ(first_difference(laz_records(zp), las_records(sp), 30), -1);
    const auto whole = read_points(zp);
    ASSERT_EQ(whole.size(), 3000u);
    expect_same_cloud(whole, read_points(sp), "read_points");
    expect_same_cloud(stream(zp, 7), whole, "blocks of 7");
  }
}

/// A record's fields of LAS formats 3 and 7 that both have, with the position in world units
/// (the two files differ in offset), for comparing the same points in another order.
using las_fields = std::tuple<std::int64_t, std::int64_t, std::int64_t, int, int, int, int, int,
                              int, std::uint64_t, int, int, int>;
std::vector<las_fields> fields_of(const std::string& path) {
  const std::string bytes = slurp(path);
  const detail::las_header h = header_of(path, bytes);
  const std::string recs = h.compressed ? laz_records(path) : las_records(path);
  std::vector<las_fields> out;
  for (std::size_t i = 0; i < h.count; ++i) {
    const char* r = recs.data() + i * h.record_length;
    const auto u8 = [&](int at) { return static_cast<int>(static_cast<unsigned char>(r[at])); };
    const auto u16 = [&](int at) {
      return static_cast<int>(peek_le<std::uint16_t>(recs, i * h.record_length + at));
    };
    const auto world = [&](int a) {  // in units of the 0.01 scale both files use
      const double w =
          peek_le<std::int32_t>(recs, i * h.record_length + 4 * a) * h.scale[a] + h.offset[a];
      return static_cast<std::int64_t>(std::llround(w * 100.0));
    };
    const bool f14 = h.format >= 6;
    const int returns = f14 ? u8(14) : (u8(14) & 7) | ((u8(14) >> 3) & 7) << 4;
    const int cls = f14 ? u8(16) : u8(15) & 31;
    const int user = f14 ? u8(17) : u8(17);
    const int source = f14 ? u16(20) : u16(18);
    const auto gps = peek_le<std::uint64_t>(recs, i * h.record_length + (f14 ? 22 : 20));
    const int rgb = f14 ? 30 : 28;
    out.emplace_back(world(0), world(1), world(2), u16(12), returns, cls, user, source, 0, gps,
                     u16(rgb), u16(rgb + 2), u16(rgb + 4));
  }
  std::sort(out.begin(), out.end());
  return out;
}

// COPC (PDAL's simple.las as a COPC file, laspy's copy): LAS 1.4 format 7 in 65 variable chunks,
// the points reordered by octree node. Every field both formats have equals the LAS twin's, as
// a multiset; read_points gives the same cloud up to order.
TEST(LazTwins, CopcFormat7HoldsTheLasPointsInAnotherOrder) {
  const std::string copc = twin("simple.copc.laz");
  EXPECT_EQ(layout_of(copc, slurp(copc)).chunks.size(), 65u);
  EXPECT_EQ(layout_of(copc, slurp(copc)).chunk_size, 0xFFFFFFFFu);
  EXPECT_TRUE(fields_of(copc) == fields_of(twin("simple.las")));
  const auto sorted = [](const pbr_lod::point_cloud& c) {
    std::vector<std::tuple<float, float, float, int, int, int>> v;
    for (std::size_t i = 0; i < c.size(); ++i)
      v.emplace_back(c.positions[i].x(), c.positions[i].y(), c.positions[i].z(), c.colours[i].r,
                     c.colours[i].g, c.colours[i].b);
    std::sort(v.begin(), v.end());
    return v;
  };
  const auto z = read_points(copc), s = read_points(twin("simple.las"));
  EXPECT_EQ(z.origin, s.origin);
  EXPECT_TRUE(sorted(z) == sorted(s));
  expect_same_cloud(stream(copc, 7), z, "blocks of 7");
}

// A streaming writer that could not seek back leaves −1 where the chunk table's offset belongs
// and appends the offset as the file's last 8 bytes.
TEST_F(Laz, ChunkTableOffsetAtTheEnd) {
  std::string laz = slurp(twin("point-time.laz"));
  const detail::las_header h = header_of("t", laz);
  const auto table_at = peek_le<std::int64_t>(laz, h.data_offset);
  poke_le<std::int64_t>(laz, h.data_offset, -1);
  put_le<std::int64_t>(laz, table_at);
  expect_same_cloud(read_points(write("end.laz", laz)), read_points(twin("point-time.las")),
                    "offset at the end");
}

// A LAZ file whose name says .las (or the reverse) reads by its format byte.
TEST_F(Laz, TheFormatByteDecidesNotTheExtension) {
  const std::string laz = slurp(twin("point-color.laz"));
  const std::string las = slurp(twin("point-color.las"));
  expect_same_cloud(read_points(write("z.las", laz)), read_points(twin("point-color.las")),
                    "LAZ named .las");
  expect_same_cloud(read_points(write("s.laz", las)), read_points(twin("point-color.las")),
                    "LAS named .laz");
}

// --- damage: the intact file reads first (a reader refusing everything passes no test below)

class LazDamage : public Laz {
 protected:
  void SetUp() override {
    Laz::SetUp();
    std::tie(good_, std::ignore) = repeat_chunk("simple", 3, false);
    ASSERT_EQ(read_points(write("good.laz", good_)).size(), 3u * 1065u);
    h_ = header_of("good", good_);
    L_ = layout_of("good", good_);
    table_at_ = static_cast<std::size_t>(peek_le<std::int64_t>(good_, h_.data_offset));
  }
  /// read_points and open_point_source of `bytes` both throw a FormatError containing `what`.
  void expect_format_error(const std::string& bytes, const std::string& what) {
    const std::string p = write("bad.laz", bytes);
    PBR_LOD_EXPECT_THROW_MSG(read_points(p), FormatError, what);
    PBR_LOD_EXPECT_THROW_MSG((void)stream(p, 100), FormatError, what);
  }
  std::string good_;
  detail::las_header h_;
  detail::laz_layout L_;
  std::size_t table_at_ = 0;
};

// The middle chunk's bytes cut to half, the rest moved up and the table re-pointed: its stream
// runs out long before its 1065 points.
TEST_F(LazDamage, TruncatedChunk) {
  const detail::laz_chunk& c = L_.chunks[1];
  const std::size_t cut = static_cast<std::size_t>(c.bytes / 2);
  std::string bad = good_;
  bad.erase(static_cast<std::size_t>(c.offset) + cut, static_cast<std::size_t>(c.bytes) - cut);
  // Re-encode the table with the shorter size, at its new place.
  const std::size_t table_at = table_at_ - (static_cast<std::size_t>(c.bytes) - cut);
  bad.resize(table_at);
  poke_le<std::int64_t>(bad, h_.data_offset, static_cast<std::int64_t>(table_at));
  put_le<std::uint32_t>(bad, 0);
  put_le<std::uint32_t>(bad, 3);
  std::vector<unsigned char> coded;
  detail::laz::range_encoder enc(coded);
  detail::laz::integer_codec ic(32, 2);
  std::int32_t prev = 0;
  for (int i = 0; i < 3; ++i) {
    const auto bytes = static_cast<std::int32_t>(i == 1 ? cut : L_.chunks[0].bytes);
    ic.encode(enc, prev, bytes, 1);
    prev = bytes;
  }
  enc.done();
  bad.append(coded.begin(), coded.end());
  expect_format_error(bad, "chunk 1: damaged or truncated");
}

// Bytes of a chunk's stream overwritten: the decoder never reads outside the chunk; whatever it
// decodes, read_points gives points or a FormatError, never a crash (run under ASan in CI).
TEST_F(LazDamage, OverwrittenChunkBytesStayInBounds) {
  std::mt19937 rng(7);
  const detail::laz_chunk& c = L_.chunks[2];
  std::uniform_int_distribution<std::size_t> where(
      static_cast<std::size_t>(c.offset) + 34, static_cast<std::size_t>(c.offset + c.bytes) - 1);
  for (int k = 0; k < 20; ++k) {
    std::string bad = good_;
    for (int i = 0; i < 8; ++i) bad[where(rng)] = static_cast<char>(rng());
    try {
      const auto cloud = read_points(write("flip.laz", bad));
      EXPECT_EQ(cloud.size(), 3u * 1065u);
    } catch (const FormatError&) {
    }
  }
}

TEST_F(LazDamage, ChunkTableVersion) {
  std::string bad = good_;
  poke_le<std::uint32_t>(bad, table_at_, 1);
  expect_format_error(bad, "chunk table: version 1 (expected 0)");
}

TEST_F(LazDamage, ChunkTableOffsetOutsideTheFile) {
  std::string bad = good_;
  poke_le<std::int64_t>(bad, h_.data_offset, static_cast<std::int64_t>(bad.size() + 100));
  expect_format_error(bad, "chunk table: offset");
  poke_le<std::int64_t>(bad, h_.data_offset, 12);  // inside the header
  expect_format_error(bad, "is not inside the file");
}

TEST_F(LazDamage, ChunkTableCountDisagreesWithThePoints) {
  std::string bad = good_;
  poke_le<std::uint32_t>(bad, table_at_ + 4, 2);
  expect_format_error(bad, "2 chunks, but 3195 points in chunks of 1065 make 3");
}

// The coded sizes cut off: the table's stream ends before its third chunk.
TEST_F(LazDamage, ChunkTableTruncated) {
  expect_format_error(good_.substr(0, table_at_ + 9), "chunk table");
}

// The file cut inside the chunks: the table offset now points past the end.
TEST_F(LazDamage, FileCutInsideTheChunks) {
  expect_format_error(good_.substr(0, static_cast<std::size_t>(L_.chunks[2].offset) + 10),
                      "is not inside the file");
}

TEST_F(LazDamage, NoLaszipVlr) {
  std::string bad = good_;
  const auto at = bad.find("laszip encoded");
  ASSERT_NE(at, std::string::npos);
  bad[at] = 'X';
  expect_format_error(bad, "none of the 1 VLRs is LASzip's");
}

TEST_F(LazDamage, UnsupportedCompressorAndItems) {
  const std::size_t vlr = good_.find("laszip encoded") - 2 + 54;  // the VLR's payload
  std::string bad = good_;
  poke_le<std::uint16_t>(bad, vlr, 1);
  expect_format_error(bad, "point-wise compression without chunks (LASzip 1.x)");
  bad = good_;
  poke_le<std::uint16_t>(bad, vlr + 34 + 6 * 1 + 4, 1);  // GPSTIME11 version 1
  expect_format_error(bad, "item GPSTIME11 has compressor version 1");
  bad = good_;
  poke_le<std::uint16_t>(bad, vlr + 34 + 6 * 2, 11);  // RGB14 in a format 3 file
  expect_format_error(bad, "do not describe point format 3 with 34-byte records");
}

// The layered format's chunk header: its own point count and the sizes of its layers.
TEST_F(Laz, DamagedLayeredChunkHeader) {
  const std::string good = slurp(twin("1_4_w_evlr.laz"));
  ASSERT_EQ(read_points(write("good.laz", good)).size(), 1000u);
  const auto chunk = static_cast<std::size_t>(layout_of("good", good).chunks[0].offset);
  std::string bad = good;
  poke_le<std::uint32_t>(bad, chunk + 30, 999);  // after the raw 30-byte record
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("count.laz", bad)), FormatError,
                           "chunk 0: holds 999 points, the chunk table says 1000");
  bad = good;
  poke_le<std::uint32_t>(bad, chunk + 34, 1u << 30);  // the xy layer's size
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("layer.laz", bad)), FormatError,
                           "chunk 0: its layers need");
  bad = good;
  poke_le<std::uint32_t>(bad, chunk + 34, peek_le<std::uint32_t>(good, chunk + 34) / 2);
  poke_le<std::uint32_t>(bad, chunk + 38,
                         peek_le<std::uint32_t>(good, chunk + 38) +
                             peek_le<std::uint32_t>(good, chunk + 34) -
                             peek_le<std::uint32_t>(good, chunk + 34) / 2);
  // The xy layer cut to half (the z layer takes the rest): its stream runs out.
  PBR_LOD_EXPECT_THROW_MSG(read_points(write("xy.laz", bad)), FormatError, "chunk 0: damaged");
}

// Cuts at every length through the header, VLRs and first chunk, then spread over the file, and
// random bytes anywhere: a FormatError or points, never anything else.
TEST_F(LazDamage, CutsAndRandomBytes) {
  const auto read_or_error = [&](const std::string& bytes, const std::string& label) {
    const std::string p = write("m.laz", bytes);
    try {
      read_points(p).validate();
      (void)stream(p, 500);
    } catch (const pbr_lod::Error&) {
    } catch (const std::exception& e) {
      ADD_FAILURE() << label << ": " << e.what();
    }
  };
  const std::size_t n = good_.size();
  for (std::size_t len = 0; len < n; len += (len < 600 ? 7 : n / 150))
    read_or_error(good_.substr(0, len), cat("cut at ", len));
  std::mt19937 rng(42);
  std::uniform_int_distribution<std::size_t> where(0, n - 1);
  for (int k = 0; k < 150; ++k) {
    std::string bad = good_;
    for (int c = 0; c <= k % 4; ++c) bad[where(rng)] = static_cast<char>(rng());
    read_or_error(bad, cat("mutation ", k));
  }
}

}  // namespace

// --- the encoder's half: LAS 1.4 layered chunks -----------------------------------------------

namespace {

/// The decoded records of chunk k of the LAZ file in `bytes`.
std::vector<unsigned char> chunk_records(const std::string& path, const std::string& bytes,
                                         const detail::laz_layout& L, std::size_t k) {
  const detail::laz_chunk& c = L.chunks[k];
  std::vector<unsigned char> rec(static_cast<std::size_t>(c.count * L.record_length));
  detail::decode_laz_chunk(
      path, L, k, reinterpret_cast<const unsigned char*>(bytes.data()) + c.offset, rec.data());
  return rec;
}

/// Records compressed by us and decoded again.
std::vector<unsigned char> round_trip(const detail::laz_layout& L,
                                      const std::vector<unsigned char>& rec) {
  const std::uint64_t count = rec.size() / L.record_length;
  const std::vector<unsigned char> chunk =
      detail::encode_layered_chunk(L.format, L.record_length, rec.data(), count);
  detail::laz_layout one = L;
  one.chunks = {detail::laz_chunk{0, count, 0, chunk.size()}};
  std::vector<unsigned char> back(rec.size());
  detail::decode_laz_chunk("round trip", one, 0, chunk.data(), back.data());
  return back;
}

}  // namespace

// Our encoder run on the records LASzip compressed gives LASzip's chunks back, byte for byte:
// the same models, contexts, predictions and choices (formats 6 and 7; the layered chunks of
// the COPC file are 65, of 3 to 100 points).
TEST(LazEncode, LayeredChunksAreLaszipsByteForByte) {
  for (const char* name : {"1_4_w_evlr.laz", "simple.copc.laz"}) {
    const std::string path = twin(name);
    const std::string bytes = slurp(path);
    const detail::laz_layout L = layout_of(path, bytes);
    for (std::size_t k = 0; k < L.chunks.size(); ++k) {
      const detail::laz_chunk& c = L.chunks[k];
      const std::vector<unsigned char> rec = chunk_records(path, bytes, L, k);
      const std::vector<unsigned char> ours =
          detail::encode_layered_chunk(L.format, L.record_length, rec.data(), c.count);
      EXPECT_EQ(std::string(ours.begin(), ours.end()),
                bytes.substr(static_cast<std::size_t>(c.offset), static_cast<std::size_t>(c.bytes)))
          << name << " chunk " << k;
    }
  }
}

// What LASzip's files do not exercise: records moving between the four scanner channels (each
// with its own contexts, a new one seeded from the channel before), format 8's NIR and extra
// bytes, fields that change in some records only. Encoded and decoded, every byte comes back.
TEST(LazEncode, RoundTripAcrossScannerChannelsFormat8AndExtraBytes) {
  const std::string path = twin("1_4_w_evlr.laz");
  const std::string bytes = slurp(path);
  const detail::laz_layout L6 = layout_of(path, bytes);
  const std::vector<unsigned char> rec6 = chunk_records(path, bytes, L6, 0);
  std::mt19937 rng(5);  // any records must round-trip; a seed makes a failure reproducible
  detail::laz_layout L8 = L6;
  L8.format = 8;
  L8.record_length = 30 + 6 + 2 + 3;
  const std::size_t n = rec6.size() / 30;
  std::vector<unsigned char> rec8(n * L8.record_length);
  for (std::size_t i = 0; i < n; ++i) {
    unsigned char* r = rec8.data() + i * L8.record_length;
    std::memcpy(r, rec6.data() + i * 30, 30);
    if (i > n / 3) r[15] = static_cast<unsigned char>((r[15] & 0xCF) | ((rng() % 4) << 4));
    for (int b = 30; b < 38; ++b)
      r[b] = static_cast<unsigned char>(i % 97 < 50 ? r[b % 12] : rng());
    r[38] = 7;                                   // an extra byte that never changes
    r[39] = static_cast<unsigned char>(i / 10);  // one that changes now and then
    r[40] = static_cast<unsigned char>(rng());
  }
  EXPECT_TRUE(round_trip(L8, rec8) == rec8);
  // Format 6 with the channels mixed, one record at a time and in short runs.
  std::vector<unsigned char> mixed = rec6;
  for (std::size_t i = 0; i < n; ++i)
    mixed[i * 30 + 15] =
        static_cast<unsigned char>((mixed[i * 30 + 15] & 0xCF) | (((i / 7) % 4) << 4));
  EXPECT_TRUE(round_trip(L6, mixed) == mixed);
}

// A whole LAS 1.4 file written as LAZ by us: it reads back to the LAS file's cloud and records;
// its one chunk is LASzip's; its EVLR moves with it; in chunks of 300 points it reads the same,
// also in blocks.
TEST_F(Laz, EncodedFileReadsBackAsItsLas) {
  const std::string las_path = twin("1_4_w_evlr.las");
  const std::string las = slurp(las_path);
  const std::string ours = detail::encode_laz_file(las_path, las);
  const std::string zp = write("ours.laz", ours);
  EXPECT_EQ(first_difference(laz_records(zp), las_records(las_path), 30), -1);
  expect_same_cloud(read_points(zp), read_points(las_path), "read_points");
  const detail::laz_layout L = layout_of(zp, ours);
  const std::string theirs = slurp(twin("1_4_w_evlr.laz"));
  const detail::laz_layout T = layout_of("theirs", theirs);
  ASSERT_EQ(L.chunks.size(), 1u);
  EXPECT_EQ(ours.substr(static_cast<std::size_t>(L.chunks[0].offset),
                        static_cast<std::size_t>(L.chunks[0].bytes)),
            theirs.substr(static_cast<std::size_t>(T.chunks[0].offset),
                          static_cast<std::size_t>(T.chunks[0].bytes)));
  // The EVLR (its 60-byte header and payload) at the offset the header now gives.
  const auto las_evlr = static_cast<std::size_t>(peek_le<std::uint64_t>(las, 235));
  const auto our_evlr = static_cast<std::size_t>(peek_le<std::uint64_t>(ours, 235));
  EXPECT_EQ(ours.substr(our_evlr), las.substr(las_evlr));

  const std::string small = detail::encode_laz_file(las_path, las, 300);
  const std::string sp = write("small.laz", small);
  EXPECT_EQ(layout_of(sp, small).chunks.size(), 4u);
  expect_same_cloud(read_points(sp), read_points(las_path), "chunks of 300");
  expect_same_cloud(stream(sp, 7), read_points(las_path), "chunks of 300, blocks of 7");
  EXPECT_EQ(first_difference(laz_records(sp), las_records(las_path), 30), -1);

  PBR_LOD_EXPECT_THROW_MSG((void)detail::encode_laz_file("z", ours), FormatError, "already LAZ");
}

// The point-wise encoder (formats 0–3) on the records of every LAS twin: as a whole file it gives
// LASzip's chunk byte for byte, and reads back to the LAS file's records and cloud.
TEST_F(Laz, PointwiseFilesAreLaszipsChunksAndReadBack) {
  for (const char* name : {"point10", "point-time", "point-color", "simple", "extra-bytes"}) {
    const std::string las_path = twin(std::string(name) + ".las");
    const std::string ours = detail::encode_laz_file(las_path, slurp(las_path));
    const std::string zp = write("ours.laz", ours);
    const detail::laz_layout L = layout_of(zp, ours);
    const std::string theirs = slurp(twin(std::string(name) + ".laz"));
    const detail::laz_layout T = layout_of("theirs", theirs);
    ASSERT_EQ(L.chunks.size(), 1u) << name;
    EXPECT_EQ(ours.substr(static_cast<std::size_t>(L.chunks[0].offset),
                          static_cast<std::size_t>(L.chunks[0].bytes)),
              theirs.substr(static_cast<std::size_t>(T.chunks[0].offset),
                            static_cast<std::size_t>(T.chunks[0].bytes)))
        << name;
    const detail::las_header h = header_of(zp, ours);
    EXPECT_EQ(first_difference(laz_records(zp), las_records(las_path), h.record_length), -1)
        << name;
    expect_same_cloud(read_points(zp), read_points(las_path), name);
  }
  // Several chunks: 1065 points in chunks of 100.
  const std::string las_path = twin("extra-bytes.las");
  const std::string small = detail::encode_laz_file(las_path, slurp(las_path), 100);
  const std::string sp = write("small.laz", small);
  EXPECT_EQ(layout_of(sp, small).chunks.size(), 11u);
  EXPECT_EQ(first_difference(laz_records(sp), las_records(las_path), 61), -1);
  expect_same_cloud(stream(sp, 7), read_points(las_path), "chunks of 100, blocks of 7");
}

// The layered files (LAS 1.4 format 6, and COPC's 65 variable chunks) cut and with random bytes:
// points or a FormatError, never anything else (under ASan in CI: nothing read out of bounds).
TEST_F(Laz, LayeredCutsAndRandomBytes) {
  std::mt19937 rng(11);
  for (const char* name : {"1_4_w_evlr.laz", "simple.copc.laz"}) {
    const std::string good = slurp(twin(name));
    ASSERT_GT(read_points(write("good.laz", good)).size(), 0u) << name;
    const auto read_or_error = [&](const std::string& bytes, const std::string& label) {
      const std::string p = write("m.laz", bytes);
      try {
        read_points(p).validate();
        (void)stream(p, 300);
      } catch (const pbr_lod::Error&) {
      } catch (const std::exception& e) {
        ADD_FAILURE() << name << ", " << label << ": " << e.what();
      }
    };
    const std::size_t n = good.size();
    for (std::size_t len = 0; len < n; len += n / 120)
      read_or_error(good.substr(0, len), cat("cut at ", len));
    std::uniform_int_distribution<std::size_t> where(0, n - 1);
    for (int k = 0; k < 120; ++k) {
      std::string bad = good;
      for (int c = 0; c <= k % 4; ++c) bad[where(rng)] = static_cast<char>(rng());
      read_or_error(bad, cat("mutation ", k));
    }
  }
}

// The formats with waveform packets (4, 5: WAVEPACKET13 v1 point-wise; 9, 10: WAVEPACKET14 v3
// layered) have no twin here. Outside the suite, laspy's fullwave.laz (format 10, 10 750 points)
// re-encodes to LASzip's bytes exactly. Here: records built from the twins with packets whose
// offsets run on (the last packet's end), jump (a 32-bit difference, a raw 64-bit offset) or
// repeat, encoded and decoded back, byte for byte; and a format 5 LAS file through the writer.
TEST_F(Laz, WaveformPacketsRoundTrip) {
  std::mt19937 rng(3);
  const auto packet = [&](std::size_t i, unsigned char* w, std::uint64_t& offset) {
    const std::uint32_t size = 4968;
    const int kind = static_cast<int>(rng() % 10);
    if (kind == 0)
      offset += 1000003;  // a 32-bit jump
    else if (kind == 1)
      offset = (std::uint64_t{rng()} << 33) | rng();  // a raw offset
    else if (kind > 3)
      offset += size;  // the last packet's end
    w[0] = static_cast<unsigned char>(1 + (i / 100) % 3);
    std::memcpy(w + 1, &offset, 8);
    std::memcpy(w + 9, &size, 4);
    const float f[4] = {540000.0f + static_cast<float>(i % 17), 1e-5f,
                        -2.8e-5f * static_cast<float>(i % 5), 1.4e-4f};
    std::memcpy(w + 13, f, 16);
  };
  // Formats 4 and 5 from the format 1 and 3 twins (the packet after GPS time / RGB).
  for (const auto& [twin_name, format, from_rl, wave_at] :
       {std::tuple<const char*, unsigned, std::size_t, std::size_t>{"point-time", 4, 28, 28},
        std::tuple<const char*, unsigned, std::size_t, std::size_t>{"simple", 5, 34, 34}}) {
    const std::string src = las_records(twin(std::string(twin_name) + ".las"));
    const std::size_t n = src.size() / from_rl, rl = from_rl + 29;
    std::vector<unsigned char> rec(n * rl);
    std::uint64_t offset = 60;
    for (std::size_t i = 0; i < n; ++i) {
      std::memcpy(rec.data() + i * rl, src.data() + i * from_rl, from_rl);
      packet(i, rec.data() + i * rl + wave_at, offset);
    }
    const std::vector<unsigned char> chunk =
        detail::encode_pointwise_chunk(format, static_cast<std::uint16_t>(rl), rec.data(), n);
    detail::laz_layout one;
    one.format = format;
    one.record_length = static_cast<std::uint16_t>(rl);
    one.chunks = {detail::laz_chunk{0, n, 0, chunk.size()}};
    std::vector<unsigned char> back(rec.size());
    detail::decode_laz_chunk("round trip", one, 0, chunk.data(), back.data());
    EXPECT_TRUE(back == rec) << "format " << format;
  }
  // Formats 9 and 10 from the format 6 twin, the channels mixed.
  const std::string path = twin("1_4_w_evlr.laz");
  const std::string bytes = slurp(path);
  const detail::laz_layout L6 = layout_of(path, bytes);
  const std::vector<unsigned char> rec6 = chunk_records(path, bytes, L6, 0);
  for (const unsigned format : {9u, 10u}) {
    detail::laz_layout L = L6;
    L.format = format;
    L.record_length = static_cast<std::uint16_t>(format == 9 ? 59 : 67);
    const std::size_t wave_at = format == 9 ? 30 : 38;
    const std::size_t n = rec6.size() / 30;
    std::vector<unsigned char> rec(n * L.record_length);
    std::uint64_t offset = 60;
    for (std::size_t i = 0; i < n; ++i) {
      unsigned char* r = rec.data() + i * L.record_length;
      std::memcpy(r, rec6.data() + i * 30, 30);
      r[15] = static_cast<unsigned char>((r[15] & 0xCF) | (((i / 50) % 4) << 4));
      for (std::size_t b = 30; b < wave_at; ++b) r[b] = static_cast<unsigned char>(i * b);
      packet(i, r + wave_at, offset);
    }
    EXPECT_TRUE(round_trip(L, rec) == rec) << "format " << format;
  }
  // A format 5 LAS file through the writer reads back as the LAS does.
  pbr_lod::test::las_spec f5;
  f5.format = 5;
  f5.record_length = 63;
  f5.xyz = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  f5.rgb = {{1, 2, 3}, {4, 5, 6}, {7, 8, 9}};
  const std::string las = pbr_lod::test::make_las(f5);
  const std::string zp = write("f5.laz", detail::encode_laz_file("f5", las));
  expect_same_cloud(read_points(zp), read_points(write("f5.las", las)), "format 5 file");
}

// The integer compressor at its edges: correctors of every bit length k (0, 1, the k ≤ 8 symbol
// path, the k > 8 high-symbol + raw-bits path up to 31, and k = 32, which only INT_MIN reaches),
// 16-bit values wrapping around their range, several contexts; and raw bits of every width
// (read_bits splits widths above 19). What is encoded decodes to itself.
TEST(LazCoder, IntegerCompressorEdges) {
  std::vector<std::int32_t> values = {0,
                                      1,
                                      -1,
                                      2,
                                      -2,
                                      255,
                                      256,
                                      -256,
                                      65535,
                                      65536,
                                      -65536,
                                      std::numeric_limits<std::int32_t>::max(),
                                      std::numeric_limits<std::int32_t>::min()};
  for (int k = 1; k < 31; ++k) values.push_back((1 << k) + 1), values.push_back(-(1 << k) - 1);
  std::vector<unsigned char> bytes;
  detail::laz::range_encoder enc(bytes);
  detail::laz::integer_codec ic32(32, 3), ic16(16, 2);
  std::int32_t prev = 0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    ic32.encode(enc, prev, values[i], static_cast<std::uint32_t>(i % 3));
    ic16.encode(enc, prev & 0xFFFF, values[i] & 0xFFFF, static_cast<std::uint32_t>(i % 2));
    enc.write_bits(
        static_cast<std::uint32_t>(1 + i % 32),
        static_cast<std::uint32_t>(values[i]) & (i % 32 == 31 ? ~0u : (1u << (1 + i % 32)) - 1));
    prev = values[i];
  }
  enc.done();
  detail::laz::byte_source in(bytes.data(), bytes.size());
  detail::laz::range_decoder dec(in);
  detail::laz::integer_codec dc32(32, 3), dc16(16, 2);
  prev = 0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    EXPECT_EQ(dc32.decode(dec, prev, static_cast<std::uint32_t>(i % 3)), values[i]) << i;
    EXPECT_EQ(dc16.decode(dec, prev & 0xFFFF, static_cast<std::uint32_t>(i % 2)),
              values[i] & 0xFFFF)
        << i;
    const std::uint32_t bits = static_cast<std::uint32_t>(1 + i % 32);
    EXPECT_EQ(dec.read_bits(bits),
              static_cast<std::uint32_t>(values[i]) & (bits == 32 ? ~0u : (1u << bits) - 1))
        << i;
    prev = values[i];
  }
  EXPECT_EQ(in.overrun(), 0u);  // done() pads the stream for the decoder's reads
}
