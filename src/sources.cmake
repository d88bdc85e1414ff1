# Compiled parts of pbr_lod, one list per area (each area owns its file). Internal headers are
# named from src/ when they cross a folder ("builders/chunked/chunk_files.hpp").
target_include_directories(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR})
include(${CMAKE_CURRENT_LIST_DIR}/core/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/io/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/raster/sources.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/core/estimation.cmake)
include(${CMAKE_CURRENT_LIST_DIR}/builders/chunked/sources.cmake)
foreach(id IN LISTS PBR_LOD_BUILDERS)  # cmake/builders.cmake
  include(${CMAKE_CURRENT_LIST_DIR}/builders/${id}/sources.cmake)
endforeach()
include(${CMAKE_CURRENT_LIST_DIR}/peers/peers.cmake)
