// Explicit topologies (a mesh file, a random cloud) built rank by rank, as box lattices are
// (partition/lattice_model.hpp): no rank holds the whole connection list or the whole body.
//
// The pipeline, all collective:
//   1. rank 0 alone reads each mesh (the Gmsh child, io/gmsh_mesh.hpp) or draws each cloud, and works out each
//      molecule's position, mass and modulus and the named faces (mesh_molecules); every rank gets the counts
//      and the faces (O(surface));
//   2. rank 0 hands the molecules to the directory ranks (balanced blocks of the natural order) and the
//      tetrahedra's edges, a chunk of tetrahedra at a time, to the directory rank of their lower end, which
//      merges them into its connections (Eq. 5's volumes summed in tetrahedron order, as the whole-body path
//      sums them); box bodies of the scene come from their stencils; rank 0 frees the mesh;
//   3. METIS partitions the graph that the directories gather on rank 0 as compact ints for the call alone (or
//      PT-Scotch on every rank's block of rows);
//   4. molecules and connections travel to their owners; ghosts ask the directory.
// The result is identical, array for array, to the whole-body reference (tests/, build_body + distribute).
#pragma once
#include <mpi.h>

#include "partition/local_model.hpp"
#include "src/model/scene.hpp"

namespace tissue {

// Collective. This rank's LocalModel of a scene with at least one explicit body, and what calibration reads of
// it; mesh bodies are read by `read_mesh` on rank 0 only.
LocalModel build_explicit_model(const Scene& scene, MPI_Comm comm, CalibrationInputs& inputs,
                                const MeshReader& read_mesh);

}  // namespace tissue
