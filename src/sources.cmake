# Compiled parts of pbr_lod, one list per area (each area owns its file).
include(${CMAKE_CURRENT_LIST_DIR}/core/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/io/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/raster/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/core/estimation.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/builders/pop.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/builders/rho_grid.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/builders/pca_octree.cmake)
