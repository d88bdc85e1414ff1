# Rasteriser support: whole-frame passes (shadow resolve, hole filling), reference renders,
# metrics (Hausdorff via FLANN k-NN), PNG (libpng), the 3-D Gaussian rasteriser. FLANN and libpng
# stay out of public headers.
target_sources(pbr_lod PRIVATE
  ${CMAKE_CURRENT_LIST_DIR}/gaussians.cpp
  ${CMAKE_CURRENT_LIST_DIR}/postprocess.cpp
  ${CMAKE_CURRENT_LIST_DIR}/reference.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_instances_1.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_instances_2.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_instances_3.cpp
  ${CMAKE_CURRENT_LIST_DIR}/render_instances_4.cpp
  ${CMAKE_CURRENT_LIST_DIR}/metrics.cpp
  ${CMAKE_CURRENT_LIST_DIR}/png.cpp
  ${CMAKE_CURRENT_LIST_DIR}/../core/knn.cpp)
