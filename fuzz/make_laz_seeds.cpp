// Writes the seed corpus of fuzz_laz (docs/fuzzing.md): small LAZ files, one per point format
// 0–10, each a few chunks of a few points, so that a mutation reaches the LAZ decoder's every
// item (POINT10, GPSTIME11, RGB12, WAVEPACKET13, BYTE; POINT14, RGB14, RGBNIR14, WAVEPACKET14,
// BYTE14) and its chunk table within 4 kB, at thousands of executions a second. The committed
// LAZ twins (tests/data/laz, 9–34 kB) are too large for that: a campaign's 4 kB cut ends inside
// their first chunk, and reading one whole costs ~8 ms under ASan.
//
//   make_laz_seeds TWINS_DIR OUT_DIR
//
// Each seed is a LAS twin's first 24 records — formats 0, 1, 2, 3 (also with 27 extra bytes) and
// 6 as they are; 4 and 5 from 1 and 3 with a waveform packet appended; 7, 8, 9 and 10 from 6 with
// RGB, NIR and packets — compressed by the library's own writer (detail::encode_laz_file) in
// chunks of 8 points.
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <stdexcept>
#include <string>
#include <vector>

#include "io/laz_encoder.hpp"
#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/io/read.hpp"

namespace {

std::string slurp(const std::string& path) {
  const std::vector<unsigned char> b = pbr_lod::detail::load_file_bytes(path);
  return {b.begin(), b.end()};
}

template <class T>
T peek(const std::string& b, std::size_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof(T));
  return v;
}

template <class T>
void poke(std::string& b, std::size_t at, T v) {
  std::memcpy(b.data() + at, &v, sizeof(T));
}

/// Fills the bytes a target format adds after a record's first `from` bytes: RGB (and NIR) from
/// the record's coordinates so that colours change from point to point, then a waveform packet
/// whose offset runs on from the last packet's end, with a jump now and then.
void fill_added(unsigned source, unsigned target, std::size_t i, const char* rec, std::size_t from,
                char* out, std::size_t rl, std::uint64_t& wave_offset) {
  const auto has_rgb = [](unsigned f) {
    return f == 2 || f == 3 || f == 5 || f == 7 || f == 8 || f == 10;
  };
  std::size_t at = from;
  const bool colour = has_rgb(target) && !has_rgb(source);
  const bool nir = target == 8 || target == 10;
  const bool wave = target == 4 || target == 5 || target == 9 || target == 10;
  for (int c = 0; colour && c < 3 + (nir ? 1 : 0); ++c, at += 2) {
    const auto v = static_cast<std::uint16_t>(static_cast<unsigned char>(rec[c * 4]) * 257 + i);
    std::memcpy(out + at, &v, 2);
  }
  if (wave) {
    const std::uint32_t size = 4968;
    wave_offset += i % 5 == 4 ? 1000003 : size;
    out[at] = static_cast<char>(1 + i % 3);
    std::memcpy(out + at + 1, &wave_offset, 8);
    std::memcpy(out + at + 9, &size, 4);
    const float xyz_t[4] = {540000.0f + static_cast<float>(i % 17), 1e-5f,
                            -2.8e-5f * static_cast<float>(i % 5), 1.4e-4f};
    std::memcpy(out + at + 13, xyz_t, 16);
    at += 29;
  }
  if (at != rl)
    throw std::logic_error("make_laz_seeds: record length of format " + std::to_string(target));
}

/// The LAS file `las` cut to its first `n` records, as point format `target` with records of
/// `rl` bytes (the twin's bytes first, fill_added's after them); a LAS 1.4 file keeps its EVLRs.
std::string small_las(const std::string& las, std::size_t n, unsigned target, std::uint16_t rl) {
  const auto offset = peek<std::uint32_t>(las, 96);
  const auto source = static_cast<unsigned char>(las[104]);
  const auto from = peek<std::uint16_t>(las, 105);
  const bool v14 = las[25] >= 4;
  const std::uint64_t count = v14 ? peek<std::uint64_t>(las, 247) : peek<std::uint32_t>(las, 107);
  if (count < n) throw std::runtime_error("make_laz_seeds: twin has fewer points than a seed");
  std::string out = las.substr(0, offset);
  out[104] = static_cast<char>(target);
  poke<std::uint16_t>(out, 105, rl);
  poke<std::uint32_t>(out, 107, v14 && target >= 6 ? 0u : static_cast<std::uint32_t>(n));
  std::string rec(rl, '\0');
  std::uint64_t wave_offset = 60;
  for (std::size_t i = 0; i < n; ++i) {
    const char* src = las.data() + offset + i * from;
    std::memcpy(rec.data(), src, from);
    fill_added(source, target, i, src, from, rec.data(), rl, wave_offset);
    out += rec;
  }
  if (v14) {
    poke<std::uint64_t>(out, 247, n);
    const auto evlr = peek<std::uint64_t>(las, 235);
    if (evlr != 0) {
      poke<std::uint64_t>(out, 235, out.size());
      out += las.substr(evlr);
    }
  }
  return out;
}

void write(const std::string& path, const std::string& bytes) {
  pbr_lod::write_file_atomically(path, bytes.data(), bytes.size());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: make_laz_seeds TWINS_DIR OUT_DIR\n";
    return 2;
  }
  const std::string twins = argv[1], out = argv[2];
  struct seed {
    const char* twin;
    unsigned format;
    std::uint16_t record_length;
  };
  const seed seeds[] = {{"point10", 0, 20},    {"point-time", 1, 28},  {"point-color", 2, 26},
                        {"simple", 3, 34},     {"extra-bytes", 3, 61}, {"point-time", 4, 57},
                        {"simple", 5, 63},     {"1_4_w_evlr", 6, 30},  {"1_4_w_evlr", 7, 36},
                        {"1_4_w_evlr", 8, 38}, {"1_4_w_evlr", 9, 59},  {"1_4_w_evlr", 10, 67}};
  try {
    for (const seed& s : seeds) {
      const std::string name = std::string(s.twin) + "_f" + std::to_string(s.format);
      const std::string las =
          small_las(slurp(twins + "/" + s.twin + ".las"), 24, s.format, s.record_length);
      const std::string laz = pbr_lod::detail::encode_laz_file(name, las, 8);
      const std::string path = out + "/laz_" + name + ".las";
      write(path, laz);
      // A seed the reader refuses would fuzz only the refusal: each must read as its LAS does.
      const std::string plain = out + "/.plain_" + name + ".las";
      write(plain, las);
      const pbr_lod::point_cloud a = pbr_lod::read_points(path), b = pbr_lod::read_points(plain);
      std::remove(plain.c_str());
      if (a.positions.size() != 24 || a.positions != b.positions || a.colours != b.colours)
        throw std::runtime_error(path + ": does not read as the LAS it encodes");
    }
  } catch (const std::exception& e) {
    std::cerr << "make_laz_seeds: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
