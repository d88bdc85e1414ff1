// pbrlod build --distributed (distributed.cpp): a chunked build (point-octree, PMR) over MPI
// ranks.
#pragma once

#include <string>
#include <vector>

namespace pbrlod_tool {

/// Whether this pbrlod was built with MPI.
bool mpi_available();

/// `mpirun -np N pbrlod build --distributed --method point-octree|pmr --param memory=SIZE INPUT -o
/// DIR`: every rank builds its share of the chunks; the folder equals the one-process build's.
int cmd_build_distributed(const std::string& method, const std::string& input,
                          const std::string& output, const std::vector<std::string>& params,
                          bool as_json);

}  // namespace pbrlod_tool
