#include "src/driver/fit.hpp"

#include <petsctao.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "src/solvers/petsc_errors.hpp"

namespace tissue {

namespace {

bool is_root(MPI_Comm comm) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  return rank == 0;
}

// Scaled variable u in [0, 1] <-> the parameter: logarithmic for positive bounds spanning more than a decade
// (time constants, moduli: equal steps in u are equal ratios), linear otherwise.
struct Scale {
  double lo, hi;
  bool log;
  explicit Scale(const FitParameter& p) : lo(p.lower), hi(p.upper), log(p.lower > 0 && p.upper > 10 * p.lower) {}
  double value(double u) const {
    u = std::min(1.0, std::max(0.0, u));
    return log ? std::exp(std::log(lo) + u * (std::log(hi) - std::log(lo))) : lo + u * (hi - lo);
  }
  double unit(double p) const {
    return log ? (std::log(p) - std::log(lo)) / (std::log(hi) - std::log(lo)) : (p - lo) / (hi - lo);
  }
};

// Linear interpolation of (xs, ys), xs strictly increasing, at x inside [xs.front(), xs.back()].
double interpolate(const std::vector<double>& xs, const std::vector<double>& ys, double x) {
  auto it = std::upper_bound(xs.begin(), xs.end(), x);
  if (it == xs.begin()) return ys.front();
  if (it == xs.end()) return ys.back();
  const std::size_t i = static_cast<std::size_t>(it - xs.begin());
  const double t = (x - xs[i - 1]) / (xs[i] - xs[i - 1]);
  return ys[i - 1] + t * (ys[i] - ys[i - 1]);
}

struct Problem {
  const FitInput& in;
  const ForwardRun& forward;
  std::string work;
  MPI_Comm comm;
  bool progress;
  std::vector<Scale> scales;
  long m = -1;          // residual length: the simulated rows of the first successful run
  long inside = 0;      // of which inside the measured x range (the points that count)
  long runs = 0, failed = 0;
  std::vector<double> best_r, best_values;
  // TAO sees r / y_scale (y_scale: the largest |measured y| of the residual's column), so that its tolerances
  // mean the same for a curve in metres (1e-5) as for one in newtons (relative misfit), and several y columns
  // (an elongation and a lateral strain) weigh alike. Per residual entry; with one column, reported norms and
  // errors are in the data's units.
  std::vector<double> column_scale;  // per y column
  std::vector<double> y_scale;       // per residual entry: its column's scale
  std::vector<double> last_p, last_r;
  bool last_ok = false;
  double best = std::numeric_limits<double>::infinity();

  std::vector<double> values(const double* u) const {
    std::vector<double> p(scales.size());
    for (std::size_t j = 0; j < scales.size(); ++j) p[j] = scales[j].value(u[j]);
    return p;
  }

  // One forward run at `p`: the residual, or false when the run failed (or gave another number of rows).
  // Collective; the same result on every rank.
  bool residual(const std::vector<double>& p, std::vector<double>& r) {
    // The same point again (TAO's first evaluation is the start, already run): the last answer.
    if (p == last_p && last_ok) return r = last_r, true;
    ++runs;
    int code = forward(fit_overrides(in, p), work);
    std::vector<double> xs;
    std::vector<std::vector<double>> ys;
    const int columns = static_cast<int>(in.y.size());
    long n = -1;
    std::string error;
    if (code == 0 && is_root(comm)) {
      try {
        read_history_columns(work + "/history.csv", in.x, in.y, xs, ys);
        n = static_cast<long>(xs.size());
      } catch (const std::exception& e) {
        error = e.what();
      }
    }
    MPI_Bcast(&n, 1, MPI_LONG, 0, comm);
    bool ok = code == 0 && n > 0 && (m < 0 || n * columns == m);
    if (ok) {
      xs.resize(n), ys.resize(columns);
      MPI_Bcast(xs.data(), static_cast<int>(n), MPI_DOUBLE, 0, comm);
      for (auto& column : ys) {
        column.resize(n);
        MPI_Bcast(column.data(), static_cast<int>(n), MPI_DOUBLE, 0, comm);
      }
      if (m < 0) {
        m = n * columns;
        y_scale.resize(m);
        for (long e = 0; e < m; ++e) y_scale[e] = column_scale[e / n];
      }
      // Column after column: r[k n + i] = simulated y_k - measured y_k at row i's x.
      r.assign(n * columns, 0.0);
      long count = 0;
      for (long i = 0; i < n; ++i)
        if (xs[i] >= in.data_x.front() && xs[i] <= in.data_x.back()) {
          for (int k = 0; k < columns; ++k) r[k * n + i] = ys[k][i] - interpolate(in.data_x, in.data_y[k], xs[i]);
          count += columns;
        }
      if (inside == 0) inside = count;
      for (double v : r) ok = ok && std::isfinite(v);
    }
    double norm = 0;
    if (ok)
      for (double v : r) norm += v * v;
    norm = std::sqrt(norm);
    if (ok && norm < best) best = norm, best_r = r, best_values = p;
    last_p = p, last_r = r, last_ok = ok;
    if (!ok) ++failed;
    if (progress && is_root(comm)) {
      std::string line = "tissue fit: run " + std::to_string(runs) + ":";
      for (std::size_t j = 0; j < p.size(); ++j) {
        char s[96];
        std::snprintf(s, sizeof s, " %s=%.6g", in.parameters[j].key.c_str(), p[j]);
        line += s;
      }
      char s[96];
      if (ok)
        std::snprintf(s, sizeof s, "  |r| %.6e (best %.6e)", norm, best);
      else
        std::snprintf(s, sizeof s, "  failed (exit %d%s%s)", code, error.empty() ? "" : ": ", error.c_str());
      std::printf("%s%s\n", line.c_str(), s);
      std::fflush(stdout);
    }
    return ok;
  }
};

PetscErrorCode tao_residual(Tao, Vec U, Vec R, void* ctx) {
  auto* P = static_cast<Problem*>(ctx);
  const PetscScalar* u;
  PetscFunctionBeginUser;
  PetscCall(VecGetArrayRead(U, &u));
  std::vector<double> p = P->values(u);
  PetscCall(VecRestoreArrayRead(U, &u));
  std::vector<double> r;
  if (!P->residual(p, r)) {
    // A failed run: a residual larger than the best seen, so the trust region shrinks back towards the best point.
    r = P->best_r;
    for (double& v : r) v = 10.0 * v + (v >= 0 ? 1.0 : -1.0) * 1e-300;
    if (r.empty()) r.assign(P->m > 0 ? P->m : 1, 1e300);
  }
  PetscScalar* out;
  PetscInt len;
  PetscCall(VecGetLocalSize(R, &len));
  PetscCall(VecGetArray(R, &out));
  for (PetscInt i = 0; i < len; ++i) out[i] = i < static_cast<PetscInt>(r.size()) ? r[i] / P->y_scale[i] : 0.0;
  PetscCall(VecRestoreArray(R, &out));
  PetscFunctionReturn(0);
}

void check(PetscErrorCode ierr, const char* what) {
  if (!ierr) return;
  const std::string why = last_petsc_error();  // (src/solvers/petsc_errors.hpp)
  throw std::runtime_error(std::string("fit: PETSc failed in ") + what + (why.empty() ? "" : ": " + why));
}

}  // namespace

FitResult fit_parameters(const FitInput& input, const ForwardRun& forward, const std::string& work, MPI_Comm comm,
                         bool progress) {
  Problem P{input, forward, work, comm, progress, {}, -1, 0, 0, 0, {}, {}, {}, {}, {}, {}, false,
            std::numeric_limits<double>::infinity()};
  const int n = static_cast<int>(input.parameters.size());
  std::vector<double> u0(n);
  for (const auto& p : input.parameters) P.scales.emplace_back(p);
  for (int j = 0; j < n; ++j) u0[j] = P.scales[j].unit(input.parameters[j].start);
  for (const auto& column : input.data_y) {
    double y_largest = 0.0;
    for (double y : column) y_largest = std::max(y_largest, std::fabs(y));
    P.column_scale.push_back(y_largest > 0 ? y_largest : 1.0);
  }

  // 1. The start: its run fixes the residual's length (a failure here is the scene's, not the optimizer's).
  std::vector<double> r0;
  if (!P.residual(P.values(u0.data()), r0))
    throw std::runtime_error("fit: the forward run at the scene's own values failed: nothing to fit from");
  if (P.inside < n + 1)
    throw std::runtime_error("fit: only " + std::to_string(P.inside) + " simulated rows fall inside the measured " +
                             input.x + " range: more are needed to fit " + std::to_string(n) + " parameters");

  // 2. TAO POUNDERS on the scaled variables, redundantly on every rank (PETSC_COMM_SELF): the residuals are the
  //    same everywhere (broadcast from rank 0), so every rank takes the same steps and the forward runs, which are
  //    collective, line up.
  Tao tao;
  Vec U, R, lo, hi;
  check(TaoCreate(PETSC_COMM_SELF, &tao), "TaoCreate");
  check(TaoSetType(tao, TAOPOUNDERS), "TaoSetType");
  check(VecCreateSeq(PETSC_COMM_SELF, n, &U), "VecCreateSeq");
  check(VecDuplicate(U, &lo), "VecDuplicate");
  check(VecDuplicate(U, &hi), "VecDuplicate");
  check(VecCreateSeq(PETSC_COMM_SELF, P.m, &R), "VecCreateSeq");
  // A start on a bound moves inside by 1e-3 of the scaled range (POUNDERS needs room for its first model).
  for (int j = 0; j < n; ++j) check(VecSetValue(U, j, std::min(std::max(u0[j], 1e-3), 1.0 - 1e-3), INSERT_VALUES),
                                    "VecSetValue");
  check(VecAssemblyBegin(U), "VecAssemblyBegin");
  check(VecAssemblyEnd(U), "VecAssemblyEnd");
  check(VecSet(lo, 0.0), "VecSet");
  check(VecSet(hi, 1.0), "VecSet");
  check(TaoSetSolution(tao, U), "TaoSetSolution");
  check(TaoSetVariableBounds(tao, lo, hi), "TaoSetVariableBounds");
  check(TaoSetResidualRoutine(tao, R, tao_residual, &P), "TaoSetResidualRoutine");
  check(TaoSetMaximumFunctionEvaluations(tao, 40 * (n + 1)), "TaoSetMaximumFunctionEvaluations");
  check(TaoSetTolerances(tao, 1e-12, 1e-10, 0.0), "TaoSetTolerances");
  check(TaoSetOptionsPrefix(tao, "fit_"), "TaoSetOptionsPrefix");
  // POUNDERS' first trust region must lie inside the bounds (it refuses X0 + delta > upper): 0.1 of the scaled
  // range, less for a start near a bound (the user's -fit_tao_pounders_delta wins).
  PetscBool user_delta = PETSC_FALSE;
  check(PetscOptionsHasName(nullptr, nullptr, "-fit_tao_pounders_delta", &user_delta), "PetscOptionsHasName");
  if (!user_delta) {
    double delta = 0.1;
    for (int j = 0; j < n; ++j) delta = std::min(delta, 0.5 * std::max(std::min(u0[j], 1.0 - u0[j]), 1e-3));
    check(PetscOptionsSetValue(nullptr, "-fit_tao_pounders_delta", std::to_string(delta).c_str()),
          "PetscOptionsSetValue");
  }
  check(TaoSetFromOptions(tao), "TaoSetFromOptions");
  check(TaoSolve(tao), "TaoSolve");
  if (!user_delta) check(PetscOptionsClearValue(nullptr, "-fit_tao_pounders_delta"), "PetscOptionsClearValue");
  TaoConvergedReason reason;
  check(TaoGetConvergedReason(tao, &reason), "TaoGetConvergedReason");
  FitResult out;
  out.converged = reason > 0;
  out.reason = TaoConvergedReasons[reason];
  // The best point any run reached (TAO's last iterate is it, unless a later model step failed).
  std::vector<double> best = P.best_values;
  check(VecDestroy(&U), "VecDestroy");
  check(VecDestroy(&R), "VecDestroy");
  check(VecDestroy(&lo), "VecDestroy");
  check(VecDestroy(&hi), "VecDestroy");
  check(TaoDestroy(&tao), "TaoDestroy");

  // 3. Standard errors and correlations from the Jacobian at the best point, by forward differences in u (away
  //    from a bound), in the parameters' own units: Cov = s^2 (J^T J)^-1, s^2 = |r|^2 / (points - n).
  // Several y columns: the weighted problem (each column over its scale, as TAO saw it), so that the standard
  // errors do not mix units; with one column the weight cancels and this is the plain one.
  const bool weighted = input.y.size() > 1;
  std::vector<double> r = P.best_r, ub(n);
  if (weighted)
    for (long i = 0; i < P.m; ++i) r[i] /= P.y_scale[i];
  for (int j = 0; j < n; ++j) ub[j] = P.scales[j].unit(best[j]);
  Eigen::MatrixXd J(P.m, n);
  for (int j = 0; j < n; ++j) {
    const double du = ub[j] > 0.5 ? -1e-4 : 1e-4;
    std::vector<double> u = ub;
    u[j] += du;
    std::vector<double> p = P.values(u.data()), rj;
    const double dp = p[j] - best[j];
    if (!P.residual(p, rj) || dp == 0.0) {
      out.notes += "the Jacobian column of " + input.parameters[j].key + " could not be computed; ";
      J.col(j).setZero();
      continue;
    }
    for (long i = 0; i < P.m; ++i) J(i, j) = (rj[i] / (weighted ? P.y_scale[i] : 1.0) - r[i]) / dp;
  }
  out.values = best;
  out.forward_runs = P.runs, out.failed_runs = P.failed;
  out.residuals = P.inside;
  double ss = 0;
  for (double v : r) ss += v * v;
  out.residual_norm = std::sqrt(ss);
  const long rows = P.m / static_cast<long>(input.y.size());
  for (std::size_t k = 0; k < input.y.size(); ++k) {
    double column = 0;
    for (long i = 0; i < rows; ++i) column += P.best_r[k * rows + i] * P.best_r[k * rows + i];
    out.column_norms.push_back(std::sqrt(column));
  }
  const long dof = P.inside - n;
  const double s2 = dof > 0 ? ss / static_cast<double>(dof) : 0.0;
  const Eigen::MatrixXd JtJ = J.transpose() * J;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(JtJ);
  const double largest = eig.eigenvalues().cwiseAbs().maxCoeff(), smallest = eig.eigenvalues().minCoeff();
  out.standard_errors.assign(n, std::numeric_limits<double>::quiet_NaN());
  out.correlation.assign(n, std::vector<double>(n, std::numeric_limits<double>::quiet_NaN()));
  // Scale-free conditioning: J^T J of the columns normalised by their norms.
  Eigen::VectorXd norms = J.colwise().norm();
  bool zero_column = false;
  for (int j = 0; j < n; ++j) zero_column = zero_column || norms[j] == 0.0;
  if (!zero_column && largest > 0 && smallest > 0) {
    const Eigen::MatrixXd Jn = J * norms.cwiseInverse().asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> en(Jn.transpose() * Jn);
    const double cond = en.eigenvalues().maxCoeff() / std::max(en.eigenvalues().minCoeff(), 1e-300);
    const Eigen::MatrixXd inv = JtJ.inverse(), cov = s2 * inv;
    for (int a = 0; a < n; ++a) out.standard_errors[a] = std::sqrt(std::max(cov(a, a), 0.0));
    for (int a = 0; a < n; ++a)
      for (int b = 0; b < n; ++b) {
        const double d = std::sqrt(std::max(inv(a, a), 0.0) * std::max(inv(b, b), 0.0));
        out.correlation[a][b] = d > 0 ? inv(a, b) / d : std::numeric_limits<double>::quiet_NaN();
      }
    if (cond > 1e10) out.identifiable = false, out.notes += "J^T J is nearly singular (condition " + std::to_string(cond) + "); ";
    for (int a = 0; a < n; ++a)
      for (int b = a + 1; b < n; ++b)
        if (std::fabs(out.correlation[a][b]) > 0.999)
          out.identifiable = false, out.notes += input.parameters[a].key + " and " + input.parameters[b].key +
                                                 " cannot be separated by the data (correlation " +
                                                 std::to_string(out.correlation[a][b]) + "); ";
  } else {
    out.identifiable = false;
    for (int j = 0; j < n; ++j)
      if (norms[j] == 0.0) out.notes += input.parameters[j].key + " does not change the curve; ";
  }
  out.on_bound.resize(n);
  for (int j = 0; j < n; ++j) {
    out.on_bound[j] = ub[j] < 1e-6 || ub[j] > 1.0 - 1e-6;
    if (out.on_bound[j]) out.notes += input.parameters[j].key + " sits on a bound; ";
  }
  return out;
}

}  // namespace tissue
