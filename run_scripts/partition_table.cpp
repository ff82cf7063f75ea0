// partition_table: how a box lattice splits into P parts, as the ghost exchange of the explicit solver sees it.
// For each P given, partitions the N^3 face-diagonal lattice exactly as `tissue` does on P ranks (METIS on
// blocks of b^3 molecules past 65,536 molecules, partition/lattice_blocks.hpp; `fine` as a last argument: METIS
// on the molecule graph itself, as before; `block=B`: blocks of B^3; `blocks`: partition.method = "blocks", the
// bisection of the index box, partition/box_bisection.hpp) on this one process; N may be NXxNYxNZ, and prints one CSV row
// per P: the block edge, the edge cut, the imbalance, and over the parts the largest owned count, ghost count (molecules owned
// elsewhere that share a connection with an owned one: what the ghost update brings in each step), ghosts /
// owned, local connections (those with an owned end: what the kernel computes), and neighbour parts (messages).
//   usage: partition_table N|NXxNYxNZ P [P ...] [fine | block=B | blocks]     (run_scripts/scaling_model.py runs it)
#include <mpi.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "partition/box_bisection.hpp"
#include "partition/lattice_blocks.hpp"
#include "partition/metis_partition.hpp"
#include "src/model/topology.hpp"

using namespace tissue;

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  if (argc < 3) {
    std::fprintf(stderr, "usage: partition_table N P [P ...] [fine | block=B]\n");
    return 2;
  }
  const std::string last = argv[argc - 1];
  const bool bisection = last == "blocks";
  const int forced = last == "fine" ? 1 : last.rfind("block=", 0) == 0 ? std::atoi(last.c_str() + 6) : 0;
  const bool fine = forced > 0;
  Body shape;
  const long n1 = std::atol(argv[1]);
  shape.n = {n1, n1, n1};
  if (const std::string dims = argv[1]; dims.find('x') != std::string::npos)
    std::sscanf(dims.c_str(), "%ldx%ldx%ld", &shape.n[0], &shape.n[1], &shape.n[2]);
  shape.h = {1.0, 1.0, 1.0};
  shape.topology = "face-diagonals";
  const std::int64_t n = shape.molecules();
  const TopologyStyle& style = *find_topology(shape.topology);
  std::printf("N,molecules,parts,block,edge_cut,imbalance,max_owned,max_ghosts,max_ghosts_per_owned,"
              "mean_ghosts_per_owned,max_local_connections,max_neighbour_parts,mean_neighbour_parts,seconds\n");
  std::vector<Neighbour> nb;
  for (int a = 2; a < argc - (fine || bisection ? 1 : 0); ++a) {
    const int parts = std::atoi(argv[a]);
    const auto t0 = std::chrono::steady_clock::now();
    PartitionStats stats;
    const int block = bisection ? 0 : fine ? forced : lattice_block_size(shape, parts);
    std::vector<int> part = bisection ? partition_box_bisection(shape, MPI_COMM_SELF, parts, stats)
                                      : partition_lattice_blocks(shape, MPI_COMM_SELF, parts, block, stats);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::vector<long> owned(parts, 0), ghosts(parts, 0), local_connections(parts, 0);
    std::vector<std::vector<int>> neighbours(parts);
    for (std::int64_t g = 0; g < n; ++g) {
      const int p = part[g];
      ++owned[p];
      lattice_neighbours(style, shape, g, nb);
      // g is a ghost of every other part that owns one of its neighbours (counted once per part).
      int seen[32], count = 0;
      for (const auto& x : nb) {
        const int q = part[x.id];
        if (x.id > g) {
          ++local_connections[p];
          if (q != p) ++local_connections[q];
        }
        if (q != p && std::find(seen, seen + count, q) == seen + count) seen[count++] = q;
      }
      for (int k = 0; k < count; ++k) {
        ++ghosts[seen[k]];
        if (std::find(neighbours[p].begin(), neighbours[p].end(), seen[k]) == neighbours[p].end())
          neighbours[p].push_back(seen[k]);
      }
    }
    double worst = 0, mean = 0, mean_nb = 0;
    std::size_t most_nb = 0;
    for (int p = 0; p < parts; ++p) {
      worst = std::max(worst, static_cast<double>(ghosts[p]) / owned[p]);
      mean += static_cast<double>(ghosts[p]) / owned[p] / parts;
      most_nb = std::max(most_nb, neighbours[p].size());
      mean_nb += static_cast<double>(neighbours[p].size()) / parts;
    }
    std::printf("%s,%lld,%d,%d,%ld,%.4f,%ld,%ld,%.5f,%.5f,%ld,%zu,%.2f,%.2f\n", argv[1], static_cast<long long>(n), parts,
                block, stats.edge_cut, stats.imbalance, *std::max_element(owned.begin(), owned.end()),
                *std::max_element(ghosts.begin(), ghosts.end()), worst, mean,
                *std::max_element(local_connections.begin(), local_connections.end()), most_nb, mean_nb, seconds);
    std::fflush(stdout);
  }
  MPI_Finalize();
  return 0;
}
