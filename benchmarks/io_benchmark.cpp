// Reading throughput of the real files in shared/data (read_mesh / read_points, end to end:
// file into memory, parse, validate, drop non-finite points, convert to float-relative), plus
// a write_ply + read round trip of the bunny in both PLY encodings.
// Counters: points/s (vertices or points read per second) and MB/s of file.
#include <benchmark/benchmark.h>

#include <filesystem>

#include "pbr_lod/io/read.hpp"
#include "pbr_lod/io/write.hpp"
#include "support/data.hpp"

namespace {

void set_counters(benchmark::State& state, const std::string& path, std::size_t points) {
  const double bytes = static_cast<double>(std::filesystem::file_size(path));
  state.counters["points/s"] =
      benchmark::Counter(static_cast<double>(points) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["MB/s"] = benchmark::Counter(bytes * static_cast<double>(state.iterations()) / 1e6,
                                              benchmark::Counter::kIsRate);
}

void read_mesh_file(benchmark::State& state, const char* name) {
  const std::string path = pbr_lod::test::data_file(name);
  pbr_lod::read_report report;
  for (auto _ : state) {
    auto m = pbr_lod::read_mesh(path, &report);
    benchmark::DoNotOptimize(m.faces.data());
  }
  set_counters(state, path, report.points_read);
}

void read_points_file(benchmark::State& state, const char* name) {
  const std::string path = pbr_lod::test::data_file(name);
  pbr_lod::read_report report;
  for (auto _ : state) {
    auto c = pbr_lod::read_points(path, &report);
    benchmark::DoNotOptimize(c.positions.data());
  }
  set_counters(state, path, report.points_read);
}

// The bunny written by write_ply (binary or ASCII) and read back: our PLY parser on its own
// output, the format the tool's intermediate files use.
void read_written_ply(benchmark::State& state, bool binary) {
  const auto mesh = pbr_lod::read_mesh(pbr_lod::test::data_file("bun_zipper.ply"));
  const std::string path =
      (std::filesystem::temp_directory_path() /
       (std::string("pbr_lod_bench_bunny_") + (binary ? "bin" : "ascii") + ".ply"))
          .string();
  pbr_lod::write_ply(path, mesh, binary);
  for (auto _ : state) {
    auto m = pbr_lod::read_mesh(path);
    benchmark::DoNotOptimize(m.faces.data());
  }
  set_counters(state, path, mesh.num_vertices());
  std::filesystem::remove(path);
}

void write_bunny(benchmark::State& state, bool binary) {
  const auto mesh = pbr_lod::read_mesh(pbr_lod::test::data_file("bun_zipper.ply"));
  const std::string path =
      (std::filesystem::temp_directory_path() / "pbr_lod_bench_write.ply").string();
  for (auto _ : state) pbr_lod::write_ply(path, mesh, binary);
  set_counters(state, path, mesh.num_vertices());
  std::filesystem::remove(path);
}

BENCHMARK_CAPTURE(read_mesh_file, bun_zipper_ply_ascii, "bun_zipper.ply")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(read_mesh_file, bun_zipper_res4_ply_ascii, "bun_zipper_res4.ply")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(read_mesh_file, happy_vrip_res3_ply_ascii, "happy_vrip_res3.ply")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(read_mesh_file, cow_obj_openmesh, "cow.obj")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(read_points_file, milk_pcd_binary_compressed, "milk_cartoon_all_small_clorox.pcd")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(read_points_file, las_1_2_format3, "1.2-with-color.las")
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(read_written_ply, bunny_binary_le, true)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(read_written_ply, bunny_ascii, false)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(write_bunny, binary_le, true)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(write_bunny, ascii, false)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
