# The builders: the one list that everything listing builders reads (the library's sources, the
# pbrlod tool's method table, the test, benchmark and fuzz targets, scripts/fuzz.sh and
# fuzz/make_corpus.sh). docs/adding-a-builder.md says what a new builder fills in.
#
#   pbr_lod_builder(ID METHOD NAME [TESTS FILE...])
#
# ID names the builder's slots, each a file of its own:
#   src/builders/ID/sources.cmake    its compiled sources (src/builders/ID/ holds them), added to the pbr_lod target
#   examples/pbrlod/ID_method.cpp    `method_entry ID_method()`: the tool's build/load/render
#   tests/builders/ID_test.cpp       its tests, with the TESTS files (tests/builders/): test_ID
#   benchmarks/ID_benchmark.cpp      its Google Benchmarks: bench_ID (benchmarks/builders.cmake
#                                    adds what a builder needs beyond the one source)
#   fuzz/ID_fuzzer.cpp               its file reader under libFuzzer: fuzz_ID
# NAME is the tool's method name (`pbrlod build --method NAME`). The order here is the order of
# the tool's method table, the demo's contact sheet and the sweep.
set(PBR_LOD_BUILDERS "")
macro(pbr_lod_builder id)
  cmake_parse_arguments(_pb "" "METHOD" "TESTS" ${ARGN})
  if(NOT _pb_METHOD)
    message(FATAL_ERROR "pbr_lod_builder(${id}): METHOD is required")
  endif()
  list(APPEND PBR_LOD_BUILDERS ${id})
  set(PBR_LOD_BUILDER_${id}_METHOD ${_pb_METHOD})
  set(PBR_LOD_BUILDER_${id}_TESTS ${id}_test.cpp ${_pb_TESTS})
endmacro()

pbr_lod_builder(point_octree METHOD point-octree  # Pajarola 2003
                TESTS chunked_point_octree_test.cpp)
pbr_lod_builder(rho_grid METHOD rho-grid  # Duguet & Drettakis 2004
                TESTS rho_grid_draw_test.cpp)
pbr_lod_builder(pop METHOD pop)  # Chen & Nguyen 2001
pbr_lod_builder(pca_octree METHOD pca-octree  # Kalaiah & Varshney 2003
                TESTS pca_octree_storage_test.cpp chunked_pca_octree_test.cpp
                      pca_octree_render_test.cpp)
pbr_lod_builder(pmr METHOD pmr  # Dey & Hudson 2002
                TESTS chunked_pmr_test.cpp)
pbr_lod_builder(gaussian_hierarchy METHOD gaussian-hierarchy  # Kerbl et al. 2024
                TESTS chunked_gaussian_hierarchy_test.cpp)
