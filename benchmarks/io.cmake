# Reading throughput of the real files in shared/data (and write_ply).
pbr_lod_add_benchmark(bench_io io_benchmark.cpp)
