// Physics terms as the scene lists them (src/physics/): gravity, viscous friction, cyclic loads, obstacles and
// molecule-molecule contact, several bodies. Checked against closed forms (free fall, terminal velocity), force
// balance at equilibrium (contact force against the load or the weight), and the same run on one rank
// (MPI_COMM_SELF, computed on every rank as the reference). Run at 1, 2 and 3 ranks.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <petscsys.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "tests/pipeline.hpp"
#include "io/scene.hpp"
#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "src/calibration/calibration.hpp"
#include "src/measure/measure.hpp"
#include "src/model/body.hpp"
#include "src/solvers/guards.hpp"
#include "src/solvers/molecule_report.hpp"
#include "src/solvers/solver.hpp"

using namespace tissue;
using tissue::test_pipeline::RunResult;
using tissue::test_pipeline::gather_positions;
using tissue::test_pipeline::run;

namespace {

double max_difference(const std::vector<double>& a, const std::vector<double>& b) {
  double worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, std::fabs(a[i] - b[i]));
  return worst;
}

const char* falling = R"(
title = "free fall"
[body]
molecules = [3, 4, 3]
spacing = [0.1, 0.1, 0.1]
topology = "face-diagonals"
youngs_modulus = 1.0e4
density = 1000.0
[physics]
gravity = [0.0, 0.0, -9.81]
[solver]
kind = "dynamic"
time_step = 1e-3
steps = 10000
)";

}  // namespace

// Absent terms are not built: a scene without [physics] or obstacles has a force model of connections and loads.
TEST(Physics, AbsentTermsAreNotBuilt) {
  auto r = run(falling, PETSC_COMM_WORLD, {}, false);
  EXPECT_EQ(r->forces->term_names(), std::vector<std::string>{"gravity"});
  const std::string text = R"(
[body]
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1e4
[[fix]]
face = "z-"
)";
  auto q = run(text, PETSC_COMM_WORLD, {}, false);
  EXPECT_TRUE(q->forces->term_names().empty());
  EXPECT_FALSE(q->measured.contact_force.has_value());
}

// Velocity Verlet is exact under a constant force: every molecule falls g t^2 / 2, at every rank count.
TEST(Physics, FreeFallFollowsGTSquaredOverTwo) {
  auto r = run(falling, PETSC_COMM_WORLD);
  ASSERT_EQ(r->state->step, 10000);
  const double t = r->state->time, drop = 0.5 * 9.81 * t * t;
  EXPECT_NEAR(t, 10.0, 1e-9);
  double worst = 0, worst_lateral = 0, worst_v = 0;
  for (int i = 0; i < r->model.owned; ++i) {
    const double* x = r->state->x.array() + 3 * i;
    const double* x0 = r->model.rest.data() + 3 * i;
    worst = std::max(worst, std::fabs((x0[2] - x[2]) - drop) / drop);
    worst_lateral = std::max({worst_lateral, std::fabs(x[0] - x0[0]), std::fabs(x[1] - x0[1])});
    worst_v = std::max(worst_v, std::fabs(r->state->v[3 * i + 2] + 9.81 * t) / (9.81 * t));
  }
  double all[3], mine[3] = {worst, worst_lateral, worst_v};
  MPI_Allreduce(mine, all, 3, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_LT(all[0], 1e-9) << "relative error of the drop";
  EXPECT_LT(all[1], 1e-9) << "lateral drift (m)";
  EXPECT_LT(all[2], 1e-9) << "relative error of the velocity";
  EXPECT_NEAR(r->measured.center_of_mass[2], 0.1 - drop, 1e-9 * drop);
}

// Viscous friction: a falling body reaches the terminal velocity M g / (N c) (the same friction c on each of
// its N molecules, whatever their masses: the springs make it fall as one).
TEST(Physics, ViscousFrictionGivesTerminalVelocity) {
  auto r = run(falling, PETSC_COMM_WORLD, {"physics.viscosity=0.5", "solver.steps=20000", "solver.time_step=2e-3"});
  // the springs couple molecules of different mass: the body falls as one at the mean terminal velocity
  const double mean_terminal = r->measured.mass * 9.81 / (0.5 * r->model.global_molecules);
  double vz = 0, m = 0;
  for (int i = 0; i < r->model.owned; ++i) vz += r->model.mass[i] * r->state->v[3 * i + 2], m += r->model.mass[i];
  double sums[2] = {vz, m}, total[2];
  MPI_Allreduce(sums, total, 2, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_NEAR(-total[0] / total[1], mean_terminal, 1e-6 * mean_terminal);
}

namespace {
// A pad resting on a plane under gravity (relaxation: the plane holds it, no [[fix]]).
const char* resting = R"(
title = "resting pad"
[body]
molecules = [5, 4, 3]
spacing = [0.01, 0.01, 0.01]
topology = "face-diagonals"
material = "cartilage"
[physics]
gravity = [0.0, 0.0, -9.81]
[[obstacle]]
kind = "plane"
point = [0.0, 0.0, -0.005]
normal = [0.0, 0.0, 1.0]
[solver]
kind = "relaxation"
tolerance = 1e-9   # stiff cartilage under its small weight: round-off floors the residual near 5e-11
)";

// A pad pushed by a face load up into a rigid spherical indenter centred above it.
const char* indented = R"(
title = "indented pad"
[body]
molecules = [7, 7, 4]
spacing = [0.002, 0.002, 0.002]
topology = "face-diagonals"
material = "cartilage"
[[load]]
face = "z-"
force = [0.0, 0.0, 2.0]
[[obstacle]]
kind = "sphere"
center = [0.006, 0.006, 0.012]
radius = 0.005
[solver]
kind = "relaxation"
tolerance = 1e-11
)";

// The same indenter pressed into a pad clamped below: static (Newton with the obstacle's tangent).
const char* clamped = R"(
title = "clamped pad, indenter pressed in"
[body]
molecules = [7, 7, 4]
spacing = [0.002, 0.002, 0.002]
topology = "face-diagonals"
material = "cartilage"
[[fix]]
face = "z-"
[[obstacle]]
kind = "sphere"
center = [0.006, 0.006, 0.0105]
radius = 0.005
[solver]
kind = "static"
tolerance = 1e-10
)";

double norm(const Vec3& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

// The sum of the connection forces on held components: the reactions of the fixes.
Vec3 reactions(const RunResult& r) {
  std::vector<double> f(3 * r.model.local);
  r.forces->connection_forces(r.state->x.array(), f.data());
  double mine[3] = {0, 0, 0}, all[3];
  for (int i = 0; i < r.model.owned; ++i)
    for (int d = 0; d < 3; ++d)
      if (r.forces->held()[3 * i + d]) mine[d] += f[3 * i + d];
  MPI_Allreduce(mine, all, 3, MPI_DOUBLE, MPI_SUM, r.model.comm);
  return {all[0], all[1], all[2]};
}
}  // namespace

// At rest on a plane, the plane carries the body's weight.
TEST(Physics, RestingBodyContactForceIsItsWeight) {
  auto r = run(resting, PETSC_COMM_WORLD);
  ASSERT_TRUE(r->report.converged);
  ASSERT_TRUE(r->measured.contact_force.has_value());
  const Vec3 c = *r->measured.contact_force;
  const double weight = r->measured.mass * 9.81;
  EXPECT_NEAR(c[2], weight, 1e-6 * weight);
  EXPECT_NEAR(c[0], 0.0, 1e-6 * weight);
  EXPECT_NEAR(c[1], 0.0, 1e-6 * weight);
  auto self = run(resting, MPI_COMM_SELF);
  EXPECT_LT(max_difference(gather_positions(*r), gather_positions(*self)), 1e-10);
  EXPECT_NEAR(norm(*self->measured.contact_force), norm(c), 1e-9 * weight);
}

// A load pushes the pad into a fixed spherical indenter: at equilibrium the indenter's force balances the load.
TEST(Physics, IndenterBalancesTheLoad) {
  auto r = run(indented, PETSC_COMM_WORLD);
  ASSERT_TRUE(r->report.converged);
  const Vec3 c = *r->measured.contact_force;
  EXPECT_NEAR(c[2], -2.0, 1e-6 * 2.0);
  EXPECT_NEAR(c[0], 0.0, 1e-6 * 2.0);
  EXPECT_NEAR(c[1], 0.0, 1e-6 * 2.0);
  auto self = run(indented, MPI_COMM_SELF);
  EXPECT_LT(max_difference(gather_positions(*r), gather_positions(*self)), 1e-10);
}

// Static (Newton with k n n^T per active contact) and relaxation agree on an indented, clamped pad, and the
// indenter's force equals the fixed face's reactions.
TEST(Physics, IndenterStaticMatchesRelaxation) {
  auto s = run(clamped, PETSC_COMM_WORLD);
  ASSERT_TRUE(s->report.converged);
  auto x = run(clamped, PETSC_COMM_WORLD, {"solver.kind=relaxation", "solver.tolerance=1e-11"});
  ASSERT_TRUE(x->report.converged);
  const Vec3 c = *s->measured.contact_force, reaction = reactions(*s);
  EXPECT_LT(c[2], 0.0);
  for (int d = 0; d < 3; ++d) EXPECT_NEAR(reaction[d], c[d], 1e-6 * norm(c));
  for (int d = 0; d < 3; ++d) EXPECT_NEAR((*x->measured.contact_force)[d], c[d], 1e-6 * norm(c));
  EXPECT_LT(max_difference(gather_positions(*s), gather_positions(*x)), 1e-6 * 0.002);
  auto self = run(clamped, MPI_COMM_SELF);
  EXPECT_LT(max_difference(gather_positions(*s), gather_positions(*self)), 1e-10);
}

namespace {
// Two bodies in one scene: [[body]] tables, numbered body after body; fixes and loads name their body.
const char* two_bodies = R"(
title = "two bodies"
[[body]]
molecules = [3, 3, 4]
spacing = [0.1, 0.1, 0.1]
topology = "rectangular"
youngs_modulus = 1.0e5
[[body]]
molecules = [4, 3, 5]
spacing = [0.1, 0.12, 0.09]
topology = "rectangular"
youngs_modulus = 3.0e5
offset = [1.0, 0.0, 0.0]
[calibration]
method = "linear"
[[fix]]
face = "z+"
body = 1
[[fix]]
face = "z+"
[[load]]
face = "z-"
body = 1
force = [0.0, 0.0, -20.0]
[solver]
kind = "static"
tolerance = 1e-11
)";
}  // namespace

// Each body has its own topology, material and offset; Eq. 3 reads the body the load is on (exact for the
// rectangular topology with the linear k), and the unloaded body does not move.
TEST(Physics, SeveralBodiesEachWithItsOwnMaterial) {
  auto r = run(two_bodies, PETSC_COMM_WORLD);
  ASSERT_TRUE(r->report.converged);
  EXPECT_EQ(r->model.global_molecules, 36 + 60);
  EXPECT_EQ(r->scene.bodies.size(), 2u);
  ASSERT_TRUE(r->test.valid);
  EXPECT_EQ(r->test.body, 1);
  EXPECT_NEAR(r->test.cross_section, 0.3 * 0.24, 1e-12);
  EXPECT_NEAR(r->test.rest_length, 0.36, 1e-12);
  ASSERT_TRUE(r->measured.youngs_modulus.has_value());
  EXPECT_NEAR(*r->measured.youngs_modulus, 3.0e5, 1e-6 * 3.0e5);
  auto x = gather_positions(*r);
  Body body = scene_shape(r->scene);
  double still = 0;
  for (std::int64_t g = 0; g < 36; ++g) {
    Vec3 p = body.rest_position(g);
    for (int d = 0; d < 3; ++d) still = std::max(still, std::fabs(x[3 * g + d] - p[d]));
  }
  EXPECT_LT(still, 1e-13);  // round-off: lattice rest lengths come from the offsets, not the rounded positions
  EXPECT_NEAR(body.rest_position(36)[0], 1.0, 1e-15);
  auto self = run(two_bodies, MPI_COMM_SELF);
  EXPECT_LT(max_difference(x, gather_positions(*self)), 1e-10);
}

namespace {
// Two pads pressed together: the lower one clamped below, the upper one loaded from above onto it. The
// molecules' spheres (radius 1 mm) of the two facing layers touch at rest.
const char* pressed = R"(
title = "two pads pressed together"
[[body]]
molecules = [5, 4, 3]
spacing = [0.002, 0.002, 0.002]
topology = "face-diagonals"
material = "cartilage"
[[body]]
molecules = [5, 4, 3]
spacing = [0.002, 0.002, 0.002]
topology = "face-diagonals"
material = "cartilage"
youngs_modulus = 5e6
offset = [0.0, 0.0, 0.006]
[physics]
contact = true
[[fix]]
face = "z-"
[[load]]
face = "z+"
body = 1
force = [0.0, 0.0, -3.0]
[solver]
kind = "relaxation"
tolerance = 1e-10
)";
}  // namespace

// The contact force between the bodies carries the load across (distance-based halo at 2 and 3 ranks).
TEST(Physics, PadsPressedTogetherCarryTheLoad) {
  auto r = run(pressed, PETSC_COMM_WORLD);
  ASSERT_TRUE(r->report.converged);
  ASSERT_EQ(r->measured.body_contact_force.size(), 2u);
  const Vec3 on0 = r->measured.body_contact_force[0], on1 = r->measured.body_contact_force[1];
  EXPECT_NEAR(on1[2], 3.0, 1e-6 * 3.0);
  EXPECT_NEAR(on0[2], -3.0, 1e-6 * 3.0);
  for (int d = 0; d < 2; ++d) {
    EXPECT_NEAR(on1[d], 0.0, 1e-6 * 3.0);
    EXPECT_NEAR(on0[d], 0.0, 1e-6 * 3.0);
  }
  auto self = run(pressed, MPI_COMM_SELF);
  EXPECT_LT(max_difference(gather_positions(*r), gather_positions(*self)), 1e-10);
  EXPECT_NEAR(self->measured.body_contact_force[1][2], on1[2], 1e-9);
}

namespace {
// Springs alone, set in motion by a perturbed start: the dynamic solver then runs the fused step (the kicks and
// the drift inside the spring kernel's sweep, src/solvers/dynamic.cpp).
const char* springs_only = R"(
title = "springs only"
[body]
molecules = [7, 5, 6]
spacing = [0.1, 0.1, 0.1]
topology = "face-diagonals"
youngs_modulus = 1.0e4
density = 1000.0
[solver]
kind = "dynamic"
time_step = 2e-5
steps = 300
)";
// Large enough that the fused steps' forces go through the spring kernel's ring (SpringKernel::forces_ring): a
// window of about three planes' rows against 15,360 molecules.
const char* ring_molecules = "body.molecules=[24, 16, 40]";
void perturb(RunResult& r) {
  double* x = r.state->x.array();
  for (int i = 0; i < r.model.local; ++i)
    for (int d = 0; d < 3; ++d) x[3 * i + d] += 0.003 * std::sin(1.7 * static_cast<double>(r.model.id[i]) + d);
}
// The two runs' positions, velocities and forces equal bit for bit on every rank; the largest |v| over every rank
// (m/s), so a caller can check that the springs did move the molecules. Mismatches are counted, not asserted, so
// every rank reaches the reductions (a rank returning early would leave the others waiting in them).
void expect_same_state(RunResult& a, RunResult& b, double* max_speed) {
  double moved = 0;
  long differ = 0, first = -1;
  for (int j = 0; j < 3 * a.model.owned; ++j) {
    const bool same = a.state->x.array()[j] == b.state->x.array()[j] && a.state->v[j] == b.state->v[j] &&
                      a.state->f[j] == b.state->f[j];
    if (!same && differ++ == 0) first = j;
    moved = std::max(moved, std::fabs(a.state->v[j]));
  }
  EXPECT_EQ(differ, 0) << "first differing entry " << first;
  long all_differ = 0;
  MPI_Allreduce(&differ, &all_differ, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_EQ(all_differ, 0);
  MPI_Allreduce(&moved, max_speed, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
}
}  // namespace

// The fused step against the separate passes: a zero gravity is a term (so the step is not fused) that adds
// +0.0 to every force, which changes no bit. Positions and velocities equal bit for bit, at every rank count.
TEST(Physics, FusedStepEqualsSeparatePassesBitForBit) {
  auto fused = run(springs_only, PETSC_COMM_WORLD, {}, true, perturb);
  auto separate = run(springs_only, PETSC_COMM_WORLD, {"physics.gravity=[0.0, 0.0, 0.0]"}, true, perturb);
  ASSERT_TRUE(fused->forces->springs_only());
  ASSERT_FALSE(separate->forces->springs_only());
  ASSERT_EQ(fused->state->step, 300);
  ASSERT_EQ(separate->state->step, 300);
  double all = 0;
  expect_same_state(*fused, *separate, &all);
  // The guard's full checks (steps 128 and 256) read the state back from the streams mid-run: the same checks
  // and the same energies as the separate passes.
  EXPECT_EQ(fused->report.guard_checks, separate->report.guard_checks);
  EXPECT_GE(fused->report.guard_checks, 3);
  EXPECT_EQ(fused->report.energy_final, separate->report.energy_final);
  EXPECT_GT(all, 1e-3);  // the springs did move the molecules (m/s)
  // With the guards off the fused step skips the kinetic energy (nothing reads it): the same bits again.
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-tissue_guards", "false"), 0);
  auto unguarded = run(springs_only, PETSC_COMM_WORLD, {}, true, perturb);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-tissue_guards"), 0);
  for (int j = 0; j < 3 * fused->model.owned; ++j) {
    ASSERT_EQ(unguarded->state->x.array()[j], separate->state->x.array()[j]) << j;
    ASSERT_EQ(unguarded->state->v[j], separate->state->v[j]) << j;
  }
}

// history.csv's rows in a fused run read the state as the solver keeps it between steps, three streams
// (SolverState::x_streams), without turning it back into PETSc's interlaced blocks: measure() there gives the
// separate passes' numbers bit for bit (step, kinetic energy, centre of mass) at every row, every 10 steps, at
// every rank count; and the run itself is the same bits as without rows.
TEST(Physics, FusedRunsHistoryRowsReadTheStreams) {
  struct Rows {
    std::vector<double> values;
    int streamed = 0;
  };
  auto solve_with_rows = [](RunResult& r, Rows& rows) {
    SolverHooks hooks;
    hooks.record = [&](const SolverState& s) {
      const Measurements m = measure(r.scene, r.model, r.test, s.x.array(), s.v.data(), s.x_streams, s.v_streams);
      rows.values.push_back(static_cast<double>(s.step));
      rows.values.push_back(m.kinetic_energy);
      for (double c : m.center_of_mass) rows.values.push_back(c);
      rows.streamed += s.x_streams != 0;
    };
    r.sim->solve(hooks);
    ASSERT_NE(r.sim->outcome(), Simulation::Outcome::solver_failure) << r.sim->failure();
  };
  const std::vector<std::string> every = {ring_molecules, "output.history_every=10"};
  std::vector<std::string> zero_gravity = every;
  zero_gravity.push_back("physics.gravity=[0.0, 0.0, 0.0]");
  auto fused = run(springs_only, PETSC_COMM_WORLD, every, false, perturb);
  auto separate = run(springs_only, PETSC_COMM_WORLD, zero_gravity, false, perturb);
  Rows a, b;
  solve_with_rows(*fused, a);
  solve_with_rows(*separate, b);
  ASSERT_TRUE(fused->forces->springs_only());
  ASSERT_EQ(a.values.size(), 5u * 31);  // steps 0, 10, ..., 300
  ASSERT_EQ(a.values.size(), b.values.size());
  for (std::size_t j = 0; j < a.values.size(); ++j) EXPECT_EQ(a.values[j], b.values[j]) << "row " << j / 5;
  EXPECT_EQ(a.streamed, 29);  // every row but the first (before the streams) and the last (interlaced)
  EXPECT_EQ(b.streamed, 0);
  EXPECT_GT(a.values[5 * 15 + 1], 0.0);  // the springs moved the molecules
  double all = 0;
  auto plain = run(springs_only, PETSC_COMM_WORLD, {ring_molecules, "physics.gravity=[0.0, 0.0, 0.0]"}, true, perturb);
  expect_same_state(*fused, *plain, &all);
  EXPECT_GT(all, 1e-3);
}

// The fused steps with their forces in a ring of rows (the ring is reused every few planes: a row handed over too
// late or zeroed too early changes the bits) against the separate passes, guards on: equal bits at every rank
// count; the ring is in use on every rank, a quarter of the owned rows or less on one rank.
void fused_in_a_ring_equals_separate_passes(const char* molecules) {
  auto fused = run(springs_only, PETSC_COMM_WORLD, {molecules}, true, perturb);
  auto separate = run(springs_only, PETSC_COMM_WORLD, {molecules, "physics.gravity=[0.0, 0.0, 0.0]"}, true, perturb);
  ASSERT_TRUE(fused->forces->springs_only());
  int size = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  int rank = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  EXPECT_GT(fused->forces->kernel().ring_rows(), 0) << "rank " << rank << " of " << size;
  if (size == 1) EXPECT_LT(4 * fused->forces->kernel().ring_rows(), fused->model.owned);
  double all = 0;
  expect_same_state(*fused, *separate, &all);
  EXPECT_GT(all, 1e-3);
  EXPECT_EQ(fused->report.energy_final, separate->report.energy_final);
  // Guards off: the signal check is made a step ahead, and every kReduceEvery-th step drifts on in the ring too.
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-tissue_guards", "false"), 0);
  auto unguarded = run(springs_only, PETSC_COMM_WORLD, {molecules}, true, perturb);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-tissue_guards"), 0);
  expect_same_state(*unguarded, *separate, &all);
  EXPECT_EQ(unguarded->report.energy_final, separate->report.energy_final);
}

TEST(Physics, FusedStepInARingEqualsSeparatePassesBitForBit) { fused_in_a_ring_equals_separate_passes(ring_molecules); }

// A stop asked for (the signal handler's flag, on rank 0 only) in a run without guards, whose signal check is
// made before the kReduceEvery-th step: the run stops there at the whole step, every rank, with the state of the
// separate passes run for exactly that many steps (a step that drifted on would differ in every x and v).
TEST(Physics, UnguardedFusedRunStopsAtTheWholeStepOfItsSignalCheck) {
  int rank = 0;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  const std::string steps = "solver.steps=" + std::to_string(tissue::kReduceEvery);
  auto separate = run(springs_only, PETSC_COMM_WORLD, {ring_molecules, steps, "physics.gravity=[0.0, 0.0, 0.0]"},
                      true, perturb);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-tissue_guards", "false"), 0);
  if (rank == 0) tissue::stop_requested = 1;
  auto stopped = run(springs_only, PETSC_COMM_WORLD, {ring_molecules}, true, perturb);
  tissue::stop_requested = 0;
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-tissue_guards"), 0);
  EXPECT_TRUE(stopped->report.interrupted);
  ASSERT_EQ(stopped->state->step, tissue::kReduceEvery);
  double all = 0;
  expect_same_state(*stopped, *separate, &all);
  EXPECT_GT(all, 1e-6);
}

// The box longest along its rows (the fastest-varying axis): at 2 ranks the partition cuts the rows, and a stencil
// segment of one rank has a direction into the ghosts' rows (an offset of about the owned count), which once kept
// every owned row live there: no ring on that rank (this test failed so).
TEST(Physics, FusedStepInARingOnEveryRankWhenThePartitionCutsTheRows) {
  fused_in_a_ring_equals_separate_passes("body.molecules=[48, 12, 24]");
}

// The state a failed guarded run put back (its last good state, r.state->step) against an unguarded run of the
// scene `set` to that step from the same start: x and v equal bit for bit on every rank.
void expect_last_good_state_of_unguarded_run(const RunResult& r, std::vector<std::string> set,
                                             const std::function<void(RunResult&)>& start, const std::string& what) {
  const long good = r.state->step;
  auto steps = [](const std::string& s) { return s.rfind("solver.steps=", 0) == 0; };
  set.erase(std::remove_if(set.begin(), set.end(), steps), set.end());
  set.push_back("solver.steps=" + std::to_string(good));
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-tissue_guards", "false"), 0);
  auto reference = run(springs_only, PETSC_COMM_WORLD, set, /*do_solve=*/good > 0, start);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-tissue_guards"), 0);
  long differ = 0, all = 0;
  for (int j = 0; j < 3 * r.model.owned; ++j)
    differ += r.state->x.array()[j] != reference->state->x.array()[j] || r.state->v[j] != reference->state->v[j];
  MPI_Allreduce(&differ, &all, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_EQ(all, 0) << what;
}

// An unstable time step in a fused run with the guards on. Its kReduceEvery-th steps drift on into the next step's
// half kick, so a check one of them finds due (energy growth, a non-finite value) is made at the next step, whole
// (StepGuard::check_pending). The failure is caught at a check (a periodic full check, every 128 steps, or one step
// after a multiple of kReduceEvery); the kinetic energy's doublings on the way made checks that passed, the last one
// deferred (one step after a multiple of kReduceEvery), and the last good state it kept and put back is an unguarded
// run's of as many steps, bit for bit (at every rank count).
TEST(Physics, FusedRunCatchesGrowthAtTheStepAfterItsDriftedGuardStep) {
  auto probe = run(springs_only, PETSC_COMM_WORLD, {}, false);
  const double dt = 1.6 * probe->sim->critical_time_step();
  ASSERT_GT(dt, 0.0);
  const std::vector<std::string> unstable = {"solver.time_step=" + fmt::format("{:.17g}", dt),
                                             "solver.allow_unstable_time_step=true", "solver.steps=2000"};
  auto r = run(springs_only, PETSC_COMM_WORLD, unstable, false, perturb);
  ASSERT_TRUE(r->forces->springs_only());
  r->sim->solve(SolverHooks{});
  ASSERT_EQ(r->sim->outcome(), Simulation::Outcome::solver_failure);
  const std::string what = r->sim->failure();
  const std::size_t at = what.find(" at step ");
  ASSERT_NE(at, std::string::npos) << what;
  const long named = std::stol(what.substr(at + 9));
  EXPECT_TRUE(named % 128 == 0 || named % kReduceEvery == 1) << what;
  EXPECT_NE(what.find("last good state: step"), std::string::npos) << what;
  const long good = r->state->step;
  EXPECT_EQ(good % kReduceEvery, 1) << what;  // a check found due at a drifted step, made (and passed) at the next
  ASSERT_GT(good, 0);
  ASSERT_LT(good, named);
  expect_last_good_state_of_unguarded_run(*r, unstable, perturb, what);
}

// A non-finite state in a fused run with the guards on, found from the kinetic energy the drifting kicks sum on the
// streams: one molecule thrown at 1e300 m/s overflows its springs' lengths, and NaN forces spread from it. Every rank
// fails with the same message, which names the first non-finite molecule and the step of the first non-finite kinetic
// energy; the last good state put back is an unguarded run's of as many steps, bit for bit (1, 2 and 3 ranks: the
// failure found on the streams is turned back to PETSc's layout on every rank together).
TEST(Physics, FusedRunCatchesANonFiniteStateOnEveryRankAlike) {
  const std::vector<std::string> set = {ring_molecules, "solver.steps=300"};
  auto throw_one = [](RunResult& r) {
    perturb(r);
    for (int i = 0; i < r.model.owned; ++i)
      if (r.model.id[i] == 1234) r.state->v[3 * i + 2] = 1e300;
  };
  auto r = run(springs_only, PETSC_COMM_WORLD, set, false, throw_one);
  ASSERT_TRUE(r->forces->springs_only());
  r->sim->solve(SolverHooks{});
  ASSERT_EQ(r->sim->outcome(), Simulation::Outcome::solver_failure);
  const std::string what = r->sim->failure();
  EXPECT_NE(what.find("non-finite"), std::string::npos) << what;
  EXPECT_NE(what.find("first non-finite kinetic energy at step"), std::string::npos) << what;
  EXPECT_NE(what.find("molecule "), std::string::npos) << what;
  // the same text on every rank: its length and a hash, the smallest and largest over the ranks
  long mine[2] = {static_cast<long>(what.size()), static_cast<long>(std::hash<std::string>{}(what) >> 1)};
  long low[2], high[2];
  MPI_Allreduce(mine, low, 2, MPI_LONG, MPI_MIN, PETSC_COMM_WORLD);
  MPI_Allreduce(mine, high, 2, MPI_LONG, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_EQ(low[0], high[0]) << what;
  EXPECT_EQ(low[1], high[1]) << what;
  const std::size_t at = what.find(" at step ");
  ASSERT_NE(at, std::string::npos) << what;
  const long named = std::stol(what.substr(at + 9));
  // found mid-run by the kinetic energy the drifted kicks summed at a kReduceEvery-th step, checked at the next, whole
  EXPECT_EQ(named % kReduceEvery, 1) << what;
  ASSERT_LT(r->state->step, named) << what;
  expect_last_good_state_of_unguarded_run(*r, set, throw_one, what);
}

// The guards' connection pass on the spring kernel's segments (SpringKernel::energy_and_shortest) against the walk
// over every written connection it replaces: the energy to round-off (another order), the smallest length / rest
// length the same double, on every rank; a lattice with a stiffer region (two materials: the segments end where they
// meet), every topology, perturbed, the partition's ghosts at 2 and 3 ranks; and a squeezed spring inside a segment.
TEST(Physics, KernelEnergyAndShortestEqualWrittenConnectionsWalk) {
  // (manual stiffnesses: the segments run past the row ends, whose missing directions are masked)
  const std::string manual = "[calibration]\nmethod = \"manual\"\nstiffness = { edge = 100.0, face = 50.0 }\n";
  for (const char* topology : {"rectangular", "face-diagonals", "body-diagonals", "tetrahedral", "manual"}) {
    const bool by_hand = std::string(topology) == "manual";
    const std::string text = (by_hand ? manual : std::string()) + std::string(R"(
[body]
molecules = [9, 7, 11]
spacing = [0.1, 0.13, 0.07]
youngs_modulus = 1.0e5
density = 1100.0
topology = ")") + (by_hand ? "face-diagonals" : topology) + R"("
[[body.region]]
lo = [0.0, 0.0, 0.0]
hi = [0.45, 0.5, 0.4]
youngs_modulus = 3.0e6
density = 1900.0
[solver]
kind = "dynamic"
steps = 1
)";
    auto r = run(text, PETSC_COMM_WORLD, {}, false, perturb);
    const LocalModel& m = r->model;
    double* x = r->state->x.array();
    for (int squeeze = 0; squeeze < 2; ++squeeze) {
      if (squeeze)  // molecule 3 + 9 * (2 + 7 * 4) put next to its +x neighbour: one short spring
        for (int i = 0; i < m.local; ++i)
          if (m.id[i] == 3 + 9 * (2 + 7 * 4))
            for (int j = 0; j < m.local; ++j)
              if (m.id[j] == m.id[i] + 1)
                for (int d = 0; d < 3; ++d) x[3 * i + d] = x[3 * j + d] - (d == 0 ? 1e-5 : 0.0);
      double energy = 0, worst = std::numeric_limits<double>::infinity();
      m.for_each_written([&](int c, int a, int b) {
        const double length = length_of(x, a, b), stretch = length - m.l0(c), ratio = length / m.l0(c);
        energy += 0.5 * m.k(c) * stretch * stretch;
        if (ratio < worst) worst = ratio;
      });
      double fast_energy = 0, fast_worst = 0;
      r->forces->kernel().energy_and_shortest(x, &fast_energy, &fast_worst);
      EXPECT_NEAR(fast_energy, energy, 1e-12 * energy) << topology << " squeeze " << squeeze;
      EXPECT_EQ(fast_worst, worst) << topology << " squeeze " << squeeze;
      // The same pass over x as three streams (the dynamic solver's layout between steps, ghosts' rows included,
      // a stride of more than the local rows): the same doubles.
      const std::size_t stride = m.local + 5;
      std::vector<double> streams(3 * stride, std::numeric_limits<double>::quiet_NaN());
      for (int i = 0; i < m.local; ++i)
        for (int d = 0; d < 3; ++d) streams[d * stride + i] = x[3 * i + d];
      double stream_energy = 0, stream_worst = 0;
      r->forces->kernel().energy_and_shortest(streams.data(), &stream_energy, &stream_worst, stride);
      EXPECT_EQ(stream_energy, fast_energy) << topology << " squeeze " << squeeze;
      EXPECT_EQ(stream_worst, fast_worst) << topology << " squeeze " << squeeze;
      long structured = r->forces->kernel().structured_connections(), all = 0;
      double least = 0;
      MPI_Allreduce(&structured, &all, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
      MPI_Allreduce(&worst, &least, 1, MPI_DOUBLE, MPI_MIN, PETSC_COMM_WORLD);
      if (std::string(topology) == "face-diagonals") EXPECT_GT(all, 0);  // the segments' path ran (any ranks)
      if (squeeze) EXPECT_LT(least, 1e-3) << topology;  // the squeezed spring is the shortest
    }
  }
}

// The guard's connection-length check (StepGuard::check_lengths at a full check) names the shortest connection
// relative to its rest length, the first in connection order on a tie (the smallest id over the ranks): two
// connections squeezed to the same 2^-14 m (rest 0.1 m), against the check's plain loop over the connections
// (the reference here), at every rank count.
TEST(Physics, LengthCheckNamesTheFirstShortestConnection) {
  const char* text = R"(
[body]
molecules = [8, 6, 5]
spacing = [0.1, 0.1, 0.1]
topology = "face-diagonals"
youngs_modulus = 1.0e4
[solver]
kind = "dynamic"
time_step = 1e-5
steps = 1
)";
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  const LocalModel& m = r->model;
  double* x = r->state->x.array();
  // Molecules a and b (ids: x-neighbours a + 1, b + 1 in the box's order) put 2^-14 m from those neighbours, at
  // exactly representable positions, so both separations (and their ratios) are the same doubles.
  const std::int64_t a = 2 + 8 * (1 + 6 * 1), b = 4 + 8 * (3 + 6 * 2);
  const double at_a[3] = {1.0, 2.0, 3.0}, at_b[3] = {5.0, 6.0, 7.0}, gap = std::ldexp(1.0, -14);
  for (int i = 0; i < m.local; ++i)
    for (int d = 0; d < 3; ++d) {
      if (m.id[i] == a + 1) x[3 * i + d] = at_a[d];
      if (m.id[i] == a) x[3 * i + d] = at_a[d] - (d == 0 ? gap : 0.0);
      if (m.id[i] == b + 1) x[3 * i + d] = at_b[d];
      if (m.id[i] == b) x[3 * i + d] = at_b[d] - (d == 0 ? gap : 0.0);
    }
  // The reference: every connection written here in order, strictly shorter replaces, then the least ratio's
  // smallest id over the ranks.
  double worst = std::numeric_limits<double>::infinity();
  long long worst_id = -1, expected = 0;
  m.for_each_written([&](int c, int ea, int eb) {
    const double ratio = length_of(x, ea, eb) / m.l0(c);
    if (ratio < worst) worst = ratio, worst_id = m.connection_id(c);
  });
  double least = 0;
  MPI_Allreduce(&worst, &least, 1, MPI_DOUBLE, MPI_MIN, PETSC_COMM_WORLD);
  long long mine = worst == least ? worst_id : std::numeric_limits<long long>::max();
  MPI_Allreduce(&mine, &expected, 1, MPI_LONG_LONG, MPI_MIN, PETSC_COMM_WORLD);
  ASSERT_EQ(least, gap / 0.1);  // both squeezed connections, the same double
  ASSERT_LT(least, kCollapsedLengthRatio);
  StepGuard guard("dynamic", r->scene, m, *r->forces, *r->state);
  std::string what;
  try {
    guard.full_check();
  } catch (const SolverFailure& e) {
    what = e.what();
  }
  EXPECT_NE(what.find("connection " + std::to_string(expected) + " collapsed"), std::string::npos) << what;
}
