# Quantised normals (Pajarola 2003 §5) and k-NN normal / splat-ellipse estimation (§4 end).
#
# estimation.cpp needs Boost's header-only union-find (its parallel passes run on the library's
# pool, core/parallel.hpp); it is its own object library so that usage requirement stays on it.
# CGAL is found here for the builders' CGAL translation units (src/builders/*.cmake), each an
# object library of its own so CGAL's -frounding-math never reaches other sources. Included after
# the config-mode finds of Eigen3/OpenMesh in the top-level list: find_package(CGAL) puts CGAL's
# own Find modules on CMAKE_MODULE_PATH (DEPENDENCIES.md).
find_package(TBB REQUIRED NO_MODULE)  # TBB::tbb (before CGAL: CGAL ships a FindTBB module)
find_package(CGAL REQUIRED)           # CGAL::CGAL

add_library(pbr_lod_estimation OBJECT ${CMAKE_CURRENT_LIST_DIR}/estimation.cpp)
set_target_properties(pbr_lod_estimation PROPERTIES POSITION_INDEPENDENT_CODE ON
                      CXX_EXTENSIONS OFF)
target_compile_features(pbr_lod_estimation PRIVATE cxx_std_20)
target_include_directories(pbr_lod_estimation PRIVATE ${PROJECT_SOURCE_DIR}/include)
target_link_libraries(pbr_lod_estimation PRIVATE Eigen3::Eigen pbr_lod_warnings)

target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/normal_quantization.cpp
               $<TARGET_OBJECTS:pbr_lod_estimation>)
# CGAL's link dependencies without its compile options: GMP/MPFR are referenced by CGAL's
# exact-number fallbacks when they are not optimised away (Debug). $<LINK_ONLY:CGAL::CGAL> would
# still bring -frounding-math to every source of pbr_lod. The variables come from CGAL's config.
target_link_libraries(pbr_lod PRIVATE TBB::tbb ${GMPXX_LIBRARIES} ${MPFR_LIBRARIES} ${GMP_LIBRARIES})
