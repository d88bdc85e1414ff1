# POP builder (Chen & Nguyen 2001): the stages in pop_adjacency.cpp (OpenMesh), pop_build.cpp and
# pop_spheres.cpp (pop_build_state.hpp says which does what), the file format in pop_io.cpp
# (OpenMeshCore is linked PRIVATE at the top level); CGAL's
# Min_sphere_of_spheres_d in pop_min_sphere.cpp, compiled as its own object library so CGAL's
# usage requirements (-frounding-math, Boost/GMP) stay in that one file (as core/estimation.cmake).
# core/estimation.cmake has already run find_package(CGAL) and linked GMP/MPFR into pbr_lod.
add_library(pbr_lod_pop_cgal OBJECT ${CMAKE_CURRENT_LIST_DIR}/pop_min_sphere.cpp)
set_target_properties(pbr_lod_pop_cgal PROPERTIES POSITION_INDEPENDENT_CODE ON CXX_EXTENSIONS OFF)
target_compile_features(pbr_lod_pop_cgal PRIVATE cxx_std_20)
target_include_directories(pbr_lod_pop_cgal PRIVATE ${PROJECT_SOURCE_DIR}/include)
target_link_libraries(pbr_lod_pop_cgal PRIVATE CGAL::CGAL Eigen3::Eigen pbr_lod_warnings)

target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/pop_adjacency.cpp
               ${CMAKE_CURRENT_LIST_DIR}/pop_build.cpp ${CMAKE_CURRENT_LIST_DIR}/pop_spheres.cpp
               ${CMAKE_CURRENT_LIST_DIR}/pop_io.cpp $<TARGET_OBJECTS:pbr_lod_pop_cgal>)
# OpenMesh's VectorT default constructor leaves its array uninitialised on purpose; with
# -fsanitize=address GCC 12 reports that as -Wmaybe-uninitialized inside OpenMesh's property
# push_back, inlined into the file that builds OpenMesh's adjacency (a false positive; a #pragma does not silence it under -Werror).
# GCC only: clang (the fuzz preset) has no such warning and rejects the unknown option.
set_source_files_properties(${CMAKE_CURRENT_LIST_DIR}/pop_adjacency.cpp PROPERTIES
                            COMPILE_OPTIONS $<$<CXX_COMPILER_ID:GNU>:-Wno-maybe-uninitialized>)
