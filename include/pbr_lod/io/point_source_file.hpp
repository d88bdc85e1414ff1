// pbr_lod — point files as point sources: PLY, LAS and PCD read in blocks, never whole.
//
// For out-of-core builds of inputs larger than memory. open_point_source makes one streaming
// pass over the file (the bounding box for the origin, the count of finite points, the report)
// and keeps an index with one entry per 2^16 kept points (24 bytes each: where that run of points
// starts in the file), so a read of any range starts at most 2^16 records before it and memory
// never grows with the file beyond that index. Reads are positioned (pread) in blocks of at
// most 4 MiB.
//
// What a source gives is exactly what read_points gives for the same file: the same origin (the
// PLY `comment pbr_lod_origin` hint under the same rule), bit-identical float positions, the same
// normals (renormalised / zeroed by the same rule) and colours, the same dropping of non-finite
// points (read() counts kept points only), the same sensor (PCD: the origin of the sensor frame)
// and the same report at open — except what concerns faces: a PLY's faces are not read, so
// faces_dropped stays 0, face rows are not checked, and a binary PLY with list properties (faces)
// gets no "bytes after the last element" warning.
//
// Formats:
//  * PLY ascii, binary little and big endian. Binary vertex rows must have a fixed size (no list
//    property in the vertex element), and elements before the vertex element must have no lists.
//  * LAS 1.0–1.4, point formats 0–10; LAZ (LASzip) formats 0–10, decoded chunk by chunk (the
//    chunks a read covers decode in parallel; a few recent chunks are cached for small reads).
//  * PCD ascii and binary. `binary_compressed` is one LZF block for the whole file, which
//    cannot be read in parts: such a file is read whole into memory, as read_points does.
// Other extensions (.obj, .off) are refused with a FormatError (read_points loads OBJ/OFF).
//
// Thread safety: read() may be called from several threads at once (positioned reads, no
// shared cursor). The file must not change while the source is open; if it is cut short, read()
// throws IoError.
#pragma once

#include <memory>
#include <string>

#include "pbr_lod/core/point_source.hpp"
#include "pbr_lod/io/read.hpp"

namespace pbr_lod {

/// Opens a point file (.ply, .las, .laz, .pcd) as a point_source read in blocks. Throws IoError /
/// FormatError as read_points does; `report` is filled as read_points fills it (see above).
[[nodiscard]] std::unique_ptr<point_source> open_point_source(const std::string& path,
                                                              read_report* report = nullptr);

}  // namespace pbr_lod
