# PMR builder (Dey & Hudson 2002): the octree, gathering and assembly in pmr_build.cpp and the
# file format in pmr_io.cpp; CGAL's Delaunay_triangulation_3 (poles, vertex removal, umbrellas)
# only in pmr_voronoi.cpp, compiled as its own object library so CGAL's usage requirements
# (-frounding-math, Boost/GMP) stay on that one file (as pop.cmake). core/estimation.cmake has
# already run find_package(CGAL) and linked GMP/MPFR into pbr_lod.
add_library(pbr_lod_pmr_cgal OBJECT ${CMAKE_CURRENT_LIST_DIR}/pmr_voronoi.cpp)
set_target_properties(pbr_lod_pmr_cgal PROPERTIES POSITION_INDEPENDENT_CODE ON CXX_EXTENSIONS OFF)
target_compile_features(pbr_lod_pmr_cgal PRIVATE cxx_std_20)
target_include_directories(pbr_lod_pmr_cgal PRIVATE ${PROJECT_SOURCE_DIR}/include)
target_link_libraries(pbr_lod_pmr_cgal PRIVATE CGAL::CGAL Eigen3::Eigen pbr_lod_warnings)

target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/pmr_build.cpp
               ${CMAKE_CURRENT_LIST_DIR}/pmr_io.cpp $<TARGET_OBJECTS:pbr_lod_pmr_cgal>)
# The chunked (out-of-core) build and the lazily opened directory it writes.
target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/chunked_pmr_build.cpp
               ${CMAKE_CURRENT_LIST_DIR}/chunked_pmr.cpp)
