// Checkpoints: everything a run needs to continue, in original molecule order so that a restart may use another
// rank count. Layout of DIR/checkpoint_<step>.h5:
//   /molecules/positions, /molecules/velocities          [N x 3]
//   /connections/endpoints [C x 2] int64, /connections/stiffness, /connections/rest_length [C x 1]
//   /connections/history [C x W] (scenes with internal variables: ForceModel::history, the viscoelastic history)
//   /cells/history [K x 9 (1 + terms)] (the cell term with a Prony series: per cell in id order, its committed
//   second Piola-Kirchhoff stress and one history tensor per Prony term, row-major)
//   root attributes: kind = "checkpoint", program, version, title, scene (the scene text after --set), ranks,
//   step, time, time_step, solver_kind, divisor (C), calibration_updates, fire_dt, fire_alpha, fire_positive;
//   every dataset carries a "checksum" attribute, verified on load.
// Written atomically (checkpoint_<step>.h5.tmp, closed, renamed); the newest `keep` are kept.
#pragma once
#include <string>
#include <vector>

#include "io/row_stream.hpp"
#include "partition/natural_order.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

struct CheckpointHeader {
  std::string path, scene_text, title, version, solver_kind;
  long step = 0;
  int ranks = 0;
  std::int64_t molecules = 0, connections = 0;
  int history_width = 0;  // /connections/history's columns (0: absent)
  std::int64_t cells = 0;  // /cells/history's rows and columns (0: absent)
  int cell_history_width = 0;
};

// Collective. Writes DIR/checkpoint_<step>.h5 and removes older checkpoints beyond the newest `keep`; with
// `forces`, the internal variables of its terms too (/connections/history, /cells/history). Returns the path written. Every
// dataset is written in pieces (io/row_stream.hpp): `molecules` over the owned molecules, `connections` over the
// local connections (those whose end a this rank owns).
std::string write_checkpoint(const std::string& directory, int keep, const Scene& scene, const LocalModel& model,
                             const RowStream& molecules, const RowStream& connections,
                             const SolverState& state, const ForceModel* forces = nullptr);

// Collective. Reads and checks the header (kind, version, scene text). Bad files throw InputError naming the file
// and the attribute or dataset.
CheckpointHeader read_checkpoint_header(const std::string& path, MPI_Comm comm);

// Collective. Loads positions, velocities and solver state into `state`, streamed in pieces over the streams a run
// writes with (Output::molecule_rows, connection_rows), after checking every dataset's shape,
// checksum, finiteness and that endpoints, rest lengths and (unless the calibration follows the deformation and
// is refreshed from the positions anyway) stiffness match the model rebuilt from the scene. With `forces` whose
// terms have internal variables, /connections/history (and /cells/history for the cell term's) must be there with
// their width, and is put back.
void read_checkpoint_state(const std::string& path, const LocalModel& model, const RowStream& molecules,
                           const RowStream& connections, SolverState& state, bool check_stiffness = true,
                           const ForceModel* forces = nullptr);

}  // namespace tissue
