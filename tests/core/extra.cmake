target_sources(test_core PRIVATE ${CMAKE_CURRENT_LIST_DIR}/normal_quantization_test.cpp ${CMAKE_CURRENT_LIST_DIR}/estimation_test.cpp
                                 ${CMAKE_CURRENT_LIST_DIR}/parallel_test.cpp
                                 ${CMAKE_CURRENT_LIST_DIR}/memory_test.cpp
                                 ${CMAKE_CURRENT_LIST_DIR}/atomic_file_test.cpp
                                 ${CMAKE_CURRENT_LIST_DIR}/normal_repair_test.cpp
                                 ${CMAKE_CURRENT_LIST_DIR}/repeated_faces_test.cpp
                                 ${CMAKE_CURRENT_LIST_DIR}/mesh_splats_test.cpp
                                 ${CMAKE_CURRENT_LIST_DIR}/grid_knn_test.cpp)
