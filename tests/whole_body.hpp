// The whole-body construction path, kept as the independent reference the tests check the rank-by-rank builders
// against (partition/lattice_model.hpp, partition/explicit_model.hpp): build_body enumerates every molecule,
// connection and tetrahedron of the scene on the calling rank, the partitioners read that whole list, and
// distribute() keeps each rank's share. Production code never calls these: every rank would hold the whole body.
#pragma once
#include <mpi.h>

#include <string>
#include <vector>

#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "src/model/body.hpp"

namespace tissue {

// Builds the whole body a scene describes, on the calling rank: geometry, every connection, per-molecule
// material and mass. Mesh bodies take their tetrahedra from `read_mesh` (a scene with a mesh body and no reader
// is a programming error).
Body build_body(const Scene& scene, const MeshReader& read_mesh = {});

// part[m] = the rank that owns molecule m, on every rank: METIS on the whole connection graph (one part without
// METIS), or by `method` (metis, or ptscotch: PT-Scotch on even blocks of rows taken from the whole list).
std::vector<int> partition_molecules(const Body& body, MPI_Comm comm, PartitionStats& stats);
std::vector<int> partition_molecules(const Body& body, MPI_Comm comm, PartitionStats& stats,
                                     PartitionSpec::Method method);
std::vector<int> partition_ptscotch(const Body& body, MPI_Comm comm, PartitionStats& stats);

// Collective. This rank's LocalModel from the whole body and the partition, and what calibration reads of it.
LocalModel distribute(const Body& body, const std::vector<int>& part, const PartitionStats& stats, MPI_Comm comm,
                      CalibrationInputs& inputs);

}  // namespace tissue
