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
  bool molecule;  // row block: molecules or connections
  int width;
  const double* f64;
  const int64_t* i64;
  size_t size;
};

}  // namespace

XdmfEntry write_snapshot(const std::string& path, MPI_Comm comm, const SnapshotFrame& f) {
  const Field fields[] = {
      {"/molecules/positions", "m", true, 3, f.positions.data(), nullptr, f.positions.size()},
      {"/molecules/displacements", "m", true, 3, f.displacements.data(), nullptr, f.displacements.size()},
      {"/molecules/velocities", "m/s", true, 3, f.velocities.data(), nullptr, f.velocities.size()},
      {"/molecules/forces", "N", true, 3, f.forces.data(), nullptr, f.forces.size()},
      {"/connections/endpoints", "", false, 2, nullptr, f.endpoints.data(), f.endpoints.size()},
      {"/connections/strain", "1", false, 1, f.connection_strain.data(), nullptr, f.connection_strain.size()},
      {"/connections/force", "N", false, 1, f.connection_force.data(), nullptr, f.connection_force.size()},
      {"/molecules/fibre_direction", "1", true, 3, f.fibre_direction.data(), nullptr, f.fibre_direction.size()},
      {"/molecules/fibre_stretch", "1", true, 1, f.fibre_stretch.data(), nullptr, f.fibre_stretch.size()},
  };
  constexpr int n_fields = sizeof(fields) / sizeof(fields[0]);

  int ranks = 1;
  check_mpi(MPI_Comm_size(comm, &ranks), path, "MPI_Comm_size");
  // The blocks must tile the ids in rank order: each offset is the sum of the rows before it.
  long long rows[2] = {f.molecule_rows, f.connection_rows}, before[2] = {0, 0}, total[2] = {0, 0};
  check_mpi(MPI_Exscan(rows, before, 2, MPI_LONG_LONG, MPI_SUM, comm), path, "MPI_Exscan");
  int rank = 0;
  check_mpi(MPI_Comm_rank(comm, &rank), path, "MPI_Comm_rank");
  if (rank == 0) before[0] = before[1] = 0;  // MPI_Exscan leaves rank 0's result undefined
  check_mpi(MPI_Allreduce(rows, total, 2, MPI_LONG_LONG, MPI_SUM, comm), path, "MPI_Allreduce");

  // A field is present if any rank has values for it; then every rank's length must match its rows.
  int present[n_fields];
  for (int i = 0; i < n_fields; ++i) present[i] = fields[i].size > 0;
  int any[n_fields];
  check_mpi(MPI_Allreduce(present, any, n_fields, MPI_INT, MPI_MAX, comm), path, "MPI_Allreduce");
  int bad = before[0] != f.molecule_offset || before[1] != f.connection_offset || total[0] != f.molecules ||
            total[1] != f.connections;
  std::string why = bad ? "the row blocks do not tile the molecules and connections in rank order" : "";
  for (int i = 0; i < n_fields && !bad; ++i) {
    const int64_t r = fields[i].molecule ? f.molecule_rows : f.connection_rows;
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
    if (any[i]) bytes += 8 * fields[i].width * (fields[i].molecule ? f.molecules : f.connections);
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
  for (int i = 0; i < n_fields; ++i) {
    if (!any[i]) continue;
    const Field& d = fields[i];
    const int64_t n = d.molecule ? f.molecules : f.connections;
    const int64_t off = d.molecule ? f.molecule_offset : f.connection_offset;
    const int64_t r = d.molecule ? f.molecule_rows : f.connection_rows;
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
  e.fibre_direction = any[7];
  e.fibre_stretch = any[8];
  return e;
}

}  // namespace tissue
