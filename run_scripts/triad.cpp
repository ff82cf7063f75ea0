// STREAM-like triad a[i] = b[i] + s * c[i], the machine's memory bandwidth as the explicit step sees it, measured
// in the same run as run_scripts/bench_explicit.sh (issue 18 item 3: "near the roofline" needs the roof).
//
// Build and run (bench_explicit.sh does both):
//   mpicxx -O3 -march=native -o /tmp/triad run_scripts/triad.cpp
//   mpirun -np R /tmp/triad [MiB per array, default 256]
// Each rank owns three arrays (first touched by itself), the ranks start every repetition together (barrier) and
// the repetition's time is the slowest rank's. Prints one line: ranks, MiB per array, the best of 20 repetitions
// in GB/s counting 24 B an element (STREAM's convention: read b and c, write a) and counting 32 B (the store's
// write-allocate read as well, which a plain store costs on this machine), and the median (24 B).
#include <mpi.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  const long mib = argc > 1 ? std::atol(argv[1]) : 256;
  const long n = mib * (1L << 20) / 8;
  std::vector<double> a(n), b(n), c(n);  // value-initialized: every page touched by this rank
  for (long i = 0; i < n; ++i) b[i] = 1.0 + 1e-9 * i, c[i] = 2.0 - 1e-9 * i;
  const double s = 0.5;
  std::vector<double> seconds;
  for (int rep = 0; rep < 21; ++rep) {
    MPI_Barrier(MPI_COMM_WORLD);
    const double t0 = MPI_Wtime();
    double* __restrict pa = a.data();
    const double* __restrict pb = b.data();
    const double* __restrict pc = c.data();
    for (long i = 0; i < n; ++i) pa[i] = pb[i] + s * pc[i];
    double t = MPI_Wtime() - t0, slowest = 0;
    MPI_Allreduce(&t, &slowest, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    if (rep > 0) seconds.push_back(slowest);  // the first pass warms up
    b[rep] += a[n - 1 - rep];                 // a is used: the loop cannot be dropped
  }
  std::sort(seconds.begin(), seconds.end());
  const double elements = static_cast<double>(n) * size;
  double check = a[n / 2], sum = 0;
  MPI_Reduce(&check, &sum, 1, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  if (rank == 0)
    std::printf("triad ranks %d MiB_per_array %ld best_GBps_24B %.2f best_GBps_32B %.2f median_GBps_24B %.2f check %.6f\n",
                size, mib, 24 * elements / seconds.front() / 1e9, 32 * elements / seconds.front() / 1e9,
                24 * elements / seconds[seconds.size() / 2] / 1e9, sum);
  MPI_Finalize();
  return 0;
}
