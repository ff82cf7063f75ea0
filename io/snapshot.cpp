#include "io/snapshot.hpp"

#include <stdexcept>

#include "io/hdf5_file.hpp"

namespace tissue {

namespace {

void check_mpi(int rc, const std::string& path, const char* what) {
  if (rc != MPI_SUCCESS) throw std::runtime_error(path + ": " + what + " failed");
}

struct Field {
  const char* dataset;
  const char* units;
  int block;  // row block: 0 molecules, 1 connections, 2 cells
  int width;
  const double* f64;
  const int64_t* i64;
  size_t size;
};

}  // namespace

XdmfEntry write_snapshot(const std::string& path, MPI_Comm comm, const SnapshotFrame& f) {
  const Field fields[] = {
      {"/molecules/positions", "m", 0, 3, f.positions.data(), nullptr, f.positions.size()},
      {"/molecules/displacements", "m", 0, 3, f.displacements.data(), nullptr, f.displacements.size()},
      {"/molecules/velocities", "m/s", 0, 3, f.velocities.data(), nullptr, f.velocities.size()},
      {"/molecules/forces", "N", 0, 3, f.forces.data(), nullptr, f.forces.size()},
      {"/connections/endpoints", "", 1, 2, nullptr, f.endpoints.data(), f.endpoints.size()},
      {"/connections/strain", "1", 1, 1, f.connection_strain.data(), nullptr, f.connection_strain.size()},
      {"/connections/force", "N", 1, 1, f.connection_force.data(), nullptr, f.connection_force.size()},
      {"/cells/corners", "", 2, f.cell_nodes, nullptr, f.cell_corners.data(), f.cell_corners.size()},
      {"/cells/volume_ratio", "1", 2, 1, f.volume_ratio.data(), nullptr, f.volume_ratio.size()},
      {"/molecules/fibre_direction", "1", 0, 3, f.fibre_direction.data(), nullptr, f.fibre_direction.size()},
      {"/molecules/fibre_stretch", "1", 0, 1, f.fibre_stretch.data(), nullptr, f.fibre_stretch.size()},
  };
  constexpr int n_fields = sizeof(fields) / sizeof(fields[0]);

  int ranks = 1;
  check_mpi(MPI_Comm_size(comm, &ranks), path, "MPI_Comm_size");
  // The blocks must tile the ids in rank order: each offset is the sum of the rows before it.
  long long rows[3] = {f.molecule_rows, f.connection_rows, f.cell_rows}, before[3] = {0, 0, 0},
            total[3] = {0, 0, 0};
  check_mpi(MPI_Exscan(rows, before, 3, MPI_LONG_LONG, MPI_SUM, comm), path, "MPI_Exscan");
  int rank = 0;
  check_mpi(MPI_Comm_rank(comm, &rank), path, "MPI_Comm_rank");
  if (rank == 0) before[0] = before[1] = before[2] = 0;  // MPI_Exscan leaves rank 0's result undefined
  check_mpi(MPI_Allreduce(rows, total, 3, MPI_LONG_LONG, MPI_SUM, comm), path, "MPI_Allreduce");

  // A field is present if any rank has values for it; then every rank's length must match its rows.
  int present[n_fields];
  for (int i = 0; i < n_fields; ++i) present[i] = fields[i].size > 0;
  int any[n_fields];
  check_mpi(MPI_Allreduce(present, any, n_fields, MPI_INT, MPI_MAX, comm), path, "MPI_Allreduce");
  const int64_t counts[3] = {f.molecules, f.connections, f.cells}, offsets[3] = {f.molecule_offset,
                                                                                  f.connection_offset, f.cell_offset};
  int bad = 0;
  for (int b = 0; b < 3; ++b) bad = bad || before[b] != offsets[b] || total[b] != counts[b];
  bad = bad || (f.cells > 0 && f.cell_nodes != 8 && f.cell_nodes != 4);
  std::string why = bad ? "the row blocks do not tile the molecules, connections and cells in rank order" : "";
  for (int i = 0; i < n_fields && !bad; ++i) {
    const int64_t r = rows[fields[i].block];
    if (any[i] && fields[i].size != static_cast<size_t>(r * fields[i].width)) {
      bad = 1;
      why = std::string(fields[i].dataset) + " has " + std::to_string(fields[i].size) + " values for " +
            std::to_string(r) + " rows of " + std::to_string(fields[i].width);
    }
  }
  int any_bad = 0;
  check_mpi(MPI_Allreduce(&bad, &any_bad, 1, MPI_INT, MPI_MAX, comm), path, "MPI_Allreduce");
  if (any_bad)
    throw std::invalid_argument(path + ": bad snapshot frame: " + (bad ? why : "see another rank's error"));

  // The space the file needs, reserved first: a full disk fails here, cleanly (Hdf5File::create).
  int64_t bytes = (1 << 20) + static_cast<int64_t>(f.title.size());
  for (int i = 0; i < n_fields; ++i)
    if (any[i]) bytes += 8 * fields[i].width * counts[fields[i].block];
  Hdf5File file = Hdf5File::create(path, comm, bytes);
  file.set_attribute("/", "kind", "snapshot");
  file.set_attribute("/", "program", "tissue");
  file.set_attribute("/", "version", TISSUE_VERSION);
  file.set_attribute("/", "title", f.title);
  file.set_attribute("/", "step", f.step);
  file.set_attribute("/", "time", f.time);
  file.set_attribute("/", "molecules", f.molecules);
  file.set_attribute("/", "connections", f.connections);
  file.set_attribute("/", "ranks", ranks);
  file.create_group("/molecules");
  file.create_group("/connections");
  if (any[7] || any[8]) file.create_group("/cells");
  for (int i = 0; i < n_fields; ++i) {
    if (!any[i]) continue;
    const Field& d = fields[i];
    const int64_t n = counts[d.block], off = offsets[d.block], r = rows[d.block];
    if (d.i64) file.write(d.dataset, n, d.width, off, r, d.i64);
    else file.write(d.dataset, n, d.width, off, r, d.f64);
    if (*d.units) file.set_attribute(d.dataset, "units", d.units);
  }
  file.close();

  XdmfEntry e;
  const size_t slash = path.find_last_of('/');
  e.h5_file = slash == std::string::npos ? path : path.substr(slash + 1);
  e.step = f.step;
  e.time = f.time;
  e.molecules = f.molecules;
  e.connections = f.connections;
  e.positions = any[0];
  e.displacements = any[1];
  e.velocities = any[2];
  e.forces = any[3];
  e.endpoints = any[4];
  e.connection_strain = any[5];
  e.connection_force = any[6];
  e.cells = any[7] ? f.cells : 0;
  e.cell_nodes = f.cell_nodes;
  e.volume_ratio = any[8];
  e.fibre_direction = any[9];
  e.fibre_stretch = any[10];
  return e;
}

}  // namespace tissue
