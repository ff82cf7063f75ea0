// What a run writes to its output directory: HDF5 snapshots (in original molecule order, whatever the
// partition) with an XDMF index that ParaView plays as a series, and summary.json. The directory is created only
// when the first file is written, so a run stopped by bad input leaves nothing behind. Every write is one agreed
// stage (partition/agreement.hpp): a failure on any rank throws the same OutputError on every rank (exit 3).
#pragma once
#include <memory>
#include <string>
#include <vector>

#include "io/row_stream.hpp"
#include "io/snapshot.hpp"
#include "io/xdmf.hpp"
#include "partition/natural_order.hpp"
#include "src/measure/measure.hpp"
#include "src/solvers/solver.hpp"

namespace tissue {

class Output {
public:
  Output(const Scene& scene, const LocalModel& model);
  // Collective. DIR/snapshot_<step>.h5, or DIR/final.h5 for the final state; refreshes DIR/tissue.xdmf.
  // `name` (e.g. "last_good.h5") overrides the file name.
  void snapshot(const SolverState& state, const ForceModel& forces, bool final = false, const char* name = nullptr);
  // Collective. DIR/checkpoint_<step>.h5 (the newest 2 kept); returns its path.
  // With `forces`, the internal variables of its terms too (the viscoelastic history).
  std::string checkpoint(const SolverState& state, const ForceModel* forces = nullptr);
  // The pieces files are written and read in (io/row_stream.hpp), planned on first use (collective): a few
  // numbers per piece. A restart reads its checkpoint over them.
  const RowStream& molecule_rows();
  const RowStream& connection_rows();
  // Collective; rank 0 writes DIR/summary.json.
  void summary(const TensionTest& test, const Measurements& measured, const Measurements& initial,
               const SolveReport& report, const SolverState& state, double wall_seconds, const std::string& failure);

  // Collective; rank 0 appends the state's row to DIR/history.csv (the first call of a run writes the header
  // over any earlier file), flushed at once so that a crash keeps the rows so far.
  void history_row(const SolverState& state, const ForceModel& forces, const TensionTest& test);
  // Collective; a restart from the checkpoint of `step`: DIR/history.csv, if there, keeps its header and its rows
  // up to that step (rewritten atomically) and the run's rows follow them.
  void continue_history(long step);

private:
  void make_directory();
  bool history_started_ = false;
  long history_rows_ = 0;  // rows this run wrote (static runs number their load steps with it)
  static std::string snapshot_name(long step);
  double stage_bytes() const;  // a bound on one file's size, for its StageDeadline
  void write_snapshot_stage(const SolverState& state, const ForceModel& forces, bool final, const char* name);
  void write_summary(const TensionTest& test, const Measurements& measured, const Measurements& initial,
                     const SolveReport& report, const SolverState& state, double wall_seconds,
                     const std::string& failure, long peak_max);
  const Scene& scene_;
  const LocalModel& model_;
  std::unique_ptr<NaturalOrder> cells_;  // built on the first snapshot with cells
  std::unique_ptr<RowStream> molecule_rows_, connection_rows_;
  std::vector<XdmfEntry> frames_;
  bool directory_made_ = false;
};

// `tissue info FILE.h5`: prints what a snapshot or checkpoint holds. Returns the exit code.
int info(const std::string& path, MPI_Comm comm);

}  // namespace tissue
