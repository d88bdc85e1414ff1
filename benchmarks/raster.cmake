# Rasteriser throughput (points, splats, triangles per second) and the cost of each effect.
pbr_lod_add_benchmark(bench_raster raster_benchmark.cpp)
