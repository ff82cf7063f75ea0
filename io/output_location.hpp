// The output location, checked before any work (the driver calls it before the model is built): a bad location
// is bad input (exit 2), found in a second, not after the solve.
#pragma once
#include <mpi.h>

#include <cstdint>

#include "src/model/scene.hpp"

namespace tissue {

// Rough sizes of what a run writes, from the scene alone (before the model exists): molecules from the bodies'
// lattice sizes (a mesh body counts its interior_molecules only), connections from the topology.
struct OutputEstimate {
  std::int64_t molecules = 0, connections = 0;
  std::int64_t snapshot_bytes = 0;    // one snapshot with the scene's fields
  std::int64_t checkpoint_bytes = 0;  // one checkpoint
  std::int64_t first_bytes = 0;       // the first file the run writes (the larger of the two it may write first)
  std::int64_t run_bytes = 0;         // everything the run keeps: its snapshots, final.h5, 2 checkpoints
};
OutputEstimate estimate_output(const Scene& scene);

// Collective (agreed, partition/agreement.hpp). The directory scene.output.directory exists or can be created, is
// a directory, every rank can create, write, fsync, rename and remove a file in it (a probe, removed again), and
// its file system has room for the first snapshot or checkpoint. Throws InputError (scene.file,
// "output.directory", the problem) on every rank otherwise. Warns (rank 0, one line) when the whole run's output
// will not fit. Leaves nothing behind: directories it created are removed again (the run creates them when it
// writes its first file).
void check_output_location(const Scene& scene, MPI_Comm comm);

}  // namespace tissue
