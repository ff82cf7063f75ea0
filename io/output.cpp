#include "io/output.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "io/atomic_file.hpp"
#include "io/checkpoint.hpp"
#include "io/hdf5_file.hpp"
#include "io/row_stream.hpp"
#include "io/snapshot.hpp"
#include "io/summary.hpp"
#include "partition/agreement.hpp"
#include "src/calibration/calibration.hpp"
#include "src/model/cell_law.hpp"

namespace tissue {

namespace {

// Bodies with fibres (docs/anisotropy.md): the deformed fibre direction and stretch per molecule, 0 where no fibre
// cell touches the molecule. Decided from the scene, so every rank takes part in the collective reordering.
bool scene_has_fibres(const Scene& scene) {
  const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
  for (std::size_t b = 0; b < specs.size(); ++b)
    if (specs[b].has_fibres()) {
      const CalibrationSpec& c = b < scene.calibrations.size() ? scene.calibrations[b] : scene.calibration;
      if (body_has_cells(specs[b], c) || body_has_tetrahedra(specs[b], c)) return true;  // lattice cells or tetrahedra
    }
  return false;
}

bool wants(const Scene& s, const char* field) {
  return std::find(s.output.fields.begin(), s.output.fields.end(), field) != s.output.fields.end();
}

void make_directories(const std::string& path) {
  std::string partial;
  for (std::size_t i = 0; i <= path.size(); ++i) {
    if (i == path.size() || path[i] == '/') {
      if (!partial.empty() && mkdir(partial.c_str(), 0755) != 0 && errno != EEXIST)
        throw OutputError(partial + ": cannot create directory: " + std::strerror(errno));
    }
    if (i < path.size()) partial += path[i];
  }
}

}  // namespace

Output::Output(const Scene& scene, const LocalModel& model)
    : scene_(scene),
      model_(model) {}

void Output::make_directory() {
  if (directory_made_) return;
  // Agreed: rank 0 alone creates it, and a failure stops every rank with its line (never a hang).
  agree(model_.comm, [&] {
    if (model_.rank == 0) make_directories(scene_.output.directory);
  });
  directory_made_ = true;
}

void Output::snapshot(const SolverState& state, const ForceModel& forces, bool final, const char* file_name) {
  if (scene_.output.fields.empty()) return;  // `fields = []`: the scene asks for no snapshot, and pays for none
  // One agreed stage: a failure on any rank (a full disk, a quota, an I/O error) is the same OutputError on
  // every rank, and the run stops with exit 3 (a snapshot the user asked for is never silently missing).
  const std::string name = file_name ? file_name : final ? "final.h5" : snapshot_name(state.step);
  const std::string path = scene_.output.directory + "/" + name;
  StageDeadline deadline(model_.comm, path, stage_seconds(stage_bytes()), path + ".tmp");
  agree(model_.comm, [&] { write_snapshot_stage(state, forces, final, file_name); });
}

std::string Output::snapshot_name(long step) {
  char name[64];
  std::snprintf(name, sizeof name, "snapshot_%08ld.h5", step);
  return name;
}

double Output::stage_bytes() const {
  // At most: 4 vectors of 3 doubles per molecule, the endpoints and 3 doubles per connection, (fewer cells
  // than molecules) 8 corners and J per cell, and with fibres a direction and a stretch per molecule.
  const double cells = scene_has_cells(scene_) ? 72.0 * static_cast<double>(model_.global_molecules) : 0.0;
  const double fibres = scene_has_fibres(scene_) ? 32.0 * static_cast<double>(model_.global_molecules) : 0.0;
  return 96.0 * static_cast<double>(model_.global_molecules) + 40.0 * static_cast<double>(model_.global_connections) +
         cells + fibres;
}

const RowStream& Output::molecule_rows() {
  // Owned molecules are in increasing id order: when the first and last ids span exactly their count, every id
  // between is one of them (a lattice's slabs, and every molecule at 1 rank), and the stream needs no id list.
  const LocalModel& m = model_;
  if (!molecule_rows_ && m.owned > 0 && m.id[m.owned - 1] - m.id[0] + 1 == m.owned)
    molecule_rows_ = std::make_unique<RowStream>(m.comm, m.global_molecules, m.owned, RowStream::Consecutive{m.id[0]});
  if (!molecule_rows_)
    molecule_rows_ = std::make_unique<RowStream>(
        model_.comm, model_.global_molecules, model_.owned,
        [&m = model_](std::int64_t first, std::int64_t end, std::int64_t* ids) {
          for (std::int64_t k = first; k < end; ++k) *ids++ = m.id[static_cast<int>(k)];
        },
        RowStream::Batched{});
  return *molecule_rows_;
}

const RowStream& Output::connection_rows() {
  // The same for connections, when this rank writes every one it holds (no end a a ghost: every connection at 1
  // rank) and their ids, increasing, span exactly their count.
  const LocalModel& m = model_;
  const int n = m.connections();
  if (!connection_rows_ && n > 0 && m.written_count == static_cast<std::size_t>(n) &&
      m.connection_id(n - 1) - m.connection_id(0) + 1 == n)
    connection_rows_ = std::make_unique<RowStream>(m.comm, m.global_connections, n,
                                                   RowStream::Consecutive{m.connection_id(0)});
  if (!connection_rows_)
    connection_rows_ = std::make_unique<RowStream>(
        model_.comm, model_.global_connections, model_.connections(),
        [&m = model_](std::int64_t first, std::int64_t end, std::int64_t* ids) {
          // A batch's ends a decoded at once; an owned end a has its connections consecutive and in order, so the
          // position among them (m.connection_id's second term) counts up from the batch's first.
          int a[RowStream::kBatch];
          const int c0 = static_cast<int>(first), n = static_cast<int>(end - first);
          m.end_a.decode(c0, c0 + n, a);
          const bool lattice = m.forward_rank.empty();
          int position = 0;
          for (int j = 0; j < n; ++j) {
            if (a[j] >= m.owned) {
              ids[j] = -1;
              continue;
            }
            if (!lattice) position = m.forward_rank[c0 + j];
            else if (j == 0 || a[j - 1] != a[j]) position = j == 0 ? m.end_a.row_position(c0) : 0;
            else ++position;
            ids[j] = m.first_connection[a[j]] + position;
          }
        },
        RowStream::Batched{});
  return *connection_rows_;
}

void Output::write_snapshot_stage(const SolverState& state, const ForceModel& forces, bool final,
                                  const char* file_name) {
  make_directory();
  const double* x = state.x.array();
  const LocalModel& m = model_;
  SnapshotHeader header;
  header.step = state.step;
  header.time = state.time;
  header.title = scene_.title;
  header.molecules = m.global_molecules;
  header.connections = m.global_connections;
  // Cells (the cell term's): their corners and volume ratio J, whatever the fields (the cells are the mesh
  // ParaView shows J on); a scene without cells computes nothing here.
  const CellField cells = forces.cells(x);
  if (cells.global_count > 0 && !cells_) cells_ = std::make_unique<NaturalOrder>(m.comm, cells.id, cells.global_count);
  header.cells = cells.global_count;
  header.cell_nodes = cells.nodes;
  bool present[kSnapshotFields] = {};
  present[kPositions] = present[kEndpoints] = true;  // the mesh
  present[kDisplacements] = wants(scene_, "displacements");
  present[kVelocities] = wants(scene_, "velocities");
  present[kForces] = wants(scene_, "forces");
  present[kConnectionStrain] = wants(scene_, "connection_strain");
  present[kConnectionForce] = wants(scene_, "connection_force");
  present[kCellCorners] = present[kVolumeRatio] = cells.global_count > 0;
  present[kFibreDirection] = present[kFibreStretch] = scene_has_fibres(scene_);
  present[kCellFibreStretch] = present[kVolumeRatio] && present[kFibreStretch];
  // Every field goes out in pieces, computed from the state as its rows are sent (RowStream): nothing the size of
  // a field is held, except a field that only exists whole (the connection forces on each molecule, the fibres).
  std::vector<double> fibre_direction, fibre_stretch;
  constexpr RowStream::Checksum kSkip = RowStream::Checksum::skip;  // a snapshot carries no row hashes
  // Rows a batch at a time (RowStream::write_double_rows): molecules' rows are slices of the state's arrays, a
  // connection's ends are decoded once a batch.
  auto copy3 = [](const double* from) {
    return [from](std::int64_t first, std::int64_t end, const std::int64_t*, double* rows) {
      std::copy(from + 3 * first, from + 3 * end, rows);
    };
  };
  // The connections' fields at once (RowStream::write_columns): a batch's ends are decoded once for its endpoints,
  // strains and forces, and each connection's length computed once for both of the last two.
  auto write_connections = [&](Hdf5File& file, const std::vector<SnapshotField>& fields,
                               const std::vector<const char*>& datasets, std::int64_t, const std::vector<int>& widths) {
    std::vector<RowStream::Column> columns;
    int endpoints = -1, strain = -1, force = -1;
    for (std::size_t i = 0; i < fields.size(); ++i) {
      columns.push_back({datasets[i], widths[i], fields[i] == kEndpoints});
      (fields[i] == kEndpoints ? endpoints : fields[i] == kConnectionStrain ? strain : force) = static_cast<int>(i);
    }
    // Where the owned molecules' ids are consecutive (every molecule at 1 rank, a lattice's slab), an owned end's
    // id is an addition instead of a lookup in the ids' runs (two a connection: most of the endpoints' CPU).
    const int direct = m.owned > 0 && m.id[m.owned - 1] - m.id[0] + 1 == m.owned ? m.owned : 0;
    const std::int64_t id0 = direct > 0 ? m.id[0] : 0;
    const ConnectionColumn l0 = m.table.rest_length_column(), k = m.table.stiffness_column();
    connection_rows().write_columns(file, columns, [&](std::int64_t first, std::int64_t end, const std::int64_t*,
                                                       void* const* rows) {
      int a[RowStream::kBatch], b[RowStream::kBatch];
      const int c0 = static_cast<int>(first), n = static_cast<int>(end - first);
      m.end_a.decode(c0, c0 + n, a);
      m.end_b.decode(c0, c0 + n, b);
      if (std::int64_t* e = endpoints >= 0 ? static_cast<std::int64_t*>(rows[endpoints]) : nullptr)  // molecule ids
        for (int j = 0; j < n; ++j) {
          e[2 * j] = a[j] < direct ? id0 + a[j] : m.id[a[j]];
          e[2 * j + 1] = b[j] < direct ? id0 + b[j] : m.id[b[j]];
        }
      double* strains = strain >= 0 ? static_cast<double*>(rows[strain]) : nullptr;
      double* spring_forces = force >= 0 ? static_cast<double*>(rows[force]) : nullptr;
      if (!strains && !spring_forces) return;
      for (int j = 0; j < n; ++j) {
        const double* xa = x + 3 * a[j];
        const double* xb = x + 3 * b[j];
        const double len = std::sqrt((xb[0] - xa[0]) * (xb[0] - xa[0]) + (xb[1] - xa[1]) * (xb[1] - xa[1]) +
                                     (xb[2] - xa[2]) * (xb[2] - xa[2]));
        const double rest = l0[c0 + j], stretch = len - rest;
        if (strains) strains[j] = stretch / rest;
        if (spring_forces) spring_forces[j] = k[c0 + j] * stretch;
      }
    });
  };
  auto write_field = [&](Hdf5File& file, SnapshotField field, const char* dataset, std::int64_t, int width) {
    switch (field) {
      case kPositions: molecule_rows().write_double_rows(file, dataset, width, copy3(x), kSkip); break;
      case kDisplacements:
        molecule_rows().write_double_rows(file, dataset, width,
                                          [&](std::int64_t first, std::int64_t end, const std::int64_t*, double* rows) {
          for (std::int64_t i = 3 * first; i < 3 * end; ++i) *rows++ = x[i] - m.rest[i];
        }, kSkip);
        break;
      case kVelocities: molecule_rows().write_double_rows(file, dataset, width, copy3(state.v.data()), kSkip); break;
      case kForces: {
        // The connection forces on each molecule: they balance the loads at equilibrium and are the reactions at
        // held molecules (the net force, zero at equilibrium, would show nothing).
        std::vector<double> f(3 * m.local);
        forces.connection_forces(x, f.data());
        molecule_rows().write_double_rows(file, dataset, width, copy3(f.data()), kSkip);
        break;
      }
      case kEndpoints:
      case kConnectionStrain:
      case kConnectionForce:  // the connections' block: write_connections, all at once
        throw std::logic_error(std::string(dataset) + ": a connection field is written with the others");
      case kCellCorners: {
        const std::vector<std::int64_t> rows = cells_->to_natural_ids(cells.corners.data(), cells.nodes);
        file.write(dataset, cells.global_count, width, cells_->begin(), cells_->count(), rows.data());
        break;
      }
      case kVolumeRatio: {
        const std::vector<double> rows = cells_->to_natural(cells.volume_ratio.data(), 1);
        file.write(dataset, cells.global_count, width, cells_->begin(), cells_->count(), rows.data());
        break;
      }
      case kCellFibreStretch: {
        const std::vector<double> rows = cells_->to_natural(cells.fibre_stretch.data(), 1);
        file.write(dataset, cells.global_count, width, cells_->begin(), cells_->count(), rows.data());
        break;
      }
      case kFibreDirection:
        // Bodies with fibres (docs/anisotropy.md): the deformed fibre direction and stretch per molecule, 0 where
        // no fibre cell touches the molecule.
        fibre_direction.assign(3 * m.owned, 0.0), fibre_stretch.assign(m.owned, 0.0);
        forces.fibre_field(x, fibre_direction.data(), fibre_stretch.data());
        molecule_rows().write_double_rows(file, dataset, width, copy3(fibre_direction.data()), kSkip);
        break;
      case kFibreStretch:
        molecule_rows().write_double_rows(file, dataset, width,
                                          [&](std::int64_t first, std::int64_t end, const std::int64_t*, double* rows) {
          std::copy(fibre_stretch.data() + first, fibre_stretch.data() + end, rows);
        }, kSkip);
        break;
      case kSnapshotFields: break;
    }
  };
  const std::string name = file_name ? file_name : final ? "final.h5" : snapshot_name(state.step);
  const std::string dir = scene_.output.directory + "/";
  frames_.push_back(write_snapshot(dir + name, m.comm, header, present, write_field, write_connections));
  RowStream::release();
  // A single box lattice is also a structured grid: lattice.xdmf, the same series without the connection list.
  const bool box = m.shape.bodies() == 1 && !m.shape.unstructured() &&
                   static_cast<std::int64_t>(m.shape.n[0]) * m.shape.n[1] * m.shape.n[2] == m.global_molecules;
  if (box)
    for (int a = 0; a < 3; ++a) frames_.back().lattice[a] = m.shape.n[a];
  agree(m.comm, [&] {
    if (m.rank != 0) return;
    write_xdmf(dir + "tissue.xdmf", frames_);
    if (box) write_lattice_xdmf(dir + "lattice.xdmf", frames_);
  });
}

std::string Output::checkpoint(const SolverState& state, const ForceModel* forces) {
  char name[64];
  std::snprintf(name, sizeof name, "checkpoint_%010ld.h5", state.step);
  const std::string path = scene_.output.directory + "/" + name;
  StageDeadline deadline(model_.comm, path, stage_seconds(stage_bytes()), path + ".tmp");
  return agree(model_.comm, [&] {
    make_directory();
    const std::string written = write_checkpoint(scene_.output.directory, 2, scene_, model_, molecule_rows(),
                                                 connection_rows(), state, forces);
    RowStream::release();
    return written;
  });
}

void Output::history_row(const SolverState& state, const ForceModel& forces, const TensionTest& test) {
  // (a dynamic run's state may be its three streams: measure() reads either layout)
  const Measurements m =
      measure(scene_, model_, test, state.x.array(), state.v.data(), state.x_streams, state.v_streams, state.time);
  // Dynamic runs and the static solve's last row: the reactions of the step's own force evaluation (no second one
  // per row; src/solvers/solver.hpp, forces_final). Static load steps:
  // the step's fraction of the loads; their rows count the load steps, and `time` is that fraction (pseudo-time).
  const SolverStyle* kind = find_solver(scene_.solver.kind);
  const bool load_steps = !kind->time_line;
  std::vector<Vec3> reactions;
  if (kind->integrates_time || (state.forces_final && state.load_factor == 1.0)) {
    reactions = forces.last_reactions();
  } else {
    std::vector<double> scratch(3 * model_.local);
    reactions = forces.reactions(state.x.array(), state.v.data(), scratch.data(), state.load_factor);
  }
  Vec3 applied = forces.applied_total(state.time);
  if (load_steps)
    for (double& c : applied) c *= state.load_factor;
  const long step = load_steps ? history_rows_ + 1 : state.step;
  const double time = load_steps ? state.load_factor : state.time;
  make_directory();  // collective (agreed): before rank 0 goes on alone
  const std::string path = scene_.output.directory + "/history.csv";
  agree(model_.comm, [&] {
    if (model_.rank != 0) return;
    std::string text;
    char cell[40];
    auto number = [&](double v) {
      std::snprintf(cell, sizeof cell, ",%.17g", v);
      text += cell;
    };
    if (!history_started_) {
      text = "step,time,force_x,force_y,force_z,elongation,kinetic_energy";
      for (std::size_t f = 0; f < reactions.size(); ++f)
        for (const char* axis : {"x", "y", "z"}) text += ",reaction" + std::to_string(f) + "_" + axis;
      text += ",lateral_strain\n";
    }
    text += std::to_string(step);
    number(time);
    for (double c : applied) number(c);
    if (m.elongation) number(*m.elongation);
    else text += ",";
    number(m.kinetic_energy);
    for (const Vec3& r : reactions)
      for (double c : r) number(c);
    if (m.lateral_strain) number(*m.lateral_strain);
    else text += ",";
    text += "\n";
    // The row in write() calls of its own (no stdio buffer): in the file when this returns, and a failed write is
    // this call's, named with its error.
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | (history_started_ ? O_APPEND : O_TRUNC), 0644);
    if (fd < 0) throw OutputError(path + ": cannot open: " + std::strerror(errno));
    for (std::size_t done = 0; done < text.size();) {
      const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        const int error = n < 0 ? errno : EIO;
        ::close(fd);
        throw OutputError(path + ": cannot write: " + std::strerror(error));
      }
      done += static_cast<std::size_t>(n);
    }
    if (::close(fd) != 0) throw OutputError(path + ": cannot write: " + std::strerror(errno));
  });
  history_started_ = true;
  ++history_rows_;
}

void Output::continue_history(long step) {
  const std::string path = scene_.output.directory + "/history.csv";
  int kept = agree(model_.comm, [&] {
    if (model_.rank != 0) return 0;
    FILE* file = std::fopen(path.c_str(), "r");
    if (!file) return 0;  // a restart into another directory: the file starts anew
    std::string text, line;
    bool header = true;
    for (int ch; (ch = std::fgetc(file)) != EOF;) {
      line += static_cast<char>(ch);
      if (ch != '\n') continue;
      // The header, then the rows whose step (the first cell) is at most the checkpoint's; a row a crash cut
      // short (no newline) is dropped.
      if (header || std::strtol(line.c_str(), nullptr, 10) <= step) text += line;
      header = false;
      line.clear();
    }
    std::fclose(file);
    if (text.empty()) return 0;
    write_file_atomically(path, text);
    return 1;
  });
  MPI_Bcast(&kept, 1, MPI_INT, 0, model_.comm);
  history_started_ = kept != 0;
}

void Output::summary(const TensionTest& test, const Measurements& measured, const Measurements& initial,
                     const SolveReport& report, const SolverState& state, double wall_seconds,
                     const std::string& failure) {
  const std::string path = scene_.output.directory + "/summary.json";
  StageDeadline deadline(model_.comm, path, stage_seconds(0), path + ".tmp");
  long peak = peak_memory_bytes(), peak_max = 0;
  MPI_Allreduce(&peak, &peak_max, 1, MPI_LONG, MPI_MAX, model_.comm);
  make_directory();  // collective (agreed): before rank 0 goes on alone
  // Rank 0 writes; every rank learns whether it could (one agreed stage).
  agree(model_.comm, [&] {
    if (model_.rank == 0) write_summary(test, measured, initial, report, state, wall_seconds, failure, peak_max);
  });
}

void Output::write_summary(const TensionTest& test, const Measurements& measured, const Measurements& initial,
                           const SolveReport& report, const SolverState& state, double wall_seconds,
                           const std::string& failure, long peak_max) {
  using nlohmann::json;
  auto opt = [](const std::optional<double>& v) { return v ? json(*v) : json(nullptr); };
  // Eq. 3 reads the body the load is on, along the load (a fibre body's E depends on the direction)
  const double target = youngs_modulus_along(
      test.body < static_cast<int>(scene_.bodies.size()) ? scene_.bodies[test.body] : scene_.body, test.axis);
  // What the solver kind reports (an unknown kind: a failure before any solve, reported as the scene's).
  const SolverStyle* kind = report.kind ? report.kind : find_solver(scene_.solver.kind);
  const bool dynamic = kind->integrates_time;
  json s;
  s["title"] = scene_.title;
  s["scene"] = scene_.file;
  s["version"] = TISSUE_VERSION;
  s["molecules"] = model_.global_molecules;
  s["connections"] = model_.global_connections;
  s["ranks"] = model_.size;
  s["topology"] = model_.shape.topology;
  s["youngs_modulus_target"] = target;
  s["youngs_modulus_measured"] = opt(measured.youngs_modulus);
  s["error_percent"] = measured.youngs_modulus ? json(100.0 * (*measured.youngs_modulus - target) / target)
                                               : json(nullptr);
  s["elongation"] = opt(measured.elongation);
  s["rest_length"] = test.valid ? json(test.rest_length) : json(nullptr);
  s["cross_section"] = test.valid ? json(test.cross_section) : json(nullptr);
  s["applied_force"] = opt(measured.applied_force);  // the load at the state's time (its history applied)
  s["poisson_ratio_measured"] = opt(measured.poisson_ratio);
  s["poisson_ratios_measured"] =
      measured.poisson_ratios ? json(*measured.poisson_ratios) : json(nullptr);
  s["shear_modulus_measured"] = opt(measured.shear_modulus);
  s["aggregate_modulus_measured"] = opt(measured.aggregate_modulus);
  auto divisor = [](const CalibrationSpec& c) {  // C, where the method reads it as given
    return find_calibration(c.method)->reads_divisor ? json(c.divisor) : json(nullptr);
  };
  s["calibration"] = {{"method", scene_.calibration.method}, {"divisor", divisor(scene_.calibration)}};
  if (find_calibration(scene_.calibration.method)->wrap_solver) {  // the final C and the updates it took (iterative.cpp)
    s["calibration"]["divisor_initial"] = scene_.calibration.divisor;
    s["calibration"]["divisor"] = opt(report.calibration_divisor);
    s["calibration"]["updates"] = report.calibration_updates;
    s["calibration"]["tolerance"] = scene_.calibration.tolerance;
  }
  if (scene_.calibrations.size() > 1) {  // several bodies: each body's own method, in body order
    json bodies = json::array();
    for (const auto& c : scene_.calibrations)
      bodies.push_back({{"method", c.method}, {"divisor", divisor(c)}});
    s["calibration"]["bodies"] = bodies;
  }
  s["solver"] = {{"kind", kind_name(report)},
                 {"iterations", report.iterations},
                 {"linear_iterations", kind->newton ? json(report.linear_iterations) : json(nullptr)},
                 {"residual", dynamic ? json(nullptr) : json(report.residual)},
                 {"residual_history", report.residual_history},
                 {"converged", report.converged},
                 {"tolerance", scene_.solver.tolerance},
                 {"tolerance_used", dynamic ? json(nullptr) : json(report.tolerance_used)},
                 {"time_step", kind->explicit_steps ? json(report.time_step) : json(nullptr)},
                 {"critical_time_step", report.critical_time_step > 0 ? json(report.critical_time_step)
                                                                      : json(nullptr)},
                 {"note", report.note},
                 // (unknown at a checkpoint, while the solve goes on)
                 {"seconds", report.running ? json(nullptr) : json(report.seconds)},
                 {"cpu_seconds", report.running ? json(nullptr) : json(report.cpu_seconds)},
                 {"guard_checks", kind->explicit_steps && !report.running ? json(report.guard_checks) : json(nullptr)},
                 {"guard_seconds", kind->explicit_steps && !report.running ? json(report.guard_seconds) : json(nullptr)},
                 {"failure", failure.empty() ? json(nullptr) : json(failure)}};
  s["time"] = kind->time_line ? json(state.time) : json(nullptr);
  s["steps"] = kind->time_line ? json(state.step) : json(nullptr);
  s["kinetic_energy"] = dynamic ? json(measured.kinetic_energy) : json(nullptr);
  s["energy_initial"] = dynamic ? json(report.energy_initial) : json(nullptr);
  s["energy_final"] = dynamic ? json(report.energy_final) : json(nullptr);
  s["center_of_mass_initial"] = initial.center_of_mass;
  s["center_of_mass"] = measured.center_of_mass;
  s["contact_force"] = measured.contact_force ? json(*measured.contact_force) : json(nullptr);
  s["body_contact_force"] = measured.body_contact_force.empty() ? json(nullptr) : json(measured.body_contact_force);
  s["reactions"] = scene_.fixes.empty() || measured.reactions.size() != scene_.fixes.size()
                       ? json(nullptr) : json(measured.reactions);
  s["bodies"] = scene_.bodies.size();
  s["partition"] = {{"edge_cut", model_.partition.edge_cut},
                    {"imbalance", model_.partition.imbalance},
                    {"ghosts_per_owned", model_.partition.surface_to_volume}};
  s["running"] = report.running;
  s["wall_seconds"] = wall_seconds;
  s["peak_memory_bytes"] = peak_max;
  write_json_atomically(scene_.output.directory + "/summary.json", s);
}

namespace {

// What `tissue info` prints about a file: it reads root attributes and dataset shapes only (metadata, no MPI), so
// that it is also the walk of the file's isolated parse (Hdf5File::open).
std::string describe(const Hdf5File& file) {
  const std::string& path = file.path();
  if (!file.has_attribute("/", "kind")) throw InputError(path, "kind", "not a snapshot or checkpoint of tissue");
  auto text = [&](const char* name) {
    return file.has_attribute("/", name) ? file.string_attribute("/", name) : std::string("(absent)");
  };
  auto number = [&](const char* name) {
    return file.has_attribute("/", name) ? std::to_string(file.int64_attribute("/", name)) : std::string("(absent)");
  };
  char time[64];
  std::snprintf(time, sizeof time, "%.9g", file.has_attribute("/", "time") ? file.double_attribute("/", "time") : 0.0);
  std::string out = path + ": a tissue " + text("kind") + "\n";
  out += "  title:       " + text("title") + "\n";
  out += "  step:        " + number("step") + "\n";
  out += "  time:        " + std::string(time) + " s\n";
  out += "  molecules:   " + number("molecules") + "\n";
  out += "  connections: " + number("connections") + "\n";
  out += "  written by:  " + number("ranks") + " ranks, tissue " + text("version") + "\n";
  out += "  datasets:   ";
  for (const char* d : {"/molecules/positions", "/molecules/displacements", "/molecules/velocities",
                        "/molecules/forces", "/molecules/fibre_direction", "/molecules/fibre_stretch",
                        "/connections/endpoints", "/connections/strain", "/connections/force",
                        "/connections/history", "/cells/corners", "/cells/volume_ratio", "/cells/fibre_stretch",
                        "/cells/history"})
    if (file.exists(d)) {
      auto shape = file.shape(d);
      out += std::string(" ") + d + " [" + std::to_string(shape[0]) + " x " +
             std::to_string(shape.size() > 1 ? shape[1] : 1) + "]";
    }
  return out + "\n";
}

}  // namespace

int info(const std::string& path, MPI_Comm comm) {
  int rank;
  MPI_Comm_rank(comm, &rank);
  struct stat st;
  if (stat(path.c_str(), &st) != 0) throw InputError(path, "", "no such file");
  Hdf5File file = [&] {
    try {
      return Hdf5File::open(path, comm, "file", [](const Hdf5File& f) { describe(f); });
    } catch (const InputError&) {
      throw;  // the isolated parse's verdict, or the walk's own refusal
    } catch (const std::exception& e) {  // the seal, HDF5, or the walk's HDF5 failure: its reason, without the path
      std::string reason = e.what();
      if (reason.rfind(path + ": ", 0) == 0) reason.erase(0, path.size() + 2);
      throw InputError(path, "", "not a readable HDF5 file written by tissue (" + reason + ")");
    }
  }();
  const std::string text = describe(file);  // every rank: a refusal stops them all
  if (rank == 0) std::fputs(text.c_str(), stdout);
  return 0;
}

}  // namespace tissue
