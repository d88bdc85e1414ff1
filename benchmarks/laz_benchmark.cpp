// LAZ throughput (src/io/laz_decoder.cpp, laz_layered.cpp): points per second decoded from the
// file's bytes in memory into LAS records, every chunk in parallel on all cores (the figure of
// issue 44: ≥ 5 M points/s on 2 cores), read_points end to end (file read, decode, LAS record
// parsing, float conversion), and the encoder (issue 44: ≥ 2 M points/s), the file's records
// compressed again into its chunks.
//
// Inputs: PBR_LOD_LAZ_BENCH, a colon-separated list of LAZ files (real data: PDAL's
// test/data/laz/autzen_trim.laz, 110 000 points in 3 chunks; its ept/source/lone-star.laz,
// 518 862 points in 11), and always a synthetic file: the committed twin tests/data/laz/simple.laz
// (format 3) with its one chunk of 1065 points repeated 400 times (laz_test_util.hpp) — real
// LASzip output, but chunks 47 times shorter than LASzip's default, so the per-chunk setup of the
// models weighs more than in real files.
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "io/laz_decoder.hpp"
#include "io/laz_encoder.hpp"
#include "io/laz_test_util.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pbr_lod/io/read.hpp"
#include "support/data.hpp"

namespace {

namespace detail = pbr_lod::detail;

std::string slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void set_points(benchmark::State& state, std::uint64_t points) {
  state.counters["points/s"] =
      benchmark::Counter(static_cast<double>(points) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["points"] = static_cast<double>(points);
}

/// The decoder alone: chunks of the in-memory file into records, on every core.
void decode_chunks(benchmark::State& state, const std::string& path) {
  const std::string bytes = slurp(path);
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  pbr_lod::read_report r;
  const detail::las_header h = detail::parse_las_header(path, b, bytes.size(), r);
  const detail::laz_fetch fetch = [&](std::uint64_t at, std::size_t n, unsigned char* out) {
    std::memcpy(out, b + at, n);
  };
  const detail::laz_layout L = detail::read_laz_layout(path, h, bytes.size(), fetch);
  std::vector<unsigned char> records(static_cast<std::size_t>(h.count * h.record_length));
  for (auto _ : state) {
    detail::decode_laz_chunks(path, L, 0, L.chunks.size(), fetch, records.data());
    benchmark::DoNotOptimize(records.data());
  }
  state.counters["chunks"] = static_cast<double>(L.chunks.size());
  set_points(state, h.count);
}

/// The encoder: the file's records, decoded once, compressed again chunk by chunk as the file
/// has them, every chunk in parallel.
void encode_chunks(benchmark::State& state, const std::string& path) {
  const std::string bytes = slurp(path);
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  pbr_lod::read_report r;
  const detail::las_header h = detail::parse_las_header(path, b, bytes.size(), r);
  const detail::laz_fetch fetch = [&](std::uint64_t at, std::size_t n, unsigned char* out) {
    std::memcpy(out, b + at, n);
  };
  const detail::laz_layout L = detail::read_laz_layout(path, h, bytes.size(), fetch);
  std::vector<unsigned char> records(static_cast<std::size_t>(h.count * h.record_length));
  detail::decode_laz_chunks(path, L, 0, L.chunks.size(), fetch, records.data());
  std::vector<std::vector<unsigned char>> out(L.chunks.size());
  for (auto _ : state) {
    pbr_lod::detail::parallel_tasks(
        L.chunks.size(), pbr_lod::resolve_threads(0), [&](std::size_t k, unsigned) {
          const detail::laz_chunk& c = L.chunks[k];
          const unsigned char* rec = records.data() + c.first * L.record_length;
          out[k] = L.format >= 6
                       ? detail::encode_layered_chunk(L.format, L.record_length, rec, c.count)
                       : detail::encode_pointwise_chunk(L.format, L.record_length, rec, c.count);
        });
    benchmark::DoNotOptimize(out.data());
  }
  set_points(state, h.count);
}

void read_points_laz(benchmark::State& state, const std::string& path) {
  pbr_lod::read_report report;
  for (auto _ : state) {
    auto c = pbr_lod::read_points(path, &report);
    benchmark::DoNotOptimize(c.positions.data());
  }
  set_points(state, report.points_read);
}

std::string synthetic() {
  const std::string p =
      (std::filesystem::temp_directory_path() / "pbr_lod_bench_simple_x400.laz").string();
  const std::string laz = pbr_lod::test::laz_repeat_chunk(
      slurp(pbr_lod::test::repository_file("laz/simple.laz")), 400, false);
  std::ofstream(p, std::ios::binary).write(laz.data(), static_cast<std::streamsize>(laz.size()));
  return p;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::pair<std::string, std::string>> files = {{"simple_x400", synthetic()}};
  if (const char* env = std::getenv("PBR_LOD_LAZ_BENCH")) {
    std::stringstream list(env);
    for (std::string p; std::getline(list, p, ':');)
      if (!p.empty()) files.emplace_back(std::filesystem::path(p).stem().string(), p);
  }
  for (const auto& [name, path] : files) {
    benchmark::RegisterBenchmark(("decode_laz/" + name).c_str(), decode_chunks, path)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("read_points_laz/" + name).c_str(), read_points_laz, path)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("encode_laz/" + name).c_str(), encode_chunks, path)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::filesystem::remove(files.front().second);
  return 0;
}
