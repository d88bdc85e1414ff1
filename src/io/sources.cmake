# I/O: OpenMesh-backed OBJ/OFF readers, our PLY/PCD/LAS readers, the PLY writer, the 3-D Gaussian
# readers (3DGS PLY, .splat, .spz) and writer.
# OpenMesh is linked PRIVATE in the top-level CMakeLists (OpenMeshCore); liblzf decodes
# PCD's binary_compressed data; zlib and libzstd decompress .spz (gzip: versions 1–3; zstd:
# version 4). None appears in a public header.
target_sources(pbr_lod PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/common.cpp
  ${CMAKE_CURRENT_LIST_DIR}/read.cpp
  ${CMAKE_CURRENT_LIST_DIR}/ply_reader.cpp
  ${CMAKE_CURRENT_LIST_DIR}/ply_writer.cpp
  ${CMAKE_CURRENT_LIST_DIR}/gaussian_reader.cpp
  ${CMAKE_CURRENT_LIST_DIR}/gaussian_writer.cpp
  ${CMAKE_CURRENT_LIST_DIR}/spz_reader.cpp
  ${CMAKE_CURRENT_LIST_DIR}/openmesh_reader.cpp
  ${CMAKE_CURRENT_LIST_DIR}/pcd_reader.cpp
  ${CMAKE_CURRENT_LIST_DIR}/las_reader.cpp
  ${CMAKE_CURRENT_LIST_DIR}/laz_decoder.cpp
  ${CMAKE_CURRENT_LIST_DIR}/laz_layered.cpp
  ${CMAKE_CURRENT_LIST_DIR}/laz_writer.cpp
  ${CMAKE_CURRENT_LIST_DIR}/copc_writer.cpp
  ${CMAKE_CURRENT_LIST_DIR}/point_source_file.cpp
  ${CMAKE_CURRENT_LIST_DIR}/png_read.cpp)

# Debian's liblzf-dev ships a config defining liblzf::liblzf (include dir /usr/include/liblzf);
# fall back to a plain search where it does not.
find_package(liblzf CONFIG QUIET)
if(TARGET liblzf::liblzf)
  target_link_libraries(pbr_lod PRIVATE liblzf::liblzf)
else()
  find_path(PBR_LOD_LZF_INCLUDE_DIR lzf.h PATH_SUFFIXES liblzf REQUIRED)
  find_library(PBR_LOD_LZF_LIBRARY lzf REQUIRED)
  target_include_directories(pbr_lod PRIVATE ${PBR_LOD_LZF_INCLUDE_DIR})
  target_link_libraries(pbr_lod PRIVATE ${PBR_LOD_LZF_LIBRARY})
endif()

# .spz: Debian's zlib1g-dev (CMake's FindZLIB) and libzstd-dev (pkg-config libzstd).
find_package(ZLIB REQUIRED)
pkg_check_modules(ZSTD REQUIRED IMPORTED_TARGET libzstd)
target_link_libraries(pbr_lod PRIVATE ZLIB::ZLIB PkgConfig::ZSTD)
