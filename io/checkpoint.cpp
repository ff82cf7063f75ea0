#include "io/checkpoint.hpp"

#include <dirent.h>
#include <fmt/format.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <type_traits>

#include "io/hdf5_file.hpp"
#include "io/row_stream.hpp"
#include "partition/agreement.hpp"

namespace tissue {

namespace {

// The order-independent checksum of a dataset (row_hash_sum): each rank sums its block, the ranks' sums add up.
template <typename T>
std::uint64_t checksum(const std::vector<T>& block, int width, std::int64_t first_row, MPI_Comm comm) {
  const std::int64_t rows = width ? static_cast<std::int64_t>(block.size()) / width : 0;
  std::uint64_t sum = row_hash_sum(block.data(), width, rows, first_row), total = 0;
  MPI_Allreduce(&sum, &total, 1, MPI_UINT64_T, MPI_SUM, comm);
  return total;
}

std::int64_t as_signed(std::uint64_t u) {
  std::int64_t s;
  std::memcpy(&s, &u, sizeof s);
  return s;
}

// Dynamic runs whose forces read velocities only (SolverState::v_half): optional, checked when present.
constexpr const char* kHalfStepVelocities = "/molecules/half_step_velocities";

// The viscoelastic history (ForceModel::history): present when the scene's terms have internal variables.
constexpr const char* kHistory = "/connections/history";
constexpr std::int64_t kMaxHistoryWidth = 1024;
// The per-cell history (ForceModel::cell_history: the cell term with a Prony series), in cell id order.
constexpr const char* kCellHistory = "/cells/history";

// The natural order of the per-cell history: the cells each rank writes.
NaturalOrder cell_order(const Term& cells, MPI_Comm comm, std::vector<double>* rows = nullptr) {
  std::vector<std::int64_t> ids;
  std::vector<double> mine;
  cells.save_cell_history(ids, rows ? *rows : mine);
  return NaturalOrder(comm, ids, cells.cell_history_count());
}

// Hdf5File's messages start with the file's path; the InputError names it already.
std::string without_path(const std::string& message, const std::string& path) {
  const std::string prefix = path + ": ";
  return message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message;
}

}  // namespace

std::string write_checkpoint(const std::string& directory, int keep, const Scene& scene, const LocalModel& model,
                             const RowStream& molecules, const RowStream& connections,
                             const SolverState& state, const ForceModel* forces) {
  char name[64];
  std::snprintf(name, sizeof name, "checkpoint_%010ld.h5", state.step);
  const std::string path = directory + "/" + name;
  {
    // The space the file needs, reserved first: a full disk fails here, cleanly (Hdf5File::create).
    const int history_width = forces ? forces->history_width() : 0;
    const Term* cells = forces ? forces->cell_history() : nullptr;
    const std::int64_t bytes = (state.v_half.empty() ? 48 : 72) * model.global_molecules +
                               (32 + 8 * history_width) * model.global_connections +
                               (cells ? 8 * cells->cell_history_width() * cells->cell_history_count() : 0) +
                               static_cast<std::int64_t>(scene.text.size()) + (1 << 20);
    Hdf5File f = Hdf5File::create(path, model.comm, bytes);
    f.set_attribute("/", "kind", "checkpoint");
    f.set_attribute("/", "program", "tissue");
    f.set_attribute("/", "version", TISSUE_VERSION);
    f.set_attribute("/", "title", scene.title);
    f.set_attribute("/", "scene", scene.text);
    f.set_attribute("/", "ranks", model.size);
    f.set_attribute("/", "molecules", model.global_molecules);
    f.set_attribute("/", "connections", model.global_connections);
    f.set_attribute("/", "step", state.step);
    f.set_attribute("/", "time", state.time);
    f.set_attribute("/", "time_step", state.time_step);
    f.set_attribute("/", "solver_kind", scene.solver.kind);
    f.set_attribute("/", "divisor", state.divisor);
    f.set_attribute("/", "calibration_updates", state.calibration_updates);
    f.set_attribute("/", "fire_dt", state.fire_dt);
    f.set_attribute("/", "fire_alpha", state.fire_alpha);
    f.set_attribute("/", "fire_positive", state.fire_positive);
    if (std::isfinite(state.energy_initial)) f.set_attribute("/", "energy_initial", state.energy_initial);
    // Every dataset streamed in pieces (io/row_stream.hpp), with its row hash as the "checksum" attribute.
    auto copy = [](const double* from, int width) {
      return [from, width](std::int64_t k, double* row) { std::copy(from + width * k, from + width * (k + 1), row); };
    };
    auto checked = [&](const char* name, std::uint64_t hash) { f.set_attribute(name, "checksum", as_signed(hash)); };
    checked("/molecules/positions", molecules.write_double(f, "/molecules/positions", 3, copy(state.x.array(), 3)));
    checked("/molecules/velocities", molecules.write_double(f, "/molecules/velocities", 3, copy(state.v.data(), 3)));
    if (!state.v_half.empty())  // forces that read velocities (dynamic.cpp): what the last evaluation read
      checked(kHalfStepVelocities, molecules.write_double(f, kHalfStepVelocities, 3, copy(state.v_half.data(), 3)));
    checked("/connections/endpoints",
            connections.write_int64(f, "/connections/endpoints", 2, [&](std::int64_t c, std::int64_t* row) {
              row[0] = model.id[model.end_a[c]], row[1] = model.id[model.end_b[c]];
            }));
    checked("/connections/stiffness", connections.write_double(f, "/connections/stiffness", 1, [&](std::int64_t c, double* row) {
              row[0] = model.k(static_cast<int>(c));
            }));
    checked("/connections/rest_length",
            connections.write_double(f, "/connections/rest_length", 1, [&](std::int64_t c, double* row) {
              row[0] = model.l0(static_cast<int>(c));
            }));
    if (history_width > 0) {  // the committed internal variables, in original connection order
      const std::vector<double> all = forces->history();
      checked(kHistory, connections.write_double(f, kHistory, history_width, copy(all.data(), history_width)));
    }
    if (cells) {  // the cell term's committed stress and history, in cell id order
      std::vector<double> rows;
      const NaturalOrder order = cell_order(*cells, model.comm, &rows);
      const int width = cells->cell_history_width();
      const std::vector<double> block = order.to_natural(rows.data(), width);
      const std::int64_t n = width ? static_cast<std::int64_t>(block.size()) / width : 0;
      f.write(kCellHistory, order.global_count(), width, order.begin(), n, block.empty() ? nullptr : block.data());
      checked(kCellHistory, checksum(block, width, order.begin(), model.comm));
    }
    f.close();  // flushed and renamed: a checkpoint on disk under its name is always complete
  }
  // The new checkpoint (and its name in the directory) reach the disk before any older one is removed, so that
  // a power loss cannot leave fewer complete checkpoints than before. A failed fsync stops the run (exit 3) and
  // removes nothing. Agreed: rank 0 works alone, every rank learns the outcome.
  agree(model.comm, [&] {
    if (model.rank != 0) return;
    for (const std::string& p : {path, directory}) {
      const int fd = ::open(p.c_str(), O_RDONLY);
      if (fd < 0) throw OutputError(p + ": cannot open to fsync: " + std::strerror(errno));
      const int rc = ::fsync(fd), err = errno;
      ::close(fd);
      if (rc != 0) throw OutputError(p + ": cannot fsync: " + std::strerror(err));
    }
    if (keep <= 0) return;
    // Keep the newest `keep` checkpoints (names sort by step), and remove the .tmp files that a killed run left
    // (ours was renamed: any .tmp still here is a dead writer's).
    std::vector<std::string> names;
    auto ends_with = [](const std::string& n, const std::string& tail) {
      return n.size() >= tail.size() && n.compare(n.size() - tail.size(), tail.size(), tail) == 0;
    };
    if (DIR* d = opendir(directory.c_str())) {
      while (dirent* e = readdir(d)) {
        std::string n = e->d_name;
        if (n.rfind("checkpoint_", 0) != 0) continue;
        if (ends_with(n, ".h5")) names.push_back(n);
        else if (ends_with(n, ".h5.tmp")) std::remove((directory + "/" + n).c_str());
      }
      closedir(d);
    }
    std::sort(names.begin(), names.end());
    for (std::size_t i = 0; i + keep < names.size(); ++i) std::remove((directory + "/" + names[i]).c_str());
  });
  return path;
}

namespace {

// The datasets of a checkpoint: name, integer (else double), width; rows are molecules or connections.
struct DatasetSpec {
  const char* name;
  bool integer;
  int width;
  bool per_molecule;
};
constexpr DatasetSpec kDatasets[] = {{"/molecules/positions", false, 3, true},
                                     {"/molecules/velocities", false, 3, true},
                                     {"/connections/endpoints", true, 2, false},
                                     {"/connections/stiffness", false, 1, false},
                                     {"/connections/rest_length", false, 1, false}};

// Every piece of metadata that the readers below touch, read and checked without MPI and without the bulk data:
// the root attributes, and each dataset's presence, shape, type, layout and checksum attribute. Run first in a
// child process (Hdf5File::open), then here. `bytes` is the file's size.
CheckpointHeader header_metadata(const Hdf5File& f, const std::string& path, std::int64_t bytes) {
  CheckpointHeader h;
  h.path = path;
  auto need = [&](const char* name) {
    if (!f.has_attribute("/", name)) throw InputError(path, name, "attribute missing: not a tissue checkpoint");
  };
  need("kind");
  if (f.string_attribute("/", "kind") != "checkpoint")
    throw InputError(path, "kind", "is \"" + f.string_attribute("/", "kind") + "\", not a checkpoint");
  for (const char* a : {"version", "scene", "step", "ranks", "molecules", "connections", "title", "solver_kind"})
    need(a);
  h.version = f.string_attribute("/", "version");
  if (h.version != TISSUE_VERSION)
    throw InputError(path, "version", "written by tissue " + h.version + ", this is " + TISSUE_VERSION);
  h.scene_text = f.string_attribute("/", "scene");
  h.title = f.string_attribute("/", "title");
  h.solver_kind = f.string_attribute("/", "solver_kind");
  h.step = f.int64_attribute("/", "step");
  h.ranks = static_cast<int>(f.int64_attribute("/", "ranks"));
  h.molecules = f.int64_attribute("/", "molecules");
  h.connections = f.int64_attribute("/", "connections");
  // Read by read_checkpoint_state; checked here: a state that no run writes (a time that is not finite or is
  // negative, a negative count) would go on silently from nowhere.
  for (const char* a : {"time", "time_step", "divisor", "fire_dt", "fire_alpha"}) {
    need(a);
    const double v = f.double_attribute("/", a);
    if (!std::isfinite(v) || v < 0)
      throw InputError(path, a, fmt::format("is {}, not a finite number >= 0", v));
  }
  for (const char* a : {"calibration_updates", "fire_positive"}) {
    need(a);
    if (f.int64_attribute("/", a) < 0) throw InputError(path, a, "is negative");
  }
  if (h.step < 0) throw InputError(path, "step", "is negative");
  if (f.has_attribute("/", "energy_initial") && !std::isfinite(f.double_attribute("/", "energy_initial")))
    throw InputError(path, "energy_initial", "is not a finite number");
  if (h.molecules < 1 || h.connections < 0)
    throw InputError(path, h.molecules < 1 ? "molecules" : "connections", "is out of range");
  // Our datasets are contiguous and uncompressed: 48 bytes per molecule and 32 per connection must fit in the
  // file. Checked before any allocation, so that a damaged count cannot ask for more memory than the file holds.
  if (h.molecules > bytes / 48 || h.connections > bytes / 32 || 48 * h.molecules + 32 * h.connections > bytes)
    throw InputError(path, "molecules",
                     std::to_string(h.molecules) + " molecules and " + std::to_string(h.connections) +
                         " connections do not fit in the file's " + std::to_string(bytes) + " bytes");
  auto check = [&](const DatasetSpec& d, std::int64_t rows = -1) {
    if (rows < 0) rows = d.per_molecule ? h.molecules : h.connections;
    if (!f.exists(d.name)) throw InputError(path, d.name, "dataset missing");
    auto shape = f.shape(d.name);
    if (shape.size() != 2 || shape[0] != rows || shape[1] != d.width)
      throw InputError(path, d.name, "has shape [" + std::to_string(shape[0]) + " x " + std::to_string(shape[1]) +
                                         "], the header says [" + std::to_string(rows) + " x " +
                                         std::to_string(d.width) + "]");
    f.check_plain(d.name, d.integer);
    if (!f.has_attribute(d.name, "checksum")) throw InputError(path, d.name, "checksum attribute missing");
    f.int64_attribute(d.name, "checksum");
  };
  for (const DatasetSpec& d : kDatasets) check(d);
  if (f.exists(kHalfStepVelocities)) check({kHalfStepVelocities, false, 3, true});
  if (f.exists(kHistory)) {
    auto shape = f.shape(kHistory);
    if (shape.size() != 2 || shape[1] < 1 || shape[1] > kMaxHistoryWidth || shape[1] * h.connections > bytes / 8)
      throw InputError(path, kHistory, "has a width that no scene gives or that does not fit in the file");
    h.history_width = static_cast<int>(shape[1]);
    check({kHistory, false, h.history_width, false});
  }
  if (f.exists(kCellHistory)) {
    auto shape = f.shape(kCellHistory);
    if (shape.size() != 2 || shape[0] < 1 || shape[1] < 1 || shape[1] > kMaxHistoryWidth ||
        shape[0] > bytes / 8 / shape[1])
      throw InputError(path, kCellHistory, "has a shape that no scene gives or that does not fit in the file");
    h.cells = shape[0];
    h.cell_history_width = static_cast<int>(shape[1]);
    check({kCellHistory, false, h.cell_history_width, false}, h.cells);
  }
  return h;
}

// What identifies a file's bytes without reading them: a write changes the change time (ctime), which no user
// can set back.
std::array<long long, 7> identity(const struct stat& st) {
  return {static_cast<long long>(st.st_dev), static_cast<long long>(st.st_ino), static_cast<long long>(st.st_size),
          st.st_mtim.tv_sec, st.st_mtim.tv_nsec, st.st_ctim.tv_sec, st.st_ctim.tv_nsec};
}

// The checkpoint whose metadata the last isolated parse of this process passed (rank 0's view). A restart opens
// its checkpoint twice, for the header before the model exists and for the state after; the second fork would copy
// the page tables of a process holding the model, for a walk of the same bytes (docs/benchmarks.md).
std::array<long long, 7> walked_identity{};
std::string walked_path;

// Opens a checkpoint for reading after its metadata has been walked in a child process (io/isolated_parse.hpp),
// unless this process walked the same, unchanged file before.
Hdf5File open_checkpoint(const std::string& path, MPI_Comm comm) {
  struct stat st;
  // Agreed: a file that one rank cannot see (a node-local path) stops every rank, not only that one.
  agree(comm, [&] {
    if (stat(path.c_str(), &st) != 0) throw InputError(path, "", "no such file");
    if (!S_ISREG(st.st_mode)) throw InputError(path, "", "not a regular file");
  });
  const std::int64_t bytes = static_cast<std::int64_t>(st.st_size);
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  int walked = rank == 0 && path == walked_path && identity(st) == walked_identity;
  MPI_Bcast(&walked, 1, MPI_INT, 0, comm);  // rank 0 alone forks: every rank must take the same branch
  if (walked) return Hdf5File::open_walked(path, comm);
  Hdf5File f = Hdf5File::open(path, comm, "checkpoint", [&](const Hdf5File& c) { header_metadata(c, path, bytes); });
  walked_path = path;
  walked_identity = identity(st);
  return f;
}

}  // namespace

CheckpointHeader read_checkpoint_header(const std::string& path, MPI_Comm comm) {
  CheckpointHeader h;
  try {
    Hdf5File f = open_checkpoint(path, comm);
    // The same walk again, here: the child survived it, and it reads nothing the child did not.
    struct stat st;
    agree(comm, [&] {  // local reads: agreed before the collectives below
      h = header_metadata(f, path, stat(path.c_str(), &st) == 0 ? static_cast<std::int64_t>(st.st_size) : 0);
    });
    // Every dataset is verified here (shape, checksum, finiteness), before the run prints anything or builds the
    // model, so that a damaged file stops the restart with its one line. Read in pieces (io/row_stream.hpp) that no
    // rank keeps: each rank checks its part of each piece.
    auto verify = [&](const char* name, std::int64_t rows, int width, auto tag) {
      using T = decltype(tag);
      std::int64_t expected = 0;
      agree(comm, [&] { expected = f.int64_attribute(name, "checksum"); });
      const RowStream nobody(comm, rows, 0, [](std::int64_t) { return std::int64_t{-1}; }, RowStream::Shared{});
      RowStream::ReadCheck got;
      if constexpr (std::is_same_v<T, double>)
        got = nobody.read_double(f, name, width, [](std::int64_t, const double*) {}, "restart");
      else
        got = nobody.read_int64(f, name, width, [](std::int64_t, const std::int64_t*) {}, "restart");
      if (as_signed(got.hash) != expected) throw InputError(path, name, "checksum mismatch: the file is corrupt");
      if (!got.finite) throw InputError(path, name, "holds a NaN or infinite value");
    };
    verify("/molecules/positions", h.molecules, 3, double());
    verify("/molecules/velocities", h.molecules, 3, double());
    verify("/connections/endpoints", h.connections, 2, std::int64_t());
    verify("/connections/stiffness", h.connections, 1, double());
    verify("/connections/rest_length", h.connections, 1, double());
    if (f.exists(kHalfStepVelocities)) verify(kHalfStepVelocities, h.molecules, 3, double());
    if (h.history_width > 0) verify(kHistory, h.connections, h.history_width, double());
    if (h.cell_history_width > 0) verify(kCellHistory, h.cells, h.cell_history_width, double());
    f.close();
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path, "", std::string("unreadable checkpoint (") + without_path(e.what(), path) + ")");
  }
  return h;
}

void read_checkpoint_state(const std::string& path, const LocalModel& model, const RowStream& molecules,
                           const RowStream& connections, SolverState& state, bool check_stiffness,
                           const ForceModel* forces) {
  try {
    Hdf5File f = open_checkpoint(path, model.comm);
    // Each dataset streamed in pieces (io/row_stream.hpp): no rank holds more than a piece of the file, and each
    // row goes straight to where the run keeps it. A damaged file may leave the state half loaded: the restart
    // stops then (exit 2), and nothing is written.
    auto load = [&](const char* name, std::int64_t rows, int width, const RowStream& stream, auto take) {
      std::int64_t expected = 0;
      // Agreed, as in read_checkpoint_header: one rank's failed check stops every rank here.
      agree(model.comm, [&] {
        if (!f.exists(name)) throw InputError(path, name, "dataset missing");
        auto shape = f.shape(name);
        if (shape.size() != 2 || shape[0] != rows || shape[1] != width)
          throw InputError(path, name, "has the wrong shape for this scene");
        if (!f.has_attribute(name, "checksum")) throw InputError(path, name, "checksum missing");
        expected = f.int64_attribute(name, "checksum");
      });
      RowStream::ReadCheck got;
      if constexpr (std::is_invocable_v<decltype(take), std::int64_t, const double*>)
        got = stream.read_double(f, name, width, take, "restart");
      else
        got = stream.read_int64(f, name, width, take, "restart");
      if (as_signed(got.hash) != expected) throw InputError(path, name, "checksum mismatch: the file is corrupt");
      if (!got.finite) throw InputError(path, name, "holds a NaN or infinite value");
    };
    auto into = [](double* to, int width) {
      return [to, width](std::int64_t k, const double* row) { std::copy(row, row + width, to + width * k); };
    };
    load("/molecules/positions", model.global_molecules, 3, molecules, into(state.x.array(), 3));
    load("/molecules/velocities", model.global_molecules, 3, molecules, into(state.v.data(), 3));

    // The model rebuilt from the scene must be the one that was saved: same connections, same stiffness.
    int ends_differ = 0, k_differs = 0, l0_differs = 0;
    load("/connections/endpoints", model.global_connections, 2, connections,
         [&](std::int64_t c, const std::int64_t* row) {
           ends_differ |= row[0] != model.id[model.end_a[c]] || row[1] != model.id[model.end_b[c]];
         });
    load("/connections/stiffness", model.global_connections, 1, connections, [&](std::int64_t c, const double* row) {
      k_differs |= check_stiffness && row[0] != model.k(static_cast<int>(c));
    });
    load("/connections/rest_length", model.global_connections, 1, connections,
         [&](std::int64_t c, const double* row) { l0_differs |= row[0] != model.l0(static_cast<int>(c)); });
    const int mismatch = ends_differ ? 1 : l0_differs ? 2 : k_differs ? 3 : 0;
    int worst = 0;
    MPI_Allreduce(&mismatch, &worst, 1, MPI_INT, MPI_MAX, model.comm);
    static const char* names[] = {"", "/connections/endpoints", "/connections/rest_length", "/connections/stiffness"};
    if (worst) throw InputError(path, names[worst], "does not match the model rebuilt from the checkpoint's scene");

    if (f.exists(kHalfStepVelocities)) {
      state.v_half.assign(3 * static_cast<std::size_t>(model.owned), 0.0);
      load(kHalfStepVelocities, model.global_molecules, 3, molecules, into(state.v_half.data(), 3));
    }
    if (const int width = forces ? forces->history_width() : 0) {
      // The scene has internal variables: a checkpoint without them (or of another width) cannot continue it.
      agree(model.comm, [&] {
        if (!f.exists(kHistory)) throw InputError(path, kHistory, "dataset missing: the scene has a viscoelastic history");
      });
      // Every local connection's row: a cut connection is held (and its history kept) on both sides.
      const RowStream local(model.comm, model.global_connections, model.connections(),
                            [&](std::int64_t c) { return model.connection_id(static_cast<int>(c)); },
                            RowStream::Shared{});
      std::vector<double> rows(static_cast<std::size_t>(model.connections()) * width);
      load(kHistory, model.global_connections, width, local, into(rows.data(), width));
      forces->set_history(rows);
    }
    if (Term* cells = forces ? forces->cell_history() : nullptr) {
      agree(model.comm, [&] {
        if (!f.exists(kCellHistory))
          throw InputError(path, kCellHistory, "dataset missing: the scene's cells have a viscoelastic history");
      });
      const int width = cells->cell_history_width();
      // The cells this rank holds, in increasing id (a stream's slots must be): by position, a cell held twice read
      // once and copied.
      const std::vector<std::int64_t> ids = cells->cell_history_ids();
      std::vector<std::int64_t> by_id(ids.size());
      for (std::size_t i = 0; i < ids.size(); ++i) by_id[i] = static_cast<std::int64_t>(i);
      std::stable_sort(by_id.begin(), by_id.end(), [&](std::int64_t a, std::int64_t b) { return ids[a] < ids[b]; });
      auto repeated = [&](std::int64_t k) { return k > 0 && ids[by_id[k]] == ids[by_id[k - 1]]; };
      const RowStream held(model.comm, cells->cell_history_count(), static_cast<std::int64_t>(ids.size()),
                           [&](std::int64_t k) { return repeated(k) ? std::int64_t{-1} : ids[by_id[k]]; },
                           RowStream::Shared{});
      std::vector<double> rows(ids.size() * width);
      load(kCellHistory, cells->cell_history_count(), width, held, [&](std::int64_t k, const double* row) {
        std::copy(row, row + width, rows.begin() + by_id[k] * width);
      });
      for (std::size_t k = 1; k < ids.size(); ++k)
        if (repeated(static_cast<std::int64_t>(k)))
          std::copy_n(rows.begin() + by_id[k - 1] * width, width, rows.begin() + by_id[k] * width);
      cells->load_cell_history(rows.data());
    }
    state.x.update_ghosts();
    agree(model.comm, [&] {  // local reads before the file's collective close
      state.step = f.int64_attribute("/", "step");
      state.time = f.double_attribute("/", "time");
      state.time_step = f.double_attribute("/", "time_step");
      state.divisor = f.double_attribute("/", "divisor");
      state.calibration_updates = f.int64_attribute("/", "calibration_updates");
      state.fire_dt = f.double_attribute("/", "fire_dt");
      state.fire_alpha = f.double_attribute("/", "fire_alpha");
      state.fire_positive = f.int64_attribute("/", "fire_positive");
      // (optional: checkpoints written before it was kept restart with the energy at their step)
      if (f.has_attribute("/", "energy_initial")) state.energy_initial = f.double_attribute("/", "energy_initial");
    });
    state.restarted = true;
    f.close();
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path, "", std::string("unreadable checkpoint (") + without_path(e.what(), path) + ")");
  }
}

}  // namespace tissue
