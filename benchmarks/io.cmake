# Reading throughput of the real files in shared/data (and write_ply).
pbr_lod_add_benchmark(bench_io io_benchmark.cpp)
# LAZ decoding (points/s on every core); reads src/io/laz_decoder.hpp and the committed twins,
# and real files named in PBR_LOD_LAZ_BENCH.
pbr_lod_add_benchmark(bench_laz laz_benchmark.cpp)
target_include_directories(bench_laz PRIVATE ${PROJECT_SOURCE_DIR}/src)
