#include "src/solvers/setup_checks.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "src/solvers/molecule_report.hpp"

namespace tissue {

double checked_time_step(const Scene& scene, const LocalModel& model, double requested, double critical,
                         const char* solver) {
  if (!(requested > critical)) return requested;
  if (!scene.solver.allow_unstable_time_step)
    throw InputError(scene.file, "solver.time_step",
                     fmt::format("{:.6g} s is {:.3g} times the critical time step {:.6g} s of this body ({} "
                                 "integration would blow up): lower it, omit it, or set "
                                 "solver.allow_unstable_time_step = true",
                                 requested, requested / critical, critical, solver));
  if (rank_of(model.comm) == 0)
    std::fprintf(stderr,
                 "tissue: warning: solver.time_step = %.6g s is %.3g times the critical time step %.6g s "
                 "(allowed by solver.allow_unstable_time_step; the critical step is a bound, the run may still "
                 "blow up)\n",
                 requested, requested / critical, critical);
  return requested;
}

void check_connections(const Scene& scene, const LocalModel& model) {
  // The first bad connection (smallest global id) over all ranks.
  long long bad = std::numeric_limits<long long>::max();
  const bool calibrated = model.table.calibrated();
  // A table stored by type holds each (l0, k) once: when every type passes, every connection does (no pass).
  bool every_type_good = model.table.typed();
  if (every_type_good) {
    const ConnectionColumn k = model.table.stiffness_column(), l = model.table.rest_length_column();
    for (std::size_t t = 0; t < model.table.connection_types(); ++t)
      every_type_good = every_type_good && l.value[t] > 0 && std::isfinite(l.value[t]) && k.value[t] >= 0 &&
                        std::isfinite(k.value[t]);
  }
  for (int c = 0; !every_type_good && c < model.connections(); ++c) {
    const double l0 = model.l0(c), k = calibrated ? model.k(c) : 0.0;
    if (!(l0 > 0) || !std::isfinite(l0) || !(k >= 0) || !std::isfinite(k))
      bad = std::min<long long>(bad, model.connection_id(c));
  }
  long long first = 0;
  MPI_Allreduce(&bad, &first, 1, MPI_LONG_LONG, MPI_MIN, model.comm);
  if (first == std::numeric_limits<long long>::max()) return;
  std::string text;
  int holder = -1, root = 0;
  for (int c = 0; c < model.connections(); ++c)
    if (model.connection_id(c) == first) {
      holder = model.rank;
      text = fmt::format("connection {} (molecules {}-{}) has rest length {:.6g} m and stiffness {:.6g} N/m: "
                         "coincident molecules or a degenerate calibration",
                         first, model.id[model.end_a[c]], model.id[model.end_b[c]], model.l0(c),
                         calibrated ? model.k(c) : 0.0);
      break;
    }
  MPI_Allreduce(&holder, &root, 1, MPI_INT, MPI_MAX, model.comm);
  throw InputError(scene.file, "body", broadcast(text, root, model.comm));
}

}  // namespace tissue
