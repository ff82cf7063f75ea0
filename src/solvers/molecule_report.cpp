#include "src/solvers/molecule_report.hpp"

#include <fmt/format.h>

#include <limits>

namespace tissue {

int rank_of(MPI_Comm comm) {
  int r;
  MPI_Comm_rank(comm, &r);
  return r;
}

std::string broadcast(const std::string& s, int root, MPI_Comm comm) {
  long n = static_cast<long>(s.size());
  MPI_Bcast(&n, 1, MPI_LONG, root, comm);
  std::string out = s;
  out.resize(n);
  MPI_Bcast(out.data(), static_cast<int>(n), MPI_CHAR, root, comm);
  return out;
}

std::int64_t argmax_molecule(const LocalModel& model, const std::vector<double>& value) {
  const double inf = std::numeric_limits<double>::infinity();
  double best = -inf;
  long long id = std::numeric_limits<long long>::max();
  for (int i = 0; i < model.owned; ++i) {
    double v = std::isnan(value[i]) ? inf : value[i];
    if (v > best || (v == best && model.id[i] < id)) best = v, id = model.id[i];
  }
  double global = -inf;
  MPI_Allreduce(&best, &global, 1, MPI_DOUBLE, MPI_MAX, model.comm);
  long long mine = best == global ? id : std::numeric_limits<long long>::max(), first = 0;
  MPI_Allreduce(&mine, &first, 1, MPI_LONG_LONG, MPI_MIN, model.comm);
  return first == std::numeric_limits<long long>::max() ? -1 : static_cast<std::int64_t>(first);
}

std::string describe_molecule(const LocalModel& model, const double* x, std::int64_t molecule) {
  int holder = -1, root = 0;
  std::string text;
  for (int i = 0; i < model.owned; ++i) {
    if (model.id[i] != molecule) continue;
    holder = model.rank;
    text = fmt::format("molecule {} at ({:.6g}, {:.6g}, {:.6g})", molecule, x[3 * i], x[3 * i + 1], x[3 * i + 2]);
    int best = -1;
    double worst = -1;
    for (int c = 0; c < model.connections(); ++c) {
      if (model.end_a[c] != i && model.end_b[c] != i) continue;
      const double s = (length_of(x, model.end_a[c], model.end_b[c]) - model.l0(c)) / model.l0(c);
      const double size = std::isfinite(s) ? std::fabs(s) : std::numeric_limits<double>::infinity();
      if (size > worst) worst = size, best = c;
    }
    if (best >= 0) {
      const double l = length_of(x, model.end_a[best], model.end_b[best]);
      text += fmt::format("; its most strained connection {} (molecules {}-{}) has strain {:.6g} (length {:.6g} m, "
                          "rest {:.6g} m)",
                          model.connection_id(best), model.id[model.end_a[best]], model.id[model.end_b[best]],
                          (l - model.l0(best)) / model.l0(best), l, model.l0(best));
    }
    break;
  }
  MPI_Allreduce(&holder, &root, 1, MPI_INT, MPI_MAX, model.comm);
  if (root < 0) return fmt::format("molecule {}", molecule);
  return broadcast(text, root, model.comm);
}

std::int64_t largest_force_molecule(const LocalModel& model, const double* f) {
  std::vector<double> size(model.owned);
  for (int i = 0; i < model.owned; ++i)
    size[i] = f[3 * i] * f[3 * i] + f[3 * i + 1] * f[3 * i + 1] + f[3 * i + 2] * f[3 * i + 2];
  return argmax_molecule(model, size);
}

}  // namespace tissue
