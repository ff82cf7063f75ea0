// The XDMF index of a series of snapshots, so that ParaView (Xdmf3ReaderS) and meshio (xdmf.TimeSeriesReader)
// open the whole run as one time series. The XML only points into the HDF5 snapshots; it holds no data.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace tissue {

// One frame of the series: a snapshot file and what it holds. Every snapshot must hold /molecules/positions
// and /connections/endpoints (the mesh); the other fields are listed only when the file has them.
struct XdmfEntry {
  std::string h5_file;  // relative to the .xdmf file's directory (a bare file name when they sit together)
  int64_t step = 0;
  double time = 0.0;
  int64_t molecules = 0;
  int64_t connections = 0;
  bool positions = true, endpoints = true;                          // the mesh: required by write_xdmf
  bool displacements = false, velocities = false, forces = false;  // /molecules/...
  bool connection_strain = false, connection_force = false;         // /connections/strain, /connections/force
  bool fibre_direction = false, fibre_stretch = false;              // /molecules/fibre_* (bodies with fibres)
  int64_t cells = 0;                                               // /cells/corners rows (0: no cells)
  int cell_nodes = 0;                                              // 8: hexahedra, 4: tetrahedra
  bool volume_ratio = false;                                       // /cells/volume_ratio
  bool cell_fibre_stretch = false;                                 // /cells/fibre_stretch
  int64_t lattice[3] = {0, 0, 0};  // a single box lattice: molecules along x, y, z (id = i + n_x (j + n_y k)); else 0
};

// Not collective: call on one rank (rank 0). Writes <path>.tmp and renames it to path, so readers never see a
// half-written index. Node attributes are named displacement, velocity, force; cell (connection) attributes
// strain and connection_force. Frames with cells also get a second temporal grid, "cells", written first (meshio's
// TimeSeriesReader reads the last one, the connections): hexahedra or tetrahedra on the same positions, with the
// same node attributes and the cell attribute volume_ratio. Throws std::runtime_error if the file cannot be written,
// std::invalid_argument for an entry without its mesh (positions, endpoints).
void write_xdmf(const std::string& path, const std::vector<XdmfEntry>& frames);

// Not collective: call on one rank. The same series for a single box lattice as a structured grid (3DSMesh: the
// topology is the lattice's dimensions, the geometry /molecules/positions), with the node attributes only: no
// per-connection list for ParaView to read, so a sample too large for its connection list in memory still opens.
// Written like write_xdmf (path.tmp, renamed). Throws std::invalid_argument for a frame without lattice dimensions
// that match its molecule count.
void write_lattice_xdmf(const std::string& path, const std::vector<XdmfEntry>& frames);

}  // namespace tissue
