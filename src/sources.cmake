# Compiled parts of pbr_lod, one list per area (each area owns its file).
include(${CMAKE_CURRENT_LIST_DIR}/core/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/io/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/raster/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/core/estimation.cmake)
foreach(id IN LISTS PBR_LOD_BUILDERS)  # cmake/builders.cmake
  include(${CMAKE_CURRENT_LIST_DIR}/builders/${id}.cmake)
endforeach()
include(${CMAKE_CURRENT_LIST_DIR}/peers/peers.cmake)
