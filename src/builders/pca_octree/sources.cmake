# PCA octree (Kalaiah & Varshney 2003, "Statistical Point Geometry"): the octree and per-node
# PCA, the k-means classification and quantisation, the file, and the point generator of §4 are
# compiled here once, so tests, the tool and benchmarks only instantiate the thin class template
# (extern template in builders/pca_octree.hpp). FLANN (through core/knn) and the normal tables
# stay behind this wall.
target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/pca_octree_build.cpp
               ${CMAKE_CURRENT_LIST_DIR}/pca_octree_stats.cpp
               ${CMAKE_CURRENT_LIST_DIR}/pca_octree_quantise.cpp
               ${CMAKE_CURRENT_LIST_DIR}/pca_octree_io.cpp
               ${CMAKE_CURRENT_LIST_DIR}/pca_octree_render.cpp)
# The chunked (out-of-core) build and the lazily opened directory it writes.
target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/chunked_pca_octree_build.cpp
               ${CMAKE_CURRENT_LIST_DIR}/chunked_pca_octree.cpp)
