# Sourced by scripts/fuzz.sh and scripts/fuzz_campaign.sh (from the repository root): every fuzz
# target of fuzz/CMakeLists.txt in one list — the readers' (meshes and points, then 3-D
# Gaussians), then one per builder of cmake/builders.cmake.
mapfile -t fuzz_builder_targets < <(sed -n 's/^pbr_lod_builder(\([a-z0-9_]*\).*/fuzz_\1/p' cmake/builders.cmake)
fuzz_targets=(fuzz_ply fuzz_obj fuzz_off fuzz_pcd fuzz_las fuzz_laz fuzz_gaussian_ply fuzz_splat
              fuzz_spz "${fuzz_builder_targets[@]}")
