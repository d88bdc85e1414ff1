# PCL peers (peers/pcl_simplify.hpp) for `pbrlod sweep`: a library of their own,
# pbr_lod::peers_pcl, so pbr_lod itself never depends on PCL. PBR_LOD_PEERS: AUTO builds them
# when PCL is found (scripts/install-deps.sh installs libpcl-dev), ON requires PCL, OFF skips it.
set(PBR_LOD_PEERS AUTO CACHE STRING "PCL peers for pbrlod sweep: AUTO, ON or OFF")
set_property(CACHE PBR_LOD_PEERS PROPERTY STRINGS AUTO ON OFF)
set(PBR_LOD_HAVE_PCL_PEERS OFF)
if(NOT PBR_LOD_PEERS STREQUAL "OFF")
  if(PBR_LOD_PEERS STREQUAL "ON")
    find_package(PCL 1.10 REQUIRED COMPONENTS common filters octree)
  else()
    find_package(PCL 1.10 QUIET COMPONENTS common filters octree)
  endif()
  if(PCL_FOUND)
    set(PBR_LOD_HAVE_PCL_PEERS ON)
    add_library(pbr_lod_peers_pcl STATIC ${CMAKE_CURRENT_LIST_DIR}/pcl_simplify.cpp)
    add_library(pbr_lod::peers_pcl ALIAS pbr_lod_peers_pcl)
    set_target_properties(pbr_lod_peers_pcl PROPERTIES POSITION_INDEPENDENT_CODE ON
                          CXX_EXTENSIONS OFF)
    target_compile_features(pbr_lod_peers_pcl PRIVATE cxx_std_20)
    target_include_directories(pbr_lod_peers_pcl SYSTEM PRIVATE ${PCL_INCLUDE_DIRS})
    target_compile_definitions(pbr_lod_peers_pcl PRIVATE ${PCL_DEFINITIONS})
    target_link_libraries(pbr_lod_peers_pcl PUBLIC pbr_lod PRIVATE ${PCL_LIBRARIES}
                          pbr_lod_warnings)
  endif()
endif()
message(STATUS "pbr_lod: PCL peers for pbrlod sweep: ${PBR_LOD_HAVE_PCL_PEERS} (PBR_LOD_PEERS=${PBR_LOD_PEERS})")
