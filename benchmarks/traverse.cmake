pbr_lod_add_benchmark(bench_traverse ${CMAKE_CURRENT_LIST_DIR}/traverse_benchmark.cpp)
