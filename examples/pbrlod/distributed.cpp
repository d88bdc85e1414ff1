// pbrlod build --distributed: a chunked build (point-octree, PMR) shared among MPI ranks (Open MPI
// from Debian). The library knows no MPI: it takes a rank, a rank count and a barrier
// (chunked_options::distributed, builders/chunked.hpp); this file gives it MPI's. Every rank runs
// the same command line over a folder on a shared file system; rank 0 prints the report.
#include "distributed.hpp"

#include <iostream>

#include "lod.hpp"
#include "pbr_lod/core/error.hpp"

#ifdef PBRLOD_HAVE_MPI
#include <mpi.h>
#endif

namespace pbrlod_tool {

bool mpi_available() {
#ifdef PBRLOD_HAVE_MPI
  return true;
#else
  return false;
#endif
}

int cmd_build_distributed(const std::string& method, const std::string& input,
                          const std::string& output, const std::vector<std::string>& params,
                          bool as_json) {
#ifdef PBRLOD_HAVE_MPI
  const method_entry& m = method_named(method);
  if (!m.build_chunked)
    throw InvalidArgument("--distributed builds point-octree, pca-octree and pmr (got " + method +
                          ")");
  MPI_Init(nullptr, nullptr);
  int rank = 0, ranks = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &ranks);
  try {
    json report;
    report.integer("ranks", ranks);
    distributed_rank me{rank, ranks, [] { MPI_Barrier(MPI_COMM_WORLD); }};
    const auto l =
        m.build_chunked(params, input, output, rank == 0 && interactive(as_json), report, &me);
    if (rank == 0)
      std::cout << (as_json ? "" : "wrote " + output + "/: ")
                << l->stats(output).merge(report).text() << "\n";
  } catch (const std::exception& e) {
    // The other ranks wait at a barrier this one will never reach.
    std::cerr << "pbrlod (rank " << rank << "): " << e.what() << "\n";
    MPI_Abort(MPI_COMM_WORLD, 1);
  }
  MPI_Finalize();
  return 0;
#else
  (void)method, (void)input, (void)output, (void)params, (void)as_json;
  throw InvalidArgument(
      "this pbrlod was built without MPI: install libopenmpi-dev (scripts/install-deps.sh) and "
      "rebuild, or leave out --distributed");
#endif
}

}  // namespace pbrlod_tool
