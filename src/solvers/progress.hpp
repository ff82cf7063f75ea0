// A progress line on rank 0 during long runs: step, residual, rate and time left, at most every 2 s.
#pragma once
#include <mpi.h>

#include <chrono>
#include <cmath>
#include <algorithm>
#include <cstdio>
#include <string>

namespace tissue {

class Progress {
public:
  Progress(const char* what, bool on, MPI_Comm comm) : what_(what) {
    int rank;
    MPI_Comm_rank(comm, &rank);
    on_ = on && rank == 0;
    start_ = last_ = std::chrono::steady_clock::now();
  }
  // residual < 0: no residual (dynamic). `total` > 0: the step count to reach; else the residual target.
  void update(long step, double residual, double target, long total) {
    if (!on_) return;
    auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - last_).count() < 2.0) return;
    last_ = now;
    double elapsed = std::chrono::duration<double>(now - start_).count();
    double rate = step / std::max(elapsed, 1e-9);
    double left = -1;
    if (total > 0) left = (total - step) / std::max(rate, 1e-9);
    else if (residual > 0 && first_residual_ > 0 && residual < first_residual_)
      left = elapsed * std::log(residual / target) / std::log(first_residual_ / residual);
    if (first_residual_ < 0) first_residual_ = residual;
    if (residual >= 0)
      std::fprintf(stderr, "%s: step %ld, residual %.3e, %.0f steps/s, %s\n", what_, step, residual, rate,
                   left >= 0 ? (std::to_string(static_cast<long>(left)) + " s left").c_str() : "time left unknown");
    else
      std::fprintf(stderr, "%s: step %ld of %ld, %.0f steps/s, %ld s left\n", what_, step, total, rate,
                   static_cast<long>(left));
  }

private:
  const char* what_;
  bool on_;
  double first_residual_ = -1;
  std::chrono::steady_clock::time_point start_, last_;
};

}  // namespace tissue
