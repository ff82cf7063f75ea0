// The last resort of partition/agreement, for tests/faults_test.py: rank 1 fails inside a stage while the other
// ranks wait in a collective of that stage that rank 1 will never enter. Rank 1 must end the job (MPI_Abort)
// after TISSUE_AGREEMENT_SECONDS with its one line and exit 3, never hang.
#include <mpi.h>

#include <cstdio>

#include "partition/agreement.hpp"

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  try {
    tissue::agree(MPI_COMM_WORLD, [&] {
      if (rank == 1) throw tissue::OutputError("out/snapshot.h5: cannot write: No space left on device");
      MPI_Barrier(MPI_COMM_WORLD);  // the stage's own collective, which rank 1 has left
    });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "agreement_stuck: rank %d returned (%s): the last resort did not fire\n", rank, e.what());
  }
  MPI_Finalize();
  return 0;
}
