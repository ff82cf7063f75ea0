// partition.method = "blocks": recursive coordinate bisection of a box lattice's index box. A cut is a lattice
// plane across the longest axis (ties to the slowest-varying id axis: z, then y), splitting the parts in two
// halves and the molecules in the same ratio, rounded to a whole plane. Every rank computes the same cuts from
// the box alone: no graph, no rank 0, no exchange. On 2 ranks a cube is two slabs of contiguous molecule ids.
#pragma once
#include <mpi.h>

#include <array>
#include <cstdint>
#include <vector>

#include "partition/metis_partition.hpp"
#include "src/model/body.hpp"

namespace tissue {

// Lattice indices [lo, hi) per axis.
struct IndexBox {
  std::array<long, 3> lo{}, hi{};
  std::int64_t molecules() const {
    std::int64_t m = 1;
    for (int d = 0; d < 3; ++d) m *= hi[d] - lo[d];
    return m;
  }
};

// The bisection of an n[0] x n[1] x n[2] box into `parts` boxes (part p is element p). Each cut puts
// floor(k / 2) of the k parts below it and round(planes * floor(k / 2) / k) planes of the axis (at least one
// each side). Throws when a box would be left with fewer planes than parts along every axis.
std::vector<IndexBox> bisect_box(const std::array<long, 3>& n, int parts);

// Whether partition.method = "blocks" applies: one body, a box lattice.
bool box_bisection_applies(const Body& shape);

// "auto" takes the bisection where its largest part is within this of the mean (planes that do not divide evenly:
// 33 planes in 2 parts is 1.03), METIS elsewhere (its tolerance is 1.001, kMetisImbalance).
constexpr double kBisectionImbalance = 1.01;

// The bisection's largest part over the mean part (+infinity where the box cannot be cut into `parts`).
double box_bisection_imbalance(const Body& shape, int parts);

// Whether `method` partitions `shape` into `parts` by the bisection: "blocks", or "auto" on one box lattice whose
// bisection is within kBisectionImbalance.
bool box_bisection_chosen(const Body& shape, PartitionSpec::Method method, int parts);

// Collective over comm (only to count the statistics). The parts (0 .. parts - 1) of this rank's block of the
// natural order (NaturalOrder::block_begin over comm's size). stats: edge cut (connections between parts, each
// once) and imbalance (largest part / mean), on every rank.
std::vector<int> partition_box_bisection(const Body& shape, MPI_Comm comm, int parts, PartitionStats& stats);

}  // namespace tissue
