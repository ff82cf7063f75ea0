// The rank's share of the body: its owned molecules (first, in original-id order, so their PETSc block ids are
// contiguous), then its ghosts (molecules owned elsewhere that share a connection with an owned one), and every
// connection with at least one owned end, in the global connection order.
//
// Why every connection touching an owned molecule, cut ones on both sides: each rank then sums the forces on
// its molecules by itself, in the same order whatever the partition, so results do not depend on the rank count
// and no reverse (ghost-to-owner) exchange of forces is needed; the price is computing cut connections twice.
#pragma once
#include <mpi.h>
#include <petscsys.h>

#include <cstdint>
#include <vector>

#include "partition/metis_partition.hpp"
#include "src/model/body.hpp"

namespace tissue {

struct LocalModel {
  MPI_Comm comm = MPI_COMM_NULL;
  int rank = 0, size = 1;
  Body shape;  // the bodies' geometry only (body 0's n, h, offset, topology, and parts); global arrays left empty
  std::int64_t global_molecules = 0, global_connections = 0;
  PartitionStats partition;

  int owned = 0;                     // molecules this rank owns: local indices [0, owned)
  int local = 0;                     // owned + ghosts
  PetscInt first_block = 0;          // PETSc block id of local molecule 0
  std::vector<std::int64_t> id;      // original id of each local molecule
  std::vector<PetscInt> block;       // PETSc block id of each local molecule (ghosts too)
  std::vector<double> rest;          // 3 * local, rest positions
  std::vector<double> mass;          // local, kg
  std::vector<double> youngs_modulus;  // local, Pa
  std::vector<int> degree;           // local, number of connections of each molecule in the whole body
  std::vector<int> body;             // local, which body ([[body]] index) each molecule belongs to

  // Connections (structure of arrays): local end indices, global id, class, rest length, stiffness.
  std::vector<int> end_a, end_b;
  std::vector<std::int64_t> connection_id;
  std::vector<ConnectionClass> connection_class;
  std::vector<double> rest_length, stiffness;
  std::vector<double> tetra_volume;  // tetrahedral topology: volume of the tetrahedra incident on each connection
  std::vector<double> tetra_lloyd_sum;  // tetrahedral: sum over incident tetrahedra of l_equiv = (6 sqrt2 V)^(1/3)
  // The rank that owns end a writes the connection to files (each connection written exactly once).
  std::vector<int> written_here;     // local connection indices this rank writes

  int connections() const { return static_cast<int>(end_a.size()); }
};

// Collective. Builds this rank's LocalModel from the global body and the partition (the explicit path: every
// rank holds the whole body while it runs).
LocalModel distribute(const Body& body, const std::vector<int>& part, const PartitionStats& stats, MPI_Comm comm);

// Collective. This rank's LocalModel of the scene, by the cheapest path that describes it: box lattices are
// generated rank by rank from their stencils (partition/lattice_model.hpp), anything else goes through the
// explicit path.
LocalModel build_local_model(const Scene& scene, MPI_Comm comm);

}  // namespace tissue
