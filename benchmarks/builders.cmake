foreach(id IN LISTS PBR_LOD_BUILDERS)  # cmake/builders.cmake: bench_ID from ID_benchmark.cpp
  pbr_lod_add_benchmark(bench_${id} ${CMAKE_CURRENT_LIST_DIR}/${id}_benchmark.cpp)
endforeach()
# PCA octree; CGAL's hierarchy_simplify_point_set in an object library of its own so that CGAL's
# compile options (-frounding-math) stay on that file (find_package(CGAL) ran in
# src/core/estimation.cmake).
add_library(bench_pca_octree_cgal OBJECT ${CMAKE_CURRENT_LIST_DIR}/pca_octree_cgal_benchmark.cpp)
target_link_libraries(bench_pca_octree_cgal PRIVATE CGAL::CGAL pbr_lod::pbr_lod benchmark::benchmark
                      pbr_lod_warnings)
target_include_directories(bench_pca_octree_cgal PRIVATE ${PROJECT_SOURCE_DIR}/tests)
target_sources(bench_pca_octree PRIVATE $<TARGET_OBJECTS:bench_pca_octree_cgal>)
target_link_libraries(bench_pca_octree PRIVATE $<LINK_ONLY:CGAL::CGAL>)
# PMR; its peer, CGAL's Delaunay_triangulation_3 of the whole input (sequential and parallel
# with TBB), in an object library of its own for the same reason.
add_library(bench_pmr_cgal OBJECT ${CMAKE_CURRENT_LIST_DIR}/pmr_cgal_benchmark.cpp)
target_link_libraries(bench_pmr_cgal PRIVATE CGAL::CGAL TBB::tbb pbr_lod::pbr_lod
                      benchmark::benchmark pbr_lod_warnings)
target_compile_definitions(bench_pmr_cgal PRIVATE CGAL_LINKED_WITH_TBB)
target_sources(bench_pmr PRIVATE $<TARGET_OBJECTS:bench_pmr_cgal>)
# CGAL's concurrent containers allocate with TBB's scalable allocator (the peer only).
target_link_libraries(bench_pmr PRIVATE $<LINK_ONLY:CGAL::CGAL> TBB::tbb TBB::tbbmalloc)
