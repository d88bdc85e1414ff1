# Gaussian hierarchy (Kerbl et al. 2024): the build (median splits, moment matching) in
# gaussian_build.cpp, the file and the cuts as Gaussian clouds in gaussian_io.cpp, the out-of-core
# build through the chunked layer and its lazy reader in gaussian_chunked.cpp.
target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/gaussian_build.cpp
               ${CMAKE_CURRENT_LIST_DIR}/gaussian_io.cpp
               ${CMAKE_CURRENT_LIST_DIR}/gaussian_chunked.cpp)
