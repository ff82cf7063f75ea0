// HDF5 snapshots: the state of a run at one step, in original (global id) order, so files do not depend on the
// partition. Layout:
//   /molecules/positions, displacements, velocities, forces   [N x 3] double
//   /connections/endpoints [C x 2] int64 (a < b), strain [C x 1], force [C x 1] double
//   /cells/corners [M x nodes] int64 (molecule ids: hexahedra of 8 corners in VTK order, or tetrahedra of 4),
//   /cells/volume_ratio [M x 1] double (J = det F): only when the scene has cells (the cell term)
//   /cells/fibre_stretch [M x 1] double (|F a|, 0 for a cell without fibres): cells of a scene with fibres
//   root attributes: kind = "snapshot", program = "tissue", version, title, step, time, molecules, connections,
//   ranks (the writer's communicator size)
// Only the fields a frame holds are written: a scene asks for them, and absent fields cost nothing.
#pragma once
#include <mpi.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "io/xdmf.hpp"

namespace tissue {

// One rank's share of a snapshot. The blocks are natural-order blocks (see partition/NaturalOrder): this rank
// holds molecules [molecule_offset, molecule_offset + molecule_rows) and likewise connections; the blocks of
// all ranks, in rank order, tile 0..N-1 and 0..C-1. A field is written when any rank holds values for it, so
// a rank with zero rows leaves every vector empty; a rank with rows gives every written field in full.
// step, time, title, molecules and connections must be the same on every rank (HDF5 metadata is collective).
struct SnapshotFrame {
  int64_t step = 0;
  double time = 0.0;
  std::string title;
  int64_t molecules = 0;    // N
  int64_t connections = 0;  // C

  int64_t molecule_offset = 0, molecule_rows = 0;
  std::vector<double> positions, displacements, velocities, forces;  // 3 * molecule_rows each, or empty
  // Bodies with fibres (docs/anisotropy.md): the deformed fibre direction (3) and stretch (1) per molecule.
  std::vector<double> fibre_direction, fibre_stretch;

  int64_t connection_offset = 0, connection_rows = 0;
  std::vector<int64_t> endpoints;                        // 2 * connection_rows, or empty
  std::vector<double> connection_strain, connection_force;  // connection_rows, or empty

  // Cells (a third block, tiled like the others): cells = 0 writes no /cells group.
  int64_t cells = 0;  // M
  int cell_nodes = 0;  // 8 or 4 (the same on every rank)
  int64_t cell_offset = 0, cell_rows = 0;
  std::vector<int64_t> cell_corners;  // cell_nodes * cell_rows
  std::vector<double> volume_ratio;   // cell_rows
  std::vector<double> cell_fibre_stretch;  // cell_rows, or empty
};

// What every snapshot file says about itself (root attributes, the XDMF entry): the same on every rank.
struct SnapshotHeader {
  int64_t step = 0;
  double time = 0.0;
  std::string title;
  int64_t molecules = 0, connections = 0;
  int64_t cells = 0;   // M (0: no /cells group)
  int cell_nodes = 0;  // 8 or 4
};

// The datasets a snapshot may hold, in the order they are written.
enum SnapshotField {
  kPositions, kDisplacements, kVelocities, kForces, kEndpoints, kConnectionStrain, kConnectionForce, kCellCorners,
  kVolumeRatio, kFibreDirection, kFibreStretch, kCellFibreStretch, kSnapshotFields
};

class Hdf5File;
// Collective: writes one field's dataset [global_rows x width] into the open file (Hdf5File::write or
// write_pieces), in original order.
using SnapshotFieldWriter =
    std::function<void(Hdf5File& file, SnapshotField field, const char* dataset, int64_t global_rows, int width)>;

// Collective: writes the fields of one row block (in SnapshotField order, datasets[i] of widths[i] for fields[i])
// into the open file at once (RowStream::write_columns), so that what their rows share is computed once.
using SnapshotFieldsWriter =
    std::function<void(Hdf5File& file, const std::vector<SnapshotField>& fields,
                       const std::vector<const char*>& datasets, int64_t global_rows, const std::vector<int>& widths)>;

// Collective over comm. Writes path atomically (path.tmp, renamed when complete) with the header's attributes and
// the fields `present` marks (the same on every rank), each by `write_field`, or, given `write_connections`, the
// connections' fields (endpoints, strain, force) by one call of it; the files are those of the SnapshotFrame
// overload below. Returns the frame's XDMF entry (file name without directory).
XdmfEntry write_snapshot(const std::string& path, MPI_Comm comm, const SnapshotHeader& header,
                         const bool (&present)[kSnapshotFields], const SnapshotFieldWriter& write_field,
                         const SnapshotFieldsWriter& write_connections = nullptr);

// Collective over comm. Writes path atomically (path.tmp, renamed when complete). Throws std::invalid_argument
// (on every rank) when the blocks do not tile 0..N-1 / 0..C-1 or a field has the wrong length, and
// std::runtime_error for I/O failures. Returns the frame's XDMF entry (file name without directory), the same
// on every rank, for write_xdmf.
XdmfEntry write_snapshot(const std::string& path, MPI_Comm comm, const SnapshotFrame& frame);

}  // namespace tissue
