// Damaged hierarchy files, one standard for every format (issue 21): a tiny hierarchy of each
// builder is saved, then
//  * cut at every byte offset: load() throws FormatError;
//  * a byte flipped (XOR 0xFF), one at a time: load() throws FormatError (the checksum, or a
//    check before it);
//  * the same flips with the checksum resealed, so the parser's own checks are what stands
//    between the damage and the caller: magic and version bytes are still a FormatError; any
//    other byte gives a FormatError or a hierarchy that saves and loads again (a flipped bound or
//    colour can be a valid file). Whether anything is read out of bounds on the way is what the
//    ASan + UBSan pass of scripts/test.sh checks.
//  * each aligned 32-bit word of the head set to 0xFFFFFFFF (a count of 2³² − 1), resealed:
//    FormatError or a valid file, and the load's peak memory stays small (a reader checks a
//    count against the file's size before the count sizes anything).
// The files are small (< 10 kB) so every cut is tried; flips try every byte of the first 256 (the
// head of every format) and 256 spread over the rest.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <iterator>
#include <string>
#include <tuple>
#include <type_traits>
#include <vector>

#include "all_builder_tests.hpp"  // generated: tests/builders/CMakeLists.txt
#include "pbr_lod/core/binary.hpp"
#include "pbr_lod/core/synthetic.hpp"

namespace pbr_lod {
namespace {

using test::bytes_t;
using test::format_case;

/// In /dev/shm (RAM) when there is one: the test writes ~20 000 small files, and on a busy disk
/// each costs milliseconds in the file system rather than microseconds in the loader. Named by
/// process too: ctest runs the tests of one format in parallel processes.
std::string scratch_path(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::is_directory("/dev/shm")
                                        ? std::filesystem::path("/dev/shm")
                                        : std::filesystem::temp_directory_path();
  return (dir / ("pbr_lod_file_damage_" + std::to_string(::getpid()) + "_" + name)).string();
}

/// The bytes a flip test tries: all of the first 256 (every format's head: magic, version,
/// flags, origin, bounds, options, counts) and 256 spread over the rest, ending before the
/// checksum's 8 bytes when `skip_checksum`.
std::vector<std::size_t> flip_positions(std::size_t size, bool skip_checksum) {
  const std::size_t end = skip_checksum ? size - 8 : size;
  std::vector<std::size_t> at;
  for (std::size_t i = 0; i < std::min<std::size_t>(end, 256); ++i) at.push_back(i);
  if (end > 256) {
    const std::size_t step = std::max<std::size_t>(1, (end - 256) / 256);
    for (std::size_t i = 256; i < end; i += step) at.push_back(i);
  }
  return at;
}

/// Every file format of every registered builder (tests/builders/adapters/ID.hpp).
std::vector<format_case> all_formats() {
  std::vector<format_case> all;
  [&all]<class... Tests>(std::type_identity<std::tuple<Tests...>>) {
    (std::ranges::copy(Tests::formats(), std::back_inserter(all)), ...);
  }(std::type_identity<test::all_builder_tests>{});
  return all;
}

void write(const std::string& path, const bytes_t& b) {
  detail::save_file_bytes(path, b);
}

/// b with its last 8 bytes set to the FNV-1a checksum of the rest, as save() ends every file.
bytes_t resealed(bytes_t b) {
  const std::uint64_t sum = detail::fnv1a(b.data(), b.size() - 8);
  std::memcpy(b.data() + b.size() - 8, &sum, 8);
  return b;
}

class FileDamage : public ::testing::TestWithParam<format_case> {
 protected:
  void SetUp() override {
    in_ = scratch_path(GetParam().name + ".lod");
    out_ = scratch_path(GetParam().name + "_out.lod");
    good_ = GetParam().make(in_);
    // The undamaged file loads: the errors below come from the damage, not from the setup.
    ASSERT_NO_THROW(GetParam().load_and_save(in_, out_));
    ASSERT_GT(good_.size(), 20u);
    ASSERT_LT(good_.size(), 10000u) << "keep the input tiny: every cut is tried";
  }
  void TearDown() override {
    std::filesystem::remove(in_);
    std::filesystem::remove(out_);
  }
  /// Loads `b`; true when load() threw a FormatError, false when it loaded. Anything else fails.
  bool rejected(const bytes_t& b) {
    write(in_, b);
    try {
      GetParam().load_and_save(in_, out_);
    } catch (const FormatError&) {
      return true;
    }
    return false;
  }
  std::string in_, out_;
  bytes_t good_;
};

TEST_P(FileDamage, CutAtEveryOffsetIsFormatError) {
  for (std::size_t len = 0; len < good_.size(); ++len)
    EXPECT_TRUE(rejected(bytes_t(good_.begin(), good_.begin() + std::ptrdiff_t(len))))
        << "cut at " << len << " of " << good_.size();
}

TEST_P(FileDamage, FlippedByteIsFormatError) {
  for (const std::size_t i : flip_positions(good_.size(), false)) {
    bytes_t b = good_;
    b[i] ^= 0xFF;
    EXPECT_TRUE(rejected(b)) << "byte " << i << " of " << good_.size() << " flipped";
  }
}

/// This process's peak resident memory (VmHWM) in bytes, or 0 where /proc does not say.
std::size_t peak_rss_bytes() {
  std::ifstream f("/proc/self/status");
  std::string key;
  while (f >> key) {
    if (key == "VmHWM:") {
      std::size_t kb = 0;
      f >> kb;
      return kb * 1024;
    }
    f.ignore(1 << 12, '\n');
  }
  return 0;
}

/// Resets VmHWM to the current resident size (Linux ≥ 4.0); false where that is not possible.
bool reset_peak_rss() {
  std::ofstream f("/proc/self/clear_refs");
  f << "5";
  f.flush();
  return static_cast<bool>(f);
}

// Found by fuzz_pmr: a leaf count of ~2³¹ sized a 2.3 GB table before the file's length was
// checked. Every 32-bit word of each format's head set to 2³² − 1 in turn must be refused (or
// read as a valid file) without the load's peak memory growing by more than 64 MB.
TEST_P(FileDamage, MaximalCountsAllocateNothingLarge) {
  if (!reset_peak_rss() || peak_rss_bytes() == 0) GTEST_SKIP() << "no /proc/self/clear_refs";
  const std::size_t end = std::min<std::size_t>(good_.size() - 8, 256);
  for (std::size_t i = 12; i + 4 <= end; i += 4) {
    bytes_t b = good_;
    std::memset(b.data() + i, 0xFF, 4);
    b = resealed(b);
    write(in_, b);
    ASSERT_TRUE(reset_peak_rss());
    const std::size_t before = peak_rss_bytes();
    try {
      GetParam().load_and_save(in_, out_);
    } catch (const FormatError&) {
    }
    const std::size_t grew = peak_rss_bytes() - before;
    EXPECT_LT(grew, std::size_t{64} << 20)
        << "word at byte " << i << ": the load's peak memory grew by " << (grew >> 20) << " MB";
  }
}

TEST_P(FileDamage, FlippedByteWithResealedChecksumIsCheckedByTheParser) {
  constexpr std::size_t head = 12;  // magic (8) and version (4): every format starts with them
  std::size_t accepted = 0;
  const auto at = flip_positions(good_.size(), true);
  for (const std::size_t i : at) {
    bytes_t b = good_;
    b[i] ^= 0xFF;
    const bool r = rejected(resealed(b));
    if (i < head) {
      EXPECT_TRUE(r) << "magic/version byte " << i << " flipped and accepted";
    }
    if (r) continue;
    ++accepted;
    // Loaded: what it saved must load again (the loader let nothing through that save() or a
    // second load() would choke on).
    const std::string again = out_ + ".again";
    EXPECT_NO_THROW(GetParam().load_and_save(out_, again)) << "byte " << i;
    std::filesystem::remove(again);
  }
  // Not asserted (a flipped float can be a valid file); printed so a change in what the parser
  // catches shows in the log.
  std::cout << GetParam().name << ": " << accepted << " of " << at.size()
            << " resealed single-byte flips load\n";
}

INSTANTIATE_TEST_SUITE_P(AllFormats, FileDamage, ::testing::ValuesIn(all_formats()),
                         [](const auto& p) { return p.param.name; });

}  // namespace
}  // namespace pbr_lod
