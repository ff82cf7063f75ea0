// Box lattices built in parallel: each rank generates only its own molecules and connections from the
// topology's stencil, so no rank ever holds the whole body (the whole-body reference in tests/, build_body +
// distribute, keeps a global connection list on every rank: about 250 bytes per molecule of the whole body).
//
// The pipeline, all collective:
//   1. every rank takes a balanced block of the original ids (the natural order of the files);
//   2. METIS partitions the connection graph (rank 0 builds the CSR from the stencils, nobody else holds it);
//   3. each block's molecules travel to their owners, with the global id of their first connection;
//   4. owners send their PETSc block ids back to the block ("directory") ranks; ghosts ask the directory;
//   5. each rank walks its owned and ghost molecules in increasing id and emits the connections with at least one
//      owned end: already in the global (a, b) order, so forces sum in the same order on any partition.
// The result is identical, array for array, to distribute() on the global body (tests/lattice_model_test.cpp).
#pragma once
#include <mpi.h>

#include "src/model/scene.hpp"
#include "partition/local_model.hpp"

namespace tissue {

// Collective. This rank's LocalModel of a scene whose bodies are all box lattices, and what calibration reads.
LocalModel build_lattice_model(const Scene& scene, MPI_Comm comm, CalibrationInputs& inputs);

}  // namespace tissue
