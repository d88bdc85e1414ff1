# Quantised normals (encode/decode), and the k-NN normal + splat-ellipse estimation.
pbr_lod_add_benchmark(bench_core ${CMAKE_CURRENT_LIST_DIR}/core_benchmark.cpp)
# Estimation against its peers: CGAL's normal estimation and k-d tree in an object library of its
# own so that CGAL's compile options (-frounding-math) stay on that file; nanoflann (header-only,
# Debian's libnanoflann-dev) for the k-NN comparison.
add_library(bench_estimation_cgal OBJECT ${CMAKE_CURRENT_LIST_DIR}/estimation_cgal_benchmark.cpp)
target_link_libraries(bench_estimation_cgal PRIVATE CGAL::CGAL TBB::tbb pbr_lod::pbr_lod
                      benchmark::benchmark pbr_lod_warnings)
target_compile_definitions(bench_estimation_cgal PRIVATE CGAL_LINKED_WITH_TBB
                           PBR_LOD_DATA_DIR="${PBR_LOD_DATA_DIR}")
target_include_directories(bench_estimation_cgal PRIVATE ${PROJECT_SOURCE_DIR}/tests)
pbr_lod_add_benchmark(bench_estimation ${CMAKE_CURRENT_LIST_DIR}/estimation_benchmark.cpp
                      $<TARGET_OBJECTS:bench_estimation_cgal>)
target_link_libraries(bench_estimation PRIVATE $<LINK_ONLY:CGAL::CGAL> TBB::tbb)
