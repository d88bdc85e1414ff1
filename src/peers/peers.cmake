# LOD peers (peers/cgal_simplify.hpp): CGAL's grid and hierarchy point-set simplification, the
# levels `pbrlod sweep` measures beside the builders. An object library of its own so CGAL's
# compile options (-frounding-math) stay on this file (as builders/pmr/sources.cmake).
add_library(pbr_lod_peers_cgal OBJECT ${CMAKE_CURRENT_LIST_DIR}/cgal_simplify.cpp)
set_target_properties(pbr_lod_peers_cgal PROPERTIES POSITION_INDEPENDENT_CODE ON
                      CXX_EXTENSIONS OFF)
target_compile_features(pbr_lod_peers_cgal PRIVATE cxx_std_20)
target_include_directories(pbr_lod_peers_cgal PRIVATE ${PROJECT_SOURCE_DIR}/include)
target_link_libraries(pbr_lod_peers_cgal PRIVATE CGAL::CGAL Eigen3::Eigen pbr_lod_warnings)
target_sources(pbr_lod PRIVATE $<TARGET_OBJECTS:pbr_lod_peers_cgal>)
