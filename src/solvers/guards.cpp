#include "src/solvers/guards.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "partition/agreement.hpp"
#include "src/physics/force_model.hpp"
#include "src/solvers/molecule_report.hpp"

namespace tissue {

namespace {

// Adds the wall time of its scope to `total` (the guard's own cost, reported as solver.guard_seconds).
struct Timer {
  double& total;
  double start = MPI_Wtime();
  ~Timer() { total += MPI_Wtime() - start; }
};

}  // namespace

StepGuard::StepGuard(const char* solver, const Scene& scene, const LocalModel& model, const ForceModel& forces,
                     SolverState& state, long every, bool copy)
    : solver_(solver), scene_(scene), model_(model), forces_(forces), state_(state), every_(std::max(1L, every)),
      copy_(copy) {
  Timer timer{seconds_};
  // The switch is in PETSc's options database (-tissue_guards false after --, or PETSC_OPTIONS), read the same on
  // every rank; a malformed value is PETSc's error.
  PetscBool on = PETSC_TRUE;
  if (PetscOptionsGetBool(nullptr, nullptr, "-tissue_guards", &on, nullptr))
    throw InputError("PETSc options", "-tissue_guards", "expects true or false");
  enabled_ = on == PETSC_TRUE;
  if (!enabled_ && rank_of(model.comm) == 0)
    std::fprintf(stderr, "tissue: warning: -tissue_guards false: the %s solver's per-step guards are disabled (for "
                         "benchmarks only: NaN, Inf and energy growth are not caught)\n", solver);
  // Each reduction of the guards carries a "failed" flag for the local work before it (attempt(),
  // partition/agreement.hpp): a rank that fails there stops every rank at that reduction with its line, instead
  // of leaving them in the next collective; no collective of its own.
  prepare_agreement(model.comm);  // collective, once: here every rank is at the same point
  // A final check only (no copy): nothing compares energies, and its one connection pass is the check's own.
  if (!copy_) {
    keep();
    return;
  }
  double local[2] = {0, 0}, global[2];
  const std::exception_ptr error = attempt([&] {
    for (int i = 0; i < 3 * model.owned; ++i) local[0] += 0.5 * model.mass[i / 3] * state.v[i] * state.v[i];
  });
  local[1] = error ? 1.0 : 0.0;
  MPI_Allreduce(local, global, 2, MPI_DOUBLE, MPI_SUM, model.comm);
  if (global[1] > 0) agree_on(model.comm, error);
  kinetic_ = global[0];
  kinetic_checked_ = kinetic_;
  energy_check_ = energy_check_ && forces.energy_never_grows();
  // The energy at the start is the growth check's reference, which only dynamic_step reads, and only with the
  // guards on (read the same on every rank: the reduction in energy() is skipped on all or none).
  if (enabled_) {
    double spring, work;
    energy0_ = kinetic_ + energy(&spring, &work);
  }
  keep();
}

void StepGuard::keep() {
  // With the guards off (benchmarks) no copy: 48 bytes a molecule that a run without checks would never restore.
  if (!enabled_) return;
  if (copy_) {
    const std::size_t xs = state_.x_streams, vs = state_.v_streams, n = model_.owned;
    if (xs) {  // the dynamic solver's streams: kept interlaced, as fail() puts them back
      const double* x = state_.x.array();
      const double* v = state_.v.data();
      good_x_.resize(3 * n), good_v_.resize(3 * n);
      for (std::size_t i = 0; i < n; ++i)
        for (int d = 0; d < 3; ++d) good_x_[3 * i + d] = x[d * xs + i], good_v_[3 * i + d] = v[d * vs + i];
    } else {
      good_x_.assign(state_.x.array(), state_.x.array() + 3 * n);
      good_v_ = state_.v;
    }
  }
  good_step_ = state_.step;
  good_time_ = state_.time;
}

// Potential energy of the springs and the work of the loads and gravity (both global) at the current positions;
// returns spring - work. Each connection is counted once over all ranks (written_here).
double StepGuard::energy(double* spring, double* work) {
  const double* x = state_.x.array();
  const std::size_t xs = state_.x_streams;  // (either layout: SolverState)
  const Components at{x, xs};
  double sums[3] = {0, 0, 0};
  const std::exception_ptr error = attempt([&] {
    // (the connection with the smallest ratio is named by check_lengths, only when it fails)
    forces_.kernel().energy_and_shortest(x, &sums[0], &worst_ratio_, xs);
    for (const auto& a : forces_.applied())
      sums[1] += a.value * (at(a.component / 3, a.component % 3) - model_.rest[a.component]);
    if (const auto& g = scene_.physics.gravity)
      for (int i = 0; i < model_.owned; ++i)
        for (int d = 0; d < 3; ++d) sums[1] += model_.mass[i] * (*g)[d] * (at(i, d) - model_.rest[3 * i + d]);
  });
  sums[2] = error ? 1.0 : 0.0;
  double global[3];
  MPI_Allreduce(sums, global, 3, MPI_DOUBLE, MPI_SUM, model_.comm);
  if (global[2] > 0) agree_on(model_.comm, error);
  *spring = global[0], *work = global[1];
  return global[0] - global[1];
}

void StepGuard::check_finite_state() {
  std::vector<double> bad;
  int any[2] = {0, 0}, all[2];
  const std::exception_ptr error = attempt([&] {
    fault_point("guard", model_.comm);
    // (an integer OR over the components: a reduction the compiler vectorizes, no branch a component)
    constexpr double largest = std::numeric_limits<double>::max();
    int flag = 0;
    auto scan = [&](const double* a, std::size_t n) {
      for (std::size_t j = 0; j < n; ++j) flag |= static_cast<int>(!(std::fabs(a[j]) <= largest));
    };
    const std::size_t n = model_.owned, xs = state_.x_streams, vs = state_.v_streams;
    if (xs) {  // the dynamic solver's streams (SolverState): each stream's owned rows
      for (int d = 0; d < 3; ++d)
        scan(state_.x.array() + d * xs, n), scan(state_.v.data() + d * vs, n), scan(state_.f.data() + d * xs, n);
    } else {
      scan(state_.x.array(), 3 * n), scan(state_.v.data(), 3 * n), scan(state_.f.data(), 3 * n);
    }
    any[0] = flag;
  });
  any[1] = error ? 1 : 0;
  MPI_Allreduce(any, all, 2, MPI_INT, MPI_MAX, model_.comm);
  if (all[1]) agree_on(model_.comm, error);
  if (!all[0]) return;
  // A failure: the molecules named (the per-molecule flags only now), from the state interlaced
  read_state();
  const double* x = state_.x.array();
  const double* v = state_.v.data();
  const double* f = state_.f.data();
  auto finite = [&](int j) { return std::isfinite(x[j]) && std::isfinite(v[j]) && std::isfinite(f[j]); };
  bad.assign(model_.owned, 0.0);
  for (int i = 0; i < model_.owned; ++i)
    for (int d = 0; d < 3; ++d)
      if (!finite(3 * i + d)) bad[i] = 1.0;
  // The first non-finite molecule: bad = 1 is the largest value, ties go to the smallest id.
  fail("non-finite position, velocity or force" + first_seen_, argmax_molecule(model_, bad));
}

void StepGuard::check_lengths(bool from_energy) {
  const double* x = state_.x.array();
  const std::size_t xs = state_.x_streams;
  double worst = std::numeric_limits<double>::infinity();
  long long worst_id = -1;
  int worst_c = -1;
  std::exception_ptr error;
  if (from_energy) {
    worst = worst_ratio_;
  } else {
    error = attempt([&] {
      double unused;
      forces_.kernel().energy_and_shortest(x, &unused, &worst, xs);
    });
  }
  double mins[2] = {worst, error ? -1.0 : 0.0}, reduced[2];  // MIN: the flag is -1 when a rank failed
  MPI_Allreduce(mins, reduced, 2, MPI_DOUBLE, MPI_MIN, model_.comm);
  if (reduced[1] < 0) agree_on(model_.comm, error);
  const double global = reduced[0];
  if (!(global < kCollapsedLengthRatio)) return;
  // A failure (rare): the first connection in this rank's order with the smallest ratio (the same doubles as the
  // kernel's pass), named, from the state interlaced.
  read_state();
  x = state_.x.array();
  worst = std::numeric_limits<double>::infinity();
  model_.for_each_written([&](int c, int a, int b) {
    const double ratio = length_of(x, a, b) / model_.l0(c);
    if (ratio < worst) worst = ratio, worst_id = model_.connection_id(c), worst_c = c;
  });
  long long mine = worst == global ? worst_id : std::numeric_limits<long long>::max(), first = 0;
  MPI_Allreduce(&mine, &first, 1, MPI_LONG_LONG, MPI_MIN, model_.comm);
  long long molecule = mine == first && worst_c >= 0 ? model_.id[model_.end_a[worst_c]] : -1, m = -1;
  MPI_Allreduce(&molecule, &m, 1, MPI_LONG_LONG, MPI_MAX, model_.comm);
  fail(fmt::format("connection {} collapsed to {:.3g} of its rest length (below {:g}: inverted or crushed)", first,
                   global, kCollapsedLengthRatio),
       m);
}

void StepGuard::full_check() {
  Timer timer{seconds_};
  read_state();
  ++checks_;
  check_finite_state();
  check_lengths();
  keep();
}

void StepGuard::full_check_as_made() {
  Timer timer{seconds_};
  read_state();
  ++checks_;
  check_finite_state();
  check_lengths(/*from_energy=*/copy_);  // no copy: the constructor made no pass (no energies)
}

void StepGuard::dynamic_step(double local_kinetic, bool whole, bool observed) {
  if (!enabled_) return;
  Timer timer{seconds_};
  if (!std::isfinite(local_kinetic) && first_bad_step_ < 0) first_bad_step_ = state_.step;
  // (a pending check is made at the next whole step, whatever its number: every rank has it pending, from the
  // same reduced values)
  // (the solver's full_check() at the last step covers the steps after the last kReduceEvery-th)
  if (state_.step % kReduceEvery != 0 && !pending_ && !observed) return;
  if (pending_ && !whole) throw std::logic_error("StepGuard: a pending check needs a whole step");
  pending_ = false;
  const std::exception_ptr error = attempt([&] { fault_point("guard", model_.comm); });
  double local[3] = {first_bad_step_ >= 0 ? 0.0 : local_kinetic, first_bad_step_ >= 0 ? 1.0 : 0.0,
                     error ? 1.0 : 0.0}, global[3];
  MPI_Allreduce(local, global, 3, MPI_DOUBLE, MPI_SUM, model_.comm);
  if (global[2] > 0) agree_on(model_.comm, error);
  kinetic_ = global[0];
  const bool bad = global[1] > 0 || !std::isfinite(kinetic_);
  if (!whole && (bad || kinetic_ > 2.0 * kinetic_checked_ || state_.step % every_ == 0)) {
    pending_ = true;  // the state is not this step's: checked at the next, whole, step
    return;
  }
  if (bad) {
    long mine = first_bad_step_ >= 0 ? first_bad_step_ : state_.step, first = 0;
    MPI_Allreduce(&mine, &first, 1, MPI_LONG, MPI_MIN, model_.comm);
    first_seen_ = fmt::format(" (first non-finite kinetic energy at step {})", first);
    read_state();
    check_finite_state();  // names the first non-finite molecule and throws
    fail("non-finite kinetic energy" + first_seen_, -1);
  }
  const bool grown = kinetic_ > 2.0 * kinetic_checked_;
  if (!grown && state_.step % every_ != 0) return;
  // Energy growth: the whole-step energy E = kinetic + springs - work of loads and gravity is conserved by a
  // stable run up to small oscillations (viscosity only removes energy); an unstable mode makes it grow like
  // the energy itself. Checked when the kinetic energy exceeds twice the largest kinetic energy of any check so
  // far, and every `every` steps. A stable run's kinetic energy is bounded, so after its first rise (a few
  // doublings from rest) only the periodic checks remain; an unstable mode outgrows every earlier maximum and is
  // checked at each doubling. (Measured against the last check's kinetic energy instead, every oscillation that
  // passed near rest re-armed a dozen checks: 25 checks per 1000 steps of a loaded 40^3 box, now 11; each costs
  // about one force evaluation. docs/stability.md.)
  kinetic_checked_ = std::max(kinetic_checked_, kinetic_);
  // (the state as the solver keeps it: interlaced or its streams; the failures below read it interlaced)
  double spring, work;
  const double e = kinetic_ + energy(&spring, &work);
  const double scale = kinetic_ + spring + std::fabs(work) + std::fabs(energy0_);
  if (energy_check_ && e - energy0_ > 0.5 * scale && scale > 0) {
    read_state();
    std::vector<double> ke(model_.owned);
    for (int i = 0; i < model_.owned; ++i)
      ke[i] = model_.mass[i] * (state_.v[3 * i] * state_.v[3 * i] + state_.v[3 * i + 1] * state_.v[3 * i + 1] +
                                state_.v[3 * i + 2] * state_.v[3 * i + 2]);
    fail(fmt::format("energy growth (total energy {:.6g} J, initial {:.6g} J, kinetic {:.6g} J: unstable time step?)",
                     e, energy0_, kinetic_),
         argmax_molecule(model_, ke));
  }
  // The full check, reusing the connection pass energy() just made.
  ++checks_;
  check_finite_state();
  check_lengths(/*from_energy=*/true);
  keep();
}

void StepGuard::relaxation_step(double residual) {
  if (!enabled_) return;
  Timer timer{seconds_};
  if (!std::isfinite(residual)) {
    check_finite_state();
    fail("non-finite residual", largest_force_molecule(model_, state_.f.data()));
  }
  if (residual0_ < 0) residual0_ = residual;
  if (residual > 1e6 * std::max(1.0, residual0_))
    fail(fmt::format("diverged (relative residual {:.3g}, initial {:.3g}: time step too large?)", residual,
                     residual0_),
         largest_force_molecule(model_, state_.f.data()));
  if (state_.step % every_ == 0) full_check();
}

void StepGuard::fail(const std::string& problem, std::int64_t molecule) {
  read_state();
  std::string where = molecule >= 0 ? describe_molecule(model_, state_.x.array(), molecule) : "no molecule found";
  const long step = state_.step;
  if (!enabled_)  // the final check of an unguarded run: no earlier state kept, so nothing may be written
    throw SolverFailure(fmt::format("{}: {} at step {}: {}; no earlier state kept (-tissue_guards false): "
                                    "nothing written", solver_, problem, step, where),
                        SolverFailure::State::nothing);
  // Put the last good state back: main() writes it as DIR/last_good.h5.
  if (copy_) {
    std::copy(good_x_.begin(), good_x_.end(), state_.x.array());
    state_.x.update_ghosts();
    state_.v = good_v_;
  }
  state_.step = good_step_;
  state_.time = good_time_;
  throw SolverFailure(fmt::format("{}: {} at step {}: {}; last good state: step {}", solver_, problem, step, where,
                                  good_step_), SolverFailure::State::last_good);
}

}  // namespace tissue