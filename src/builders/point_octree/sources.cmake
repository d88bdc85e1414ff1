# Point-octree (Pajarola 2003): header-only builder, compiled once here for every input
# attribute set (extern templates in builders/point_octree.hpp).
target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/point_octree_instances_1.cpp
               ${CMAKE_CURRENT_LIST_DIR}/point_octree_instances_2.cpp)
# The chunked (out-of-core) build and the lazily opened directory it writes.
target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/chunked_point_octree_build.cpp
               ${CMAKE_CURRENT_LIST_DIR}/chunked_point_octree.cpp)
