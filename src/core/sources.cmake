target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/version.cpp ${CMAKE_CURRENT_LIST_DIR}/synthetic.cpp
               ${CMAKE_CURRENT_LIST_DIR}/memory.cpp ${CMAKE_CURRENT_LIST_DIR}/parallel.cpp
               ${CMAKE_CURRENT_LIST_DIR}/mesh_normals.cpp ${CMAKE_CURRENT_LIST_DIR}/mesh_splats.cpp
               ${CMAKE_CURRENT_LIST_DIR}/point_source.cpp
               ${CMAKE_CURRENT_LIST_DIR}/atomic_file.cpp ${CMAKE_CURRENT_LIST_DIR}/normal_repair.cpp
               ${CMAKE_CURRENT_LIST_DIR}/repeated_faces.cpp)
