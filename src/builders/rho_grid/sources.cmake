# ρ-grid packed point trees (Duguet & Drettakis 2004).
#
# rho_grid_build.cpp is the one ρ-grid translation unit that includes CGAL (AABB tree
# closest-point and triangle/box queries): it is compiled as its own object library so that
# CGAL::CGAL's usage requirements (-frounding-math, Boost/GMP includes) stay on that file, as
# src/core/estimation.cmake does for estimation.cpp (which finds TBB and CGAL before us).
add_library(pbr_lod_rho_grid_build OBJECT ${CMAKE_CURRENT_LIST_DIR}/rho_grid_build.cpp)
set_target_properties(pbr_lod_rho_grid_build PROPERTIES POSITION_INDEPENDENT_CODE ON
                      CXX_EXTENSIONS OFF)
target_compile_features(pbr_lod_rho_grid_build PRIVATE cxx_std_20)
target_include_directories(pbr_lod_rho_grid_build PRIVATE ${PROJECT_SOURCE_DIR}/include)
target_link_libraries(pbr_lod_rho_grid_build PRIVATE CGAL::CGAL Eigen3::Eigen TBB::tbb
                      pbr_lod_warnings)

target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/rho_grid_io.cpp
               ${CMAKE_CURRENT_LIST_DIR}/rho_grid_codec.cpp
               $<TARGET_OBJECTS:pbr_lod_rho_grid_build>)
