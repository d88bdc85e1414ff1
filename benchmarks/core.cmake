# Quantised normals (encode/decode) and k-NN normal + splat-ellipse estimation throughput.
pbr_lod_add_benchmark(bench_core ${CMAKE_CURRENT_LIST_DIR}/core_benchmark.cpp)
