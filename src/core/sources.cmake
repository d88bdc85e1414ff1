target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/version.cpp ${CMAKE_CURRENT_LIST_DIR}/synthetic.cpp
               ${CMAKE_CURRENT_LIST_DIR}/memory.cpp ${CMAKE_CURRENT_LIST_DIR}/parallel.cpp
               ${CMAKE_CURRENT_LIST_DIR}/mesh_normals.cpp ${CMAKE_CURRENT_LIST_DIR}/mesh_splats.cpp
               ${CMAKE_CURRENT_LIST_DIR}/point_source.cpp
               ${CMAKE_CURRENT_LIST_DIR}/atomic_file.cpp ${CMAKE_CURRENT_LIST_DIR}/normal_repair.cpp
               ${CMAKE_CURRENT_LIST_DIR}/repeated_faces.cpp ${CMAKE_CURRENT_LIST_DIR}/mesh_colours.cpp
               ${CMAKE_CURRENT_LIST_DIR}/grid_knn.cpp)
# The task runner: oneTBB's pool, except under ThreadSanitizer, which cannot see the
# synchronisation inside Debian's uninstrumented libtbb (parallel_threads.cpp says why).
if(PBR_LOD_TSAN)
  target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/parallel_threads.cpp)
else()
  target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/parallel_tbb.cpp)
endif()
