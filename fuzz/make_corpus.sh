#!/usr/bin/env bash
# Writes the fuzz targets' seed corpora: small valid files of every format, one folder per target.
#   fuzz/make_corpus.sh PBRLOD DATA OUT [MAKE_LAZ_SEEDS]
# PBRLOD: the pbrlod tool (builds the hierarchy files); DATA: the shared/data folder (the bunny
# res4 PLY and the LAS file are copied from it; the hierarchies are built from them); OUT: the
# corpus root, e.g. build/fuzz/corpus, which gets OUT/fuzz_<target>/; MAKE_LAZ_SEEDS: the fuzz
# tree's make_laz_seeds (fuzz/make_laz_seeds.cpp), which writes fuzz_laz's small LAZ seeds.
# Seeds are small on purpose: libFuzzer runs each input whole, so a 2 MB seed (the real PCD scan)
# would cost milliseconds per execution. The PCD seeds are written here, byte by byte, in the
# three encodings (ascii, binary, binary_compressed) instead.
set -euo pipefail
pbrlod="$1" data="$2" out="$3" make_laz_seeds="${4:-}"
# The builders (one fuzz target each) are those of cmake/builders.cmake.
builders=$(sed -n 's/^pbr_lod_builder(\([a-z0-9_]*\).*/\1/p' "$(dirname "$0")/../cmake/builders.cmake")
for t in ply obj off pcd las laz gaussian_ply splat spz $builders; do mkdir -p "$out/fuzz_$t"; done

# --- meshes and point clouds ---------------------------------------------------------------------
cp --no-preserve=mode "$data/bun_zipper_res4.ply" "$out/fuzz_ply/bunny_res4.ply"
cp --no-preserve=mode "$data/1.2-with-color.las" "$out/fuzz_las/with_color_1.2.las"
# LAZ: the LAS reader decodes by the format byte, whatever the extension, so fuzz_las covers our
# LAZ decoder too. The committed twins (tests/data/laz, 9–29 kB): formats 0 and 3, 3 with 27 extra
# bytes (a BYTE item), LAS 1.4 format 6 (layered) and a COPC file (format 7, 65 chunks).
laz_twins="$(dirname "$0")/../tests/data/laz"
for f in point10 simple extra-bytes 1_4_w_evlr simple.copc; do
  cp --no-preserve=mode "$laz_twins/$f.laz" "$out/fuzz_las/laz_$f.las"
done
# fuzz_laz: the same reader from LAZ seeds only, each under 4 kB (formats 0–10 in chunks of 8
# points, written by our encoder from the twins' first records; a COPC file below).
if [ -n "$make_laz_seeds" ]; then "$make_laz_seeds" "$laz_twins" "$out/fuzz_laz"; fi

# Inputs that once failed a target (fuzz/regressions/<target>/, README.md there): every run
# starts from them, so a fix that comes undone fails the next run.
for d in "$(dirname "$0")"/regressions/fuzz_*/; do
  cp --no-preserve=mode "$d"* "$out/$(basename "$d")/"
done

# An octahedron with vertex colours and normals: the coloured mesh the POP seed is built from.
octahedron="$out/fuzz_ply/octahedron_colour.ply"
cat > "$octahedron" <<'PLY'
ply
format ascii 1.0
element vertex 6
property float x
property float y
property float z
property float nx
property float ny
property float nz
property uchar red
property uchar green
property uchar blue
element face 8
property list uchar int vertex_indices
end_header
1 0 0 1 0 0 255 0 0
-1 0 0 -1 0 0 0 255 0
0 1 0 0 1 0 0 0 255
0 -1 0 0 -1 0 255 255 0
0 0 1 0 0 1 0 255 255
0 0 -1 0 0 -1 255 0 255
3 0 2 4
3 2 1 4
3 1 3 4
3 3 0 4
3 2 0 5
3 1 2 5
3 3 1 5
3 0 3 5
PLY

# Binary PLY, both byte orders: one triangle (float xyz, uchar count + int indices).
f0='\x00\x00\x00\x00' f1le='\x00\x00\x80\x3f' f1be='\x3f\x80\x00\x00'
binary_ply() {  # binary_ply ORDER ZERO ONE INT0 INT1 INT2
  printf 'ply\nformat binary_%s_endian 1.0\nelement vertex 3\nproperty float x\n' "$1"
  printf 'property float y\nproperty float z\nelement face 1\n'
  printf 'property list uchar int vertex_indices\nend_header\n'
  printf "$2$2$2$3$2$2$2$3$2"'\x03'"$4$5$6"
}
binary_ply little "$f0" "$f1le" '\x00\x00\x00\x00' '\x01\x00\x00\x00' '\x02\x00\x00\x00' \
  > "$out/fuzz_ply/triangle_le.ply"
binary_ply big "$f0" "$f1be" '\x00\x00\x00\x00' '\x00\x00\x00\x01' '\x00\x00\x00\x02' \
  > "$out/fuzz_ply/triangle_be.ply"

cat > "$out/fuzz_obj/quad.obj" <<'OBJ'
# a quad with texture coordinates and normals, a triangle without
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
f 1/1/1 2/2/1 3/3/1 4/4/1
f -4 -2 -1
OBJ
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\nvn 0 0 1\n' > "$out/fuzz_obj/triangle.obj"

printf 'OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n' > "$out/fuzz_off/square.off"
cat > "$out/fuzz_off/tetra_colour.off" <<'OFF'
COFF
4 4 6
0 0 0 255 0 0 255
1 0 0 0 255 0 255
0 1 0 0 0 255 255
0 0 1 255 255 255 255
3 0 2 1
3 0 1 3
3 0 3 2
3 1 2 3
OFF
printf 'NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n' > "$out/fuzz_off/normals.off"

pcd_head() {  # pcd_head DATA FIELDS SIZE TYPE COUNT POINTS
  printf '# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS %s\nSIZE %s\n' "$2" "$3"
  printf 'TYPE %s\nCOUNT %s\nWIDTH %s\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %s\nDATA %s\n' \
    "$4" "$5" "$6" "$6" "$1"
}
{
  pcd_head ascii 'x y z normal_x normal_y normal_z rgb' '4 4 4 4 4 4 4' 'F F F F F F F' \
    '1 1 1 1 1 1 1' 3
  printf '0 0 0 0 0 1 4.2108e+06\n1 0 0 0 0 1 4.2108e+06\nnan nan nan 0 0 1 0\n'
} > "$out/fuzz_pcd/ascii.pcd"
# Two points (0,0,0) and (1,1,1), colours red and green (rgb as U4: 0x00RRGGBB).
red='\x00\x00\xff\x00' green='\x00\xff\x00\x00'
{
  pcd_head binary 'x y z rgb' '4 4 4 4' 'F F F U' '1 1 1 1' 2
  printf "$f0$f0$f0$red$f1le$f1le$f1le$green"
} > "$out/fuzz_pcd/binary.pcd"
# binary_compressed: u32 compressed size, u32 raw size, then LZF. The raw data is one array per
# field (x x y y z z rgb rgb: 32 bytes); LZF's control byte 0x1f is "a literal run of 32 bytes".
{
  pcd_head binary_compressed 'x y z rgb' '4 4 4 4' 'F F F U' '1 1 1 1' 2
  printf '\x21\x00\x00\x00\x20\x00\x00\x00\x1f'
  printf "$f0$f1le$f0$f1le$f0$f1le$red$green"
} > "$out/fuzz_pcd/binary_compressed.pcd"

# --- 3-D Gaussians (io/gaussians.hpp): 3DGS PLY, .splat, .spz, two Gaussians each ------------
# Written by python3 (a dependency already): binary records are clearer as struct.pack than as
# printf escapes. The version-4 .spz seed needs the zstd tool and is left out without it.
python3 - "$out" <<'PY'
import gzip, math, struct, sys
out = sys.argv[1]
def ply(degree, binary):
    rest = 3 * ((degree + 1) ** 2 - 1)
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += ["f_rest_%d" % k for k in range(rest)]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    rows = [[0, 0, 0, 0, 0, 0, 0.5, -0.5, 0.1] + [0.01 * k for k in range(rest)]
            + [2.0, -3.0, -3.5, -4.0, 1, 0, 0, 0],
            [1, 2, 3, 0, 0, 0, 0.0, 0.2, 0.4] + [-0.02 * k for k in range(rest)]
            + [-1.0, -2.0, -2.0, -5.0, 0.5, 0.5, 0.5, 0.5]]
    head = "ply\nformat %s 1.0\nelement vertex 2\n" % ("binary_little_endian" if binary else "ascii")
    head += "".join("property float %s\n" % n for n in names) + "end_header\n"
    if binary:
        return head.encode() + b"".join(struct.pack("<%df" % len(r), *r) for r in rows)
    return (head + "".join(" ".join("%g" % v for v in r) + "\n" for r in rows)).encode()
open(out + "/fuzz_gaussian_ply/degree0.ply", "wb").write(ply(0, True))
open(out + "/fuzz_gaussian_ply/degree1_ascii.ply", "wb").write(ply(1, False))
open(out + "/fuzz_gaussian_ply/degree3.ply", "wb").write(ply(3, True))
splat = b"".join(struct.pack("<6f8B", x, 0, 0, 0.1, 0.2, 0.3, 255, 128, 0, 200, 200, 128, 128, 60)
                 for x in (0.0, 1.0))
open(out + "/fuzz_splat/two.splat", "wb").write(splat)
def spz(version, degree):
    n, dim = 2, (degree + 1) ** 2 - 1
    head = struct.pack("<IIIBBBB", 0x5053474e, version, n, degree, 12, 0, 0)
    pos = bytes([0, 16, 0, 0, 248, 255, 0, 24, 0] + [0] * 9)  # (1, -0.5, 1.5), (0, 0, 0)
    rot = bytes([0, 0, 0, 192] + [0, 0, 240, 31]) if version >= 3 else bytes([128] * 3 + [255, 128, 128])
    sh = bytes([192, 128, 64] * dim * n)
    return head, [pos, bytes([51, 200]), bytes([255, 0, 128] * n), bytes([160, 176, 144] * n), rot, sh]
for v, d in ((2, 0), (3, 1), (3, 3)):
    head, parts = spz(v, d)
    open(out + "/fuzz_spz/v%d_degree%d.spz" % (v, d), "wb").write(
        gzip.compress(head + b"".join(parts), mtime=0))
head, parts = spz(4, 1)
for k, p in enumerate(parts):
    open(out + "/fuzz_spz/.v4_stream%d" % k, "wb").write(p)
PY
if command -v zstd > /dev/null; then
  # Version 4: a 32-byte header, the table of contents, one zstd frame per attribute.

  for k in 0 1 2 3 4 5; do
    zstd -q -f --no-check "$out/fuzz_spz/.v4_stream$k" -o "$out/fuzz_spz/.v4_stream$k.zst"
  done
  python3 - "$out/fuzz_spz" <<'PY'
import os, struct, sys
d = sys.argv[1]
plain = [open("%s/.v4_stream%d" % (d, k), "rb").read() for k in range(6)]
packed = [open("%s/.v4_stream%d.zst" % (d, k), "rb").read() for k in range(6)]
head = struct.pack("<IIIBBBBI", 0x5053474e, 4, 2, 1, 12, 0, 6, 32) + bytes(12)
toc = b"".join(struct.pack("<QQ", len(p), len(q)) for p, q in zip(packed, plain))
open(d + "/v4_degree1.spz", "wb").write(head + toc + b"".join(packed))
PY
fi
rm -f "$out"/fuzz_spz/.v4_stream*
# Another encoder's files (tests/data/gaussians/PROVENANCE.md: PlayCanvas, @adobe/spz).
fixtures="$(dirname "$0")/../tests/data/gaussians"
cp --no-preserve=mode "$fixtures"/minimal-v*.spz "$out/fuzz_spz/"
cp --no-preserve=mode "$fixtures/minimal.splat" "$out/fuzz_splat/"

# --- hierarchy files, built by the pbrlod tool from the small inputs above -----------------------
bunny="$out/fuzz_ply/bunny_res4.ply"
las="$out/fuzz_las/with_color_1.2.las"
build() {  # build TARGET NAME INPUT METHOD [--param k=v]...
  local target="$1" name="$2" input="$3" method="$4"
  shift 4
  "$pbrlod" build --method "$method" "$@" "$input" -o "$out/fuzz_$target/$name.lod" > /dev/null
}
# Tiny seeds beside the realistic ones: every execution runs an input whole (load, save, load
# again under ASan), so the fuzzer's rate is set by the sizes it mutates; a 6-vertex hierarchy
# reaches the same parsing code hundreds of times faster than a 453-vertex one.
build point_octree octahedron_colour "$octahedron" point-octree
build pca_octree octahedron_colour "$octahedron" pca-octree
build pmr octahedron "$octahedron" pmr
rm -f "$out/fuzz_pmr/octahedron.lod.build-seconds"
build rho_grid octahedron_rho2 "$octahedron" rho-grid --param rho=2 --param level=1
build gaussian_hierarchy octahedron_colour "$octahedron" gaussian-hierarchy
build gaussian_hierarchy minimal_spz_v2 "$fixtures/minimal-v2.spz" gaussian-hierarchy
build point_octree bunny "$bunny" point-octree
build point_octree las_colour "$las" point-octree
build pop bunny "$bunny" pop
build pop octahedron_colour "$octahedron" pop
build pop bunny_float_nodes "$bunny" pop --param nodes=float
build pca_octree bunny "$bunny" pca-octree
build pca_octree las_colour "$las" pca-octree
build pmr bunny "$bunny" pmr
rm -f "$out/fuzz_pmr/bunny.lod.build-seconds"  # the tool's timing note, not a PMR file
for layout in is nis compressed; do
  build rho_grid "bunny_rho2_$layout" "$bunny" rho-grid --param rho=2 --param level=3 \
    --param layout=$layout
  build rho_grid "las_rho3_$layout" "$las" rho-grid --param rho=3 --param level=2 \
    --param layout=$layout
done
build rho_grid bunny_rho4_no_attributes "$bunny" rho-grid --param rho=4 --param level=1 \
  --param normal_bits=0 --param material_bits=0
build rho_grid bunny_rho5 "$bunny" rho-grid --param rho=5 --param level=1
# A COPC file as `pbrlod export` writes it (io/copc.hpp: LAS 1.4 format 7, normals as extra bytes,
# variable chunks, the hierarchy EVLR), for fuzz_las: the LAS reader reads it as the LAZ it is.
"$pbrlod" export "$out/fuzz_point_octree/las_colour.lod" --format copc --node-points 64 \
  -o "$out/fuzz_las/copc_export.las" > /dev/null
"$pbrlod" export "$out/fuzz_point_octree/octahedron_colour.lod" --format copc --node-points 2 \
  -o "$out/fuzz_laz/copc_octahedron.las" > /dev/null
