// pbrlod papers — the papers' own curves beside ours (papers.cpp).
#pragma once

#include <string>

namespace pbrlod_tool {

/// `pbrlod papers [--data DIR] [--papers DIR] -o DIR`: builds PMR, POP, the PCA octree and the
/// point-octree on the Buddha (res3) and the bunny of DIR (default $PBR_LOD_DATA), measures the
/// analogue of each paper's table or figure and writes DIR/papers.md (the paper's rows and
/// ours, side by side), papers.csv (ours) and two SVG charts.
int cmd_papers(const std::string& data_dir, const std::string& papers_dir, const std::string& dir,
               const std::string& view_spec, int repeats);

}  // namespace pbrlod_tool
