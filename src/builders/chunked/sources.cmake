# The out-of-core layer every chunked builder plugs into (docs/adding-a-builder.md): the
# partition, halo and distribution passes and the chunk reader (chunk_files.hpp), and what the
# chunked builds' folders share (chunked.cpp). A builder's own chunked build and reader live in
# its folder and include "builders/chunked/chunk_files.hpp" (src/ is a private include directory).
target_sources(pbr_lod PRIVATE ${CMAKE_CURRENT_LIST_DIR}/chunked.cpp)
