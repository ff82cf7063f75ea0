// Dynamic: undamped velocity Verlet in real time (half kick, drift, forces, half kick) for solver.steps steps in
// total (a restart continues until that total). Viscous friction, when the scene lists it, acts through the
// force model with the half-step velocity.
//
// Energy: besides the kinetic + potential energy at whole steps, which Verlet conserves only up to O((w dt)^2)
// oscillations, the report carries the leapfrog energy 1/2 v(n-1/2).M v(n+1/2) + U(x(n)), which the scheme
// conserves exactly for linear springs; its drift measures the integrator and the nonlinearity, not dt.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <optional>
#include <vector>

#if defined(__x86_64__)
#include <immintrin.h>
#endif
#include <mpi.h>

#include "partition/ghosted_vector.hpp"
#include "src/solvers/guards.hpp"
#include "src/solvers/progress.hpp"
#include "src/solvers/setup_checks.hpp"
#include "src/solvers/solver.hpp"
#include "src/vector_clones.hpp"

namespace tissue {

namespace {
// Total leapfrog energy (global), with v at a whole step and a = f/m there.
double leapfrog_energy(const LocalModel& model, const ForceModel& forces, const SolverState& s, double dt) {
  double e = forces.potential_energy(s.x.array());
  for (int i = 0; i < model.owned; ++i)
    for (int d = 0; d < 3; ++d) {
      const double vi = s.v[3 * i + d], ai = s.f[3 * i + d] / model.mass[i];
      e += 0.5 * model.mass[i] * (vi * vi - 0.25 * dt * dt * ai * ai);
    }
  double total = 0;
  MPI_Allreduce(&e, &total, 1, MPI_DOUBLE, MPI_SUM, model.comm);
  return total;
}
std::size_t v_size(const LocalModel& model) { return 3 * static_cast<std::size_t>(model.owned); }

// The Verlet passes over the owned molecules, compiled for AVX-512, AVX2 and the baseline (picked at run time,
// as the spring kernel's): each molecule's half kick dt / 2m is computed in the pass (the same doubles as a
// stored array, without its 8 bytes a molecule), and a pass that sums the kinetic energy first writes each
// molecule's m v^2 to a small block and then adds the block in molecule order, so that the loop over the
// molecules vectorizes and the sum keeps the order (and bits) of a plain loop. (TISSUE_CLONES:
// src/vector_clones.hpp)
constexpr int kBlock = 256;

// Half kick and drift: v += dt/2m f, x += dt v.
TISSUE_CLONES
void kick_drift(int n, double dt, const double* __restrict m, const double* __restrict f, double* __restrict v,
                double* __restrict x) {
  for (int i = 0; i < n; ++i) {
    const double kick = 0.5 * dt / m[i];
    for (int d = 0; d < 3; ++d) {
      const int j = 3 * i + d;
      v[j] += kick * f[j];
      x[j] += dt * v[j];
    }
  }
}

// Runs update(i), which moves molecule i and returns its m v^2, over the molecules [0, n) in blocks, and adds
// each block's values in molecule order (inlined into the clones below, so the loop over a block vectorizes).
template <class Update>
__attribute__((always_inline)) inline double kinetic_sum(int n, Update update, double kinetic = 0) {
  alignas(64) double ke[kBlock];
  for (int i0 = 0; i0 < n; i0 += kBlock) {
    const int b = std::min(kBlock, n - i0);
    for (int i = i0; i < i0 + b; ++i) ke[i - i0] = update(i);
    for (int i = 0; i < b; ++i) kinetic += ke[i];
  }
  return kinetic;
}

// Half kick to the whole step (its kinetic energy, returned: `kinetic` plus the sum of m v^2 in molecule order),
// then the next step's half kick and drift.
TISSUE_CLONES
double kick_kick_drift(int n, double dt, const double* __restrict m, const double* __restrict f,
                       double* __restrict v, double* __restrict x, double kinetic = 0) {
  return kinetic_sum(n, [&](int i) __attribute__((always_inline)) {
    const double kick = 0.5 * dt / m[i];
    double vv = 0;
    for (int d = 0; d < 3; ++d) {
      const int j = 3 * i + d;
      const double whole = v[j] + kick * f[j];  // half kick to the whole step (held: f = 0, v = 0)
      vv += whole * whole;
      v[j] = whole + kick * f[j];  // the next step's half kick
      x[j] += dt * v[j];           // and drift
    }
    return m[i] * vv;
  }, kinetic);
}

// The fused steps' state as three streams (structure of arrays: x[d * stride + i] for d = x, y, z), so that the
// spring kernel loads and stores whole vectors of one component instead of de-interleaving PETSc's blocks of 3:
// the same arithmetic as kick_kick_drift, on other addresses.
struct Streams3 {
  const double* f[3];
  double* v[3];
  double* x[3];
};
Streams3 streams_at(const Streams3& s, int begin) {
  return {{s.f[0] + begin, s.f[1] + begin, s.f[2] + begin},
          {s.v[0] + begin, s.v[1] + begin, s.v[2] + begin},
          {s.x[0] + begin, s.x[1] + begin, s.x[2] + begin}};
}

TISSUE_CLONES
double kick_kick_drift_streams(int n, double dt, const double* __restrict m, const double* __restrict f0,
                               const double* __restrict f1, const double* __restrict f2, double* __restrict v0,
                               double* __restrict v1, double* __restrict v2, double* __restrict x0,
                               double* __restrict x1, double* __restrict x2, double kinetic) {
  return kinetic_sum(n, [&](int i) __attribute__((always_inline)) {
    const double kick = 0.5 * dt / m[i];
    const double w0 = v0[i] + kick * f0[i], w1 = v1[i] + kick * f1[i], w2 = v2[i] + kick * f2[i];
    double vv = 0;
    vv += w0 * w0, vv += w1 * w1, vv += w2 * w2;
    v0[i] = w0 + kick * f0[i], v1[i] = w1 + kick * f1[i], v2[i] = w2 + kick * f2[i];
    x0[i] += dt * v0[i], x1[i] += dt * v1[i], x2[i] += dt * v2[i];
    return m[i] * vv;
  }, kinetic);
}

// The same without the kinetic energy, for a run whose guards are off (nothing else reads it): the sum is a chain
// of dependent additions (molecule order), a few cycles a molecule.
TISSUE_CLONES
void kick_kick_drift_only_streams(int n, double dt, const double* __restrict m, const double* __restrict f0,
                                  const double* __restrict f1, const double* __restrict f2, double* __restrict v0,
                                  double* __restrict v1, double* __restrict v2, double* __restrict x0,
                                  double* __restrict x1, double* __restrict x2) {
  for (int i = 0; i < n; ++i) {
    const double kick = 0.5 * dt / m[i];
    v0[i] = (v0[i] + kick * f0[i]) + kick * f0[i];
    v1[i] = (v1[i] + kick * f1[i]) + kick * f1[i];
    v2[i] = (v2[i] + kick * f2[i]) + kick * f2[i];
    x0[i] += dt * v0[i], x1[i] += dt * v1[i], x2[i] += dt * v2[i];
  }
}

// The molecules' masses as a byte a molecule (its type: the index of its mass among the rank's distinct masses)
// and the types' half kicks dt / 2m, for the fused steps' kicks: 1 byte a molecule streamed from
// memory instead of 8 (a lattice has a few masses: interior, faces, edges, corners). The table's values are the
// per-molecule expressions' own doubles, so the kicks' bits are unchanged. Empty when a rank has more than
// kMassTypes distinct masses (the kicks then read m).
constexpr int kMassTypes = 16;  // two zmm registers of half kicks
struct MassTypes {
  std::vector<std::uint8_t> type;
  double half_kick[kMassTypes] = {};
  double mass[kMassTypes] = {};  // each type's m (the kinetic energy's)
  MassTypes(int n, const double* m, double dt) {
    std::uint64_t bits[kMassTypes];
    int types = 0, last = 0;
    std::vector<std::uint8_t> t(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      std::uint64_t b;
      std::memcpy(&b, m + i, sizeof b);  // equal doubles by their bits (the same m, the same half kick)
      if (types == 0 || bits[last] != b) {
        last = 0;
        while (last < types && bits[last] != b) ++last;
        if (last == types) {
          if (types == kMassTypes) return;
          bits[types] = b, half_kick[types] = 0.5 * dt / m[i], mass[types] = m[i], ++types;
        }
      }
      t[i] = static_cast<std::uint8_t>(last);
    }
    type = std::move(t);
  }
};

// The drifting kicks (kick_kick_drift_only_streams, or with Sum kick_kick_drift_streams's kinetic energy) with the
// half kick by type: the types' half kicks in two zmm registers and each row's picked by its type byte (vpermt2pd:
// a table lookup without a gather), 8 rows an iteration; the same operations on the same doubles in the same order
// (no contraction: -ffp-contract=off), so the same bits. With Sum, each row's m v^2 (m from the types' table) is
// summed in 8 lanes, added to `kinetic` at the end in a fixed order: not molecule order, so the sum's last bits may
// differ from kick_kick_drift_streams's; only the guards read it (a non-finite value, growth against factors of 2),
// and a chain of dependent additions a molecule is what the lanes save.
#if defined(__x86_64__)
template <bool Sum>
__attribute__((target("avx512f"))) double kick_kick_drift_typed_avx512(
    int n, double dt, const MassTypes& types, const std::uint8_t* __restrict type, const double* __restrict f0,
    const double* __restrict f1, const double* __restrict f2, double* __restrict v0, double* __restrict v1,
    double* __restrict v2, double* __restrict x0, double* __restrict x1, double* __restrict x2, double kinetic) {
  const double* half_kick = types.half_kick;
  const __m512d lo = _mm512_loadu_pd(half_kick), hi = _mm512_loadu_pd(half_kick + 8), h = _mm512_set1_pd(dt);
  const __m512d mlo = _mm512_loadu_pd(types.mass), mhi = _mm512_loadu_pd(types.mass + 8);
  const double* f[3] = {f0, f1, f2};
  double* v[3] = {v0, v1, v2};
  double* x[3] = {x0, x1, x2};
  __m512d sum = _mm512_setzero_pd();
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    std::uint64_t t8;
    std::memcpy(&t8, type + i, sizeof t8);
    // (the zero-masked widening: the same instruction, without GCC 12's false uninitialized warning)
    const __m512i t = _mm512_maskz_cvtepu8_epi64(0xff, _mm_cvtsi64_si128(static_cast<long long>(t8)));
    const __m512d kick = _mm512_permutex2var_pd(lo, t, hi);
    __m512d vv = _mm512_setzero_pd();
    for (int d = 0; d < 3; ++d) {
      const __m512d kf = _mm512_mul_pd(kick, _mm512_loadu_pd(f[d] + i));
      const __m512d whole = _mm512_add_pd(_mm512_loadu_pd(v[d] + i), kf);  // the half kick to the whole step
      if (Sum) vv = _mm512_add_pd(vv, _mm512_mul_pd(whole, whole));
      const __m512d w = _mm512_add_pd(whole, kf);
      _mm512_storeu_pd(v[d] + i, w);
      _mm512_storeu_pd(x[d] + i, _mm512_add_pd(_mm512_loadu_pd(x[d] + i), _mm512_mul_pd(h, w)));
    }
    if (Sum) sum = _mm512_add_pd(sum, _mm512_mul_pd(_mm512_permutex2var_pd(mlo, t, mhi), vv));
  }
  if (Sum) {
    alignas(64) double lanes[8];
    _mm512_store_pd(lanes, sum);
    for (double l : lanes) kinetic += l;
  }
  for (; i < n; ++i) {
    const double kick = half_kick[type[i]];
    double vv = 0;
    for (int d = 0; d < 3; ++d) {
      const double whole = v[d][i] + kick * f[d][i];
      vv += whole * whole;
      v[d][i] = whole + kick * f[d][i];
      x[d][i] += dt * v[d][i];
    }
    if (Sum) kinetic += types.mass[type[i]] * vv;
  }
  return kinetic;
}
#endif  // __x86_64__

// The half kick to the whole step alone (the step before an observed state) and the half kick and drift that
// follow it, on the streams: kick() and kick_drift()'s arithmetic, on other addresses.
TISSUE_CLONES
double kick_streams(int n, double dt, const double* __restrict m, const double* __restrict f0,
                    const double* __restrict f1, const double* __restrict f2, double* __restrict v0,
                    double* __restrict v1, double* __restrict v2, double kinetic) {
  return kinetic_sum(n, [&](int i) __attribute__((always_inline)) {
    const double kick = 0.5 * dt / m[i];
    v0[i] += kick * f0[i], v1[i] += kick * f1[i], v2[i] += kick * f2[i];
    double vv = 0;
    vv += v0[i] * v0[i], vv += v1[i] * v1[i], vv += v2[i] * v2[i];
    return m[i] * vv;
  }, kinetic);
}
TISSUE_CLONES
void kick_only_streams(int n, double dt, const double* __restrict m, const double* __restrict f0,
                       const double* __restrict f1, const double* __restrict f2, double* __restrict v0,
                       double* __restrict v1, double* __restrict v2) {
  for (int i = 0; i < n; ++i) {
    const double kick = 0.5 * dt / m[i];
    v0[i] += kick * f0[i], v1[i] += kick * f1[i], v2[i] += kick * f2[i];
  }
}
TISSUE_CLONES
void kick_drift_streams(int n, double dt, const double* __restrict m, const double* __restrict f0,
                        const double* __restrict f1, const double* __restrict f2, double* __restrict v0,
                        double* __restrict v1, double* __restrict v2, double* __restrict x0, double* __restrict x1,
                        double* __restrict x2) {
  for (int i = 0; i < n; ++i) {
    const double kick = 0.5 * dt / m[i];
    v0[i] += kick * f0[i], v1[i] += kick * f1[i], v2[i] += kick * f2[i];
    x0[i] += dt * v0[i], x1[i] += dt * v1[i], x2[i] += dt * v2[i];
  }
}

// The fused step (springs only): the kick-kick-drift on each run of rows the spring kernel hands over as final,
// while they are still in cache, so x, v and f stream from memory once a step instead of twice. The runs come in
// molecule order and the kinetic sum carries over, so every bit is that of the separate pass.
struct FusedStreams {
  double dt;
  const double* m;
  Streams3 at;
  double kinetic;
  bool sum;  // whether anything reads the kinetic energy (the guards)
  bool drift;  // false: the step ends at an observed whole step (the half kick to it alone)
  std::size_t ring = 0;  // f's rows in a ring of this many (SpringKernel::forces_ring); 0: f has every row
  const MassTypes* types = nullptr;  // the drifting kicks' masses by type (null: from m)
};
void fused_rows_streams(void* context, int begin, int end) {
  FusedStreams& s = *static_cast<FusedStreams*>(context);
  Streams3 p = streams_at(s.at, begin);
  if (s.ring)  // the kernel hands over runs within one turn of the ring
    for (int d = 0; d < 3; ++d) p.f[d] = s.at.f[d] + (static_cast<std::size_t>(begin) & (s.ring - 1));
  if (!s.drift) {
    if (s.sum)
      s.kinetic = kick_streams(end - begin, s.dt, s.m + begin, p.f[0], p.f[1], p.f[2], p.v[0], p.v[1], p.v[2],
                               s.kinetic);
    else
      kick_only_streams(end - begin, s.dt, s.m + begin, p.f[0], p.f[1], p.f[2], p.v[0], p.v[1], p.v[2]);
    return;
  }
#if defined(__x86_64__)
  if (s.types) {
    auto kicks = s.sum ? kick_kick_drift_typed_avx512<true> : kick_kick_drift_typed_avx512<false>;
    s.kinetic = kicks(end - begin, s.dt, *s.types, s.types->type.data() + begin, p.f[0], p.f[1], p.f[2], p.v[0],
                      p.v[1], p.v[2], p.x[0], p.x[1], p.x[2], s.kinetic);
    return;
  }
#endif
  if (s.sum)
    s.kinetic = kick_kick_drift_streams(end - begin, s.dt, s.m + begin, p.f[0], p.f[1], p.f[2], p.v[0], p.v[1],
                                        p.v[2], p.x[0], p.x[1], p.x[2], s.kinetic);
  else
    kick_kick_drift_only_streams(end - begin, s.dt, s.m + begin, p.f[0], p.f[1], p.f[2], p.v[0], p.v[1], p.v[2],
                                 p.x[0], p.x[1], p.x[2]);
}

// n molecules' values, interlaced (a[3 i + d]) to three streams (a[d * n + i]) and back, in place through
// `scratch` (3 n values): the fused steps borrow the force array, whose values no later pass reads, so the
// streams cost no memory.
TISSUE_CLONES
void to_streams(double* __restrict a, int n, double* __restrict scratch) {
  for (int i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d) scratch[d * static_cast<std::size_t>(n) + i] = a[3 * static_cast<std::size_t>(i) + d];
  std::copy(scratch, scratch + 3 * static_cast<std::size_t>(n), a);
}
TISSUE_CLONES
void to_interlaced(double* __restrict a, int n, double* __restrict scratch) {
  for (int i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d) scratch[3 * static_cast<std::size_t>(i) + d] = a[d * static_cast<std::size_t>(n) + i];
  std::copy(scratch, scratch + 3 * static_cast<std::size_t>(n), a);
}

// Half kick to the whole step; returns the sum of m v^2.
TISSUE_CLONES
double kick(int n, double dt, const double* __restrict m, const double* __restrict f, double* __restrict v) {
  return kinetic_sum(n, [&](int i) __attribute__((always_inline)) {
    const double kick = 0.5 * dt / m[i];
    double vv = 0;
    for (int d = 0; d < 3; ++d) {
      const int j = 3 * i + d;
      v[j] += kick * f[j];  // half kick (held: f = 0, v = 0)
      vv += v[j] * v[j];
    }
    return m[i] * vv;
  });
}
}  // namespace

SolveReport solve_dynamic(const Scene& scene, const LocalModel& model, const ForceModel& forces, SolverState& state,
                          const SolverHooks& hooks) {
  SolveReport report;
  report.critical_time_step = critical_time_step(forces);
  const double dt = scene.solver.time_step ? checked_time_step(scene, model, *scene.solver.time_step,
                                                                report.critical_time_step, "dynamic")
                                           : 0.5 * report.critical_time_step;
  report.time_step = dt;
  state.time_step = dt;
  const double* m = model.mass.data();
  double* x = state.x.array();
  double* v = state.v.data();
  double* f = state.f.data();

  Progress progress("dynamic", scene.output.progress, model.comm);
  state.x.update_ghosts();
  forces.set_time(state.time);  // time-dependent terms (cyclic loads) read the time of the evaluation
  // The forces at the start: a restart evaluates them with the half-step velocities the straight run used.
  const bool keep_half = forces.reads_velocity();
  const bool restart_half = keep_half && state.restarted && state.v_half.size() == v_size(model);
  forces.forces(x, restart_half ? state.v_half.data() : v, f);
  if (keep_half) state.v_half.assign(v_size(model), 0.0);
  double* v_half = keep_half ? state.v_half.data() : nullptr;
  // (a restart reports the energy of the run's start, which its checkpoint keeps, not of the checkpoint's step)
  if (!(state.restarted && std::isfinite(state.energy_initial)))
    state.energy_initial = leapfrog_energy(model, forces, state, dt);
  report.energy_initial = state.energy_initial;
  // NaN, Inf and energy growth caught within 16 steps (one reduction per 16 steps, the first non-finite step
  // named), connection lengths every 128 steps; the last good state is kept (guards.hpp).
  StepGuard guard("dynamic", scene, model, forces, state);
  const long total = scene.solver.steps;
  // Held components: zero velocity from here on (their force is zero, so the kicks keep it zero); the step
  // loops then read no held flags.
  for (int j : forces.held_owned()) v[j] = 0.0;
  const int n = model.owned;
  // Whether nothing reads the state at whole step s interlaced (snapshots and checkpoints come at multiples of
  // their cadences; history.csv's rows and the guard's periodic checks read the streams as they are: SolverState
  // ::x_streams): then the fused streams may end there; whether nothing but the guard's reductions and the
  // signal check reads it at all (no row either): then the half kick that ends step s, the one that starts step
  // s + 1 and its drift are one pass over the molecules instead of two, with the same arithmetic.
  const long rows = hooks.record ? scene.output.history_every : 0;  // history.csv's cadence
  auto streams_read = [&](long s) {
    const long snap = hooks.snapshot ? scene.output.snapshot_every : 0, ckpt = scene.output.checkpoint_every;
    return s < total && !(snap > 0 && s % snap == 0) && !(ckpt > 0 && s % ckpt == 0);
  };
  auto unread = [&](long s) { return streams_read(s) && !(rows > 0 && s % rows == 0); };
  auto unobserved = [&](long s) { return unread(s) && s % kReduceEvery != 0; };
  if (rows > 0 && !state.restarted) hooks.record(state);  // history.csv's first row: the state at t = 0
  const bool history = forces.has_history();
  // Springs alone (no load, term or held component, on every rank: the fused steps' ghost update is
  // collective): the kicks go inside the kernel's sweep, and x, v and f stay as three streams each (Streams3)
  // between steps, the guards' steps (every kReduceEvery-th) included: turned back into PETSc's interlaced blocks
  // only before a step whose state something reads (a snapshot, checkpoint or history row), when the guard reads
  // the state (its full checks) or a stop writes a checkpoint, and at the end.
  // Both decisions agreed: {springs only here, no ghosts here}, each the least over the ranks.
  int here[2] = {forces.springs_only() ? 1 : 0, model.local == model.owned ? 1 : 0}, everywhere[2] = {0, 0};
  MPI_Allreduce(here, everywhere, 2, MPI_INT, MPI_MIN, model.comm);
  const bool fuse = everywhere[0] == 1;
  const int local = model.local;
  std::optional<StreamGhosts> stream_ghosts;
  if (fuse && everywhere[1] == 0) stream_ghosts.emplace(model);
  // The fused steps that drift need each force only until its row's kicks: their forces go into a ring of a few
  // planes' rows that stays in cache (SpringKernel::forces_ring), not through memory. The steps that end at a
  // whole step keep every row's force in f (the next step's half kick reads it, and the state may be read).
  const std::size_t ring_rows = fuse ? static_cast<std::size_t>(forces.kernel().ring_rows()) : 0;
  std::vector<double> ring(ring_rows ? 3 * (ring_rows + static_cast<std::size_t>(model.local - model.owned)) : 0);
  // (the drifting kicks by mass type on a CPU with AVX-512; everywhere else from m)
  std::optional<MassTypes> mass_types;
#if defined(__x86_64__)
  if (fuse && __builtin_cpu_supports("avx512f")) mass_types.emplace(n, m, dt);
#endif
  const MassTypes* types = mass_types && !mass_types->type.empty() ? &*mass_types : nullptr;
  bool streams = false;  // x, v, f hold three streams each (x and f: stride local, v: stride n)
  auto set_streams = [&](bool on) {
    if (on == streams) return;
    // f's values are spent here (the last step's kicks used them; the next step recomputes them).
    if (on) to_streams(x, local, f), to_streams(v, n, f);
    else to_interlaced(x, local, f), to_interlaced(v, n, f);
    streams = on;
    state.x_streams = on ? static_cast<std::size_t>(local) : 0;  // (what the guard and history rows read)
    state.v_streams = on ? static_cast<std::size_t>(n) : 0;
  };
  bool drifted = false;  // the last pass already did this step's half kick and drift
  // The state at a whole step, interlaced, for whatever reads it (the guard, a checkpoint): the conversion spends
  // f, so the forces are evaluated again, at the same positions (the ghosts' too: nothing drifted since the
  // step's evaluation), the same bits as the streams' (SpringKernel).
  auto expose = [&] {
    if (!streams) return;
    set_streams(false);
    forces.forces(x, v, f);
  };
  guard.on_read(expose);
  SolverHooks exposed = hooks;  // a stop's checkpoint reads the state
  if (hooks.checkpoint)
    exposed.checkpoint = [&](const SolverState& s) {
      expose();
      hooks.checkpoint(s);
    };
  // A kReduceEvery-th step's state is read by the signal check (a stop writes a checkpoint of the whole step) and
  // by the guard when it finds a check due there (growth, a non-finite value; the periodic full checks are known
  // ahead). The signal check's reduction is made before that step instead, and the guard, told that the step
  // drifted on, makes a check it finds due at the next step, which then ends at its whole state
  // (StepGuard::check_pending): so the step drifts on into the next one's half kick like any other unless a stop
  // was asked for or a full check is due (then it ends at the whole step, as before). A signal that arrives after
  // the check is seen at the next one, kReduceEvery steps on.
  const long full_every = guard.enabled() ? guard.every() : 0;
  while (state.step < total) {
    const long next = state.step + 1;
    const bool ahead = next % kReduceEvery == 0 && next < total;
    bool stop_ahead = false;
    if (ahead) {
      int mine = stop_requested ? 1 : 0, any = 0;
      MPI_Allreduce(&mine, &any, 1, MPI_INT, MPI_MAX, model.comm);
      stop_ahead = any != 0;
    }
    const bool next_unobserved = (ahead ? unread(next) && !stop_ahead : unobserved(next)) && !guard.check_pending() &&
                                 !(full_every > 0 && next % full_every == 0);
    const bool fused = fuse && streams_read(state.step + 1);
    // (the layout the last step left: a fused step that ended at an observed state kept the streams)
    if (!drifted) {
      if (streams) {
        const std::size_t sl = local, sn = n;
        kick_drift_streams(n, dt, m, f, f + sl, f + 2 * sl, v, v + sn, v + 2 * sn, x, x + sl, x + 2 * sl);
      } else {
        kick_drift(n, dt, m, f, v, x);
      }
    }
    set_streams(fused);
    if (!streams) state.x.update_ghosts();
    else if (stream_ghosts) stream_ghosts->update(x, local);
    forces.set_time(state.time + dt);
    double kinetic = 0;
    if (fused) {
      const std::size_t sl = local, sn = n;
      FusedStreams step{dt, m, {{f, f + sl, f + 2 * sl}, {v, v + sn, v + 2 * sn}, {x, x + sl, x + 2 * sl}}, 0.0,
                        guard.enabled(), next_unobserved};
      ReadAhead ahead;  // what the kicks read besides f (x: the kernel read it; the types: 1 byte a row)
      if (next_unobserved && types) step.types = types;
      ahead.rows[0] = v, ahead.rows[1] = v + sn, ahead.rows[2] = v + 2 * sn, ahead.rows[3] = m;
      ahead.streams = step.types ? 3 : 4, ahead.end = n;
      if (ring_rows && next_unobserved) {
        double* r = ring.data();
        step.at.f[0] = r, step.at.f[1] = r + ring_rows, step.at.f[2] = r + 2 * ring_rows;
        step.ring = ring_rows;
        forces.kernel().forces_ring(x, r, sl, fused_rows_streams, &step, &ahead);
      } else {
        forces.kernel().forces_streams(x, f, sl, fused_rows_streams, &step, &ahead);
      }
      kinetic = step.kinetic;
      drifted = next_unobserved;
    } else {
      if (history) forces.begin_step(dt);  // viscoelastic history: this step's update, committed at its end
      forces.forces(x, v, f);
      if (history) forces.commit_step(x);
      drifted = next_unobserved;
      if (drifted) {
        kinetic = kick_kick_drift(n, dt, m, f, v, x);
      } else {
        // A step whose state may be read (a checkpoint among them): keep the half-step velocities the forces
        // read.
        if (v_half) std::copy(v, v + 3 * n, v_half);
        kinetic = kick(n, dt, m, f, v);
      }
    }
    ++state.step;
    state.time += dt;
    // (a step whose state is written is whole: it did not drift on)
    guard.dynamic_step(0.5 * kinetic, /*whole=*/!drifted, /*observed=*/!unread(state.step));
    if (state.step == total) guard.full_check();
    progress.update(state.step, -1, 0, total);
    if (rows > 0 && (state.step % rows == 0 || state.step == total)) hooks.record(state);
    if (hooks.snapshot && scene.output.snapshot_every > 0 && state.step % scene.output.snapshot_every == 0 &&
        state.step < total)
      hooks.snapshot(state);
    // (after a check ahead: its reduction again only when it said stop, a flag no rank clears, so every rank
    // stops; else the checkpoint cadence alone)
    const long signal_every = ahead && !stop_ahead ? 0 : kReduceEvery;
    if (state.step < total && step_boundary(scene, model, state, exposed, signal_every)) {
      report.interrupted = true;
      break;
    }
  }
  // Only a stop at a guard's step can leave the streams on (every other step that ends the loop is read, so
  // interlaced): that step ended at the whole step, nothing drifted since its forces.
  expose();
  guard.on_read(nullptr);
  report.iterations = state.step;
  report.guard_checks = guard.checks();
  report.guard_seconds = guard.seconds();
  report.converged = !report.interrupted;
  report.energy_final = leapfrog_energy(model, forces, state, dt);
  return report;
}

TISSUE_SOLVER(dynamic, {"dynamic", solve_dynamic, "velocity Verlet in time (explicit)", /*equilibrium=*/false,
                        /*newton=*/false, /*explicit_steps=*/true, /*integrates_time=*/true,
                        /*settles_on_obstacles=*/false, /*time_line=*/true});

}  // namespace tissue
