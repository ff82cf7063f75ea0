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
  int block;  // row block: 0 molecules, 1 connections, 2 cells
  int width;
  const double* f64;
  const int64_t* i64;
  size_t size;
};

}  // namespace

XdmfEntry write_snapshot(const std::string& path, MPI_Comm comm, const SnapshotFrame& f) {
  const Field fields[] = {
      {"/molecules/positions", 0, 3, f.positions.data(), nullptr, f.positions.size()},
      {"/molecules/displacements", 0, 3, f.displacements.data(), nullptr, f.displacements.size()},
      {"/molecules/velocities", 0, 3, f.velocities.data(), nullptr, f.velocities.size()},
      {"/molecules/forces", 0, 3, f.forces.data(), nullptr, f.forces.size()},
      {"/connections/endpoints", 1, 2, nullptr, f.endpoints.data(), f.endpoints.size()},
      {"/connections/strain", 1, 1, f.connection_strain.data(), nullptr, f.connection_strain.size()},
      {"/connections/force", 1, 1, f.connection_force.data(), nullptr, f.connection_force.size()},
      {"/cells/corners", 2, f.cell_nodes, nullptr, f.cell_corners.data(), f.cell_corners.size()},
      {"/cells/volume_ratio", 2, 1, f.volume_ratio.data(), nullptr, f.volume_ratio.size()},
      {"/molecules/fibre_direction", 0, 3, f.fibre_direction.data(), nullptr, f.fibre_direction.size()},
      {"/molecules/fibre_stretch", 0, 1, f.fibre_stretch.data(), nullptr, f.fibre_stretch.size()},
      {"/cells/fibre_stretch", 2, 1, f.cell_fibre_stretch.data(), nullptr, f.cell_fibre_stretch.size()},
  };
  constexpr int n_fields = sizeof(fields) / sizeof(fields[0]);
  static_assert(n_fields == kSnapshotFields, "one entry a snapshot field, in SnapshotField's order");

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

  SnapshotHeader header;
  header.step = f.step, header.time = f.time, header.title = f.title;
  header.molecules = f.molecules, header.connections = f.connections;
  header.cells = f.cells, header.cell_nodes = f.cell_nodes;
  bool written[kSnapshotFields];
  for (int i = 0; i < n_fields; ++i) written[i] = any[i] != 0;
  return write_snapshot(path, comm, header, written,
                        [&](Hdf5File& file, SnapshotField i, const char* dataset, int64_t n, int width) {
                          const Field& d = fields[i];
                          const int64_t off = offsets[d.block], r = rows[d.block];
                          if (d.i64) file.write(dataset, n, width, off, r, d.i64);
                          else file.write(dataset, n, width, off, r, d.f64);
                        });
}

XdmfEntry write_snapshot(const std::string& path, MPI_Comm comm, const SnapshotHeader& h,
                         const bool (&present)[kSnapshotFields], const SnapshotFieldWriter& write_field,
                         const SnapshotFieldsWriter& write_connections) {
  struct Dataset {
    const char* name;
    const char* units;
    int block;  // row block: 0 molecules, 1 connections, 2 cells
    int width;
  };
  const Dataset datasets[kSnapshotFields] = {
      {"/molecules/positions", "m", 0, 3},      {"/molecules/displacements", "m", 0, 3},
      {"/molecules/velocities", "m/s", 0, 3},   {"/molecules/forces", "N", 0, 3},
      {"/connections/endpoints", "", 1, 2},     {"/connections/strain", "1", 1, 1},
      {"/connections/force", "N", 1, 1},        {"/cells/corners", "", 2, h.cell_nodes},
      {"/cells/volume_ratio", "1", 2, 1},       {"/molecules/fibre_direction", "1", 0, 3},
      {"/molecules/fibre_stretch", "1", 0, 1},  {"/cells/fibre_stretch", "1", 2, 1},
  };
  const int64_t counts[3] = {h.molecules, h.connections, h.cells};
  int ranks = 1;
  check_mpi(MPI_Comm_size(comm, &ranks), path, "MPI_Comm_size");
  // The space the file needs, reserved first: a full disk fails here, cleanly (Hdf5File::create).
  int64_t bytes = (1 << 20) + static_cast<int64_t>(h.title.size());
  for (int i = 0; i < kSnapshotFields; ++i)
    if (present[i]) bytes += 8 * datasets[i].width * counts[datasets[i].block];
  Hdf5File file = Hdf5File::create(path, comm, bytes);
  file.set_attribute("/", "kind", "snapshot");
  file.set_attribute("/", "program", "tissue");
  file.set_attribute("/", "version", TISSUE_VERSION);
  file.set_attribute("/", "title", h.title);
  file.set_attribute("/", "step", h.step);
  file.set_attribute("/", "time", h.time);
  file.set_attribute("/", "molecules", h.molecules);
  file.set_attribute("/", "connections", h.connections);
  file.set_attribute("/", "ranks", ranks);
  file.create_group("/molecules");
  file.create_group("/connections");
  if (present[kCellCorners] || present[kVolumeRatio]) file.create_group("/cells");
  for (int i = 0; i < kSnapshotFields; ++i) {
    if (!present[i]) continue;
    const Dataset& d = datasets[i];
    if (write_connections && d.block == 1) {
      // Every present field of the connections' block (they follow each other in SnapshotField order), at once.
      std::vector<SnapshotField> fields;
      std::vector<const char*> names;
      std::vector<int> widths;
      for (int j = i; j < kSnapshotFields && datasets[j].block == 1; ++j)
        if (present[j]) fields.push_back(static_cast<SnapshotField>(j)), names.push_back(datasets[j].name),
                        widths.push_back(datasets[j].width);
      write_connections(file, fields, names, counts[1], widths);
      for (const SnapshotField f : fields)
        if (*datasets[f].units) file.set_attribute(datasets[f].name, "units", datasets[f].units);
      i = fields.back();
      continue;
    }
    write_field(file, static_cast<SnapshotField>(i), d.name, counts[d.block], d.width);
    if (*d.units) file.set_attribute(d.name, "units", d.units);
  }
  file.close();

  XdmfEntry e;
  const size_t slash = path.find_last_of('/');
  e.h5_file = slash == std::string::npos ? path : path.substr(slash + 1);
  e.step = h.step;
  e.time = h.time;
  e.molecules = h.molecules;
  e.connections = h.connections;
  e.positions = present[kPositions];
  e.displacements = present[kDisplacements];
  e.velocities = present[kVelocities];
  e.forces = present[kForces];
  e.endpoints = present[kEndpoints];
  e.connection_strain = present[kConnectionStrain];
  e.connection_force = present[kConnectionForce];
  e.cells = present[kCellCorners] ? h.cells : 0;
  e.cell_nodes = h.cell_nodes;
  e.volume_ratio = present[kVolumeRatio];
  e.fibre_direction = present[kFibreDirection];
  e.fibre_stretch = present[kFibreStretch];
  e.cell_fibre_stretch = present[kCellFibreStretch];
  return e;
}

}  // namespace tissue
