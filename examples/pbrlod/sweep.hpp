// pbrlod sweep — every builder over the same inputs, views and tolerances (sweep.cpp).
#pragma once

#include <string>
#include <vector>

namespace pbrlod_tool {

/// `pbrlod sweep [INPUT...] -o DIR [--size small|full] [--check] [--json]`: writes
/// DIR/sweep.csv and DIR/sweep.json. With --check, returns 1 (and names each problem on stderr)
/// when a builder produced no rows or a series' error grows as its tolerance tightens.
int cmd_sweep(const std::vector<std::string>& inputs, const std::string& dir,
              const std::string& size, bool check, bool as_json);

}  // namespace pbrlod_tool
