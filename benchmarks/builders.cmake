pbr_lod_add_benchmark(bench_point_octree ${CMAKE_CURRENT_LIST_DIR}/point_octree_benchmark.cpp)
pbr_lod_add_benchmark(bench_pop ${CMAKE_CURRENT_LIST_DIR}/pop_benchmark.cpp)
pbr_lod_add_benchmark(bench_rho_grid ${CMAKE_CURRENT_LIST_DIR}/rho_grid_benchmark.cpp)
pbr_lod_add_benchmark(bench_pmr ${CMAKE_CURRENT_LIST_DIR}/pmr_benchmark.cpp)
