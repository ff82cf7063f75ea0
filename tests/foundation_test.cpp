// The foundation, end to end in process: scene text -> body -> partition -> calibration -> solve -> measure,
// checked against closed forms, conservation laws and the same run on one rank (MPI_COMM_SELF, computed on
// every rank as the reference). Run at 1, 2 and 3 ranks.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <cmath>
#include <functional>

#include "tests/pipeline.hpp"
#include "io/scene.hpp"
#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "src/calibration/calibration.hpp"
#include "src/measure/measure.hpp"
#include "src/model/body.hpp"
#include "src/solvers/solver.hpp"
#include "tests/whole_body.hpp"

using namespace tissue;
using tissue::test_pipeline::RunResult;
using tissue::test_pipeline::run;

namespace {


const char* tension = R"(
title = "tension"
[body]
molecules = [4, 5, 6]
spacing = [0.1, 0.12, 0.09]
topology = "rectangular"
youngs_modulus = 1.0e5
density = 1000.0
[calibration]
method = "linear"
[[fix]]
face = "z+"
[[load]]
face = "z-"
force = [0.0, 0.0, -20.0]
[solver]
kind = "relaxation"
tolerance = 1e-12
)";

}  // namespace

// Rectangular topology with the linear k: every column of springs along the load is exactly E A_col / l0, so
// Eq. 3 must give E back (to the solver tolerance), and the lateral faces must not move (Poisson ratio 0).
TEST(Foundation, RectangularLinearMeasuresE) {
  for (const char* kind : {"relaxation", "static"}) {
    auto r = run(tension, PETSC_COMM_WORLD, {std::string("solver.kind=") + kind});
    ASSERT_TRUE(r->report.converged) << kind;
    ASSERT_TRUE(r->measured.youngs_modulus.has_value());
    EXPECT_NEAR(*r->measured.youngs_modulus / 1.0e5, 1.0, 1e-6) << kind;
    // The closed form of the elongation: F l0 / (E A).
    const double l0 = 5 * 0.09, A = 3 * 0.1 * 4 * 0.12;
    EXPECT_NEAR(*r->measured.elongation / (20.0 * l0 / (1.0e5 * A)), 1.0, 1e-6) << kind;
    ASSERT_TRUE(r->measured.poisson_ratio.has_value());
    EXPECT_NEAR(*r->measured.poisson_ratio, 0.0, 1e-6) << kind;  // static: mechanisms free in x, y
  }
}

// The same scene on this communicator and on one rank: every molecule's final position agrees to 1e-10.
TEST(Foundation, SameAnswerOnAnyRankCount) {
  for (const char* kind : {"static", "relaxation"}) {
    std::vector<std::string> set = {std::string("solver.kind=") + kind, "body.topology=face-diagonals",
                                    "body.molecules=[5,4,7]"};
    // The displacement error is about the condition number times the residual: ask for a residual that puts
    // both runs well inside 1e-10 of each other (Newton gets there in one more iteration).
    set.push_back(std::string(kind) == "static" ? "solver.tolerance=1e-12" : "solver.tolerance=1e-11");
    auto parallel = run(tension, PETSC_COMM_WORLD, set);
    auto serial = run(tension, MPI_COMM_SELF, set);
    ASSERT_TRUE(parallel->report.converged && serial->report.converged) << kind;
    const double* xp = parallel->state->x.array();
    const double* xs = serial->state->x.array();  // one rank: local index == original id
    double worst = 0;
    for (int i = 0; i < parallel->model.owned; ++i) {
      const std::int64_t g = parallel->model.id[i];
      for (int d = 0; d < 3; ++d)
        worst = std::max(worst, std::fabs(xp[3 * i + d] - xs[3 * g + d]) / std::max(1.0, std::fabs(xs[3 * g + d])));
    }
    EXPECT_LT(worst, 1e-10) << kind;
    EXPECT_NEAR(*parallel->measured.youngs_modulus, *serial->measured.youngs_modulus,
                1e-9 * *serial->measured.youngs_modulus);
  }
}

// Static and relaxation reach the same equilibrium (two independent solvers).
TEST(Foundation, StaticAgreesWithRelaxation) {
  std::vector<std::string> base = {"body.topology=body-diagonals", "solver.tolerance=1e-11"};
  auto a = base, b = base;
  a.push_back("solver.kind=static");
  b.push_back("solver.kind=relaxation");
  auto s = run(tension, PETSC_COMM_WORLD, a), r = run(tension, PETSC_COMM_WORLD, b);
  EXPECT_NEAR(*s->measured.elongation / *r->measured.elongation, 1.0, 1e-6);
}

// Newton's third law: the connection forces of any configuration sum to zero (to round-off), and at equilibrium
// the reactions at the held face balance the applied load.
TEST(Foundation, InternalForcesSumToZeroAndReactionsBalanceTheLoad) {
  auto r = run(tension, PETSC_COMM_WORLD, {"body.topology=tetrahedral", "solver.kind=static"}, true);
  const LocalModel& m = r->model;
  std::vector<double> f(3 * m.local);
  // A scrambled configuration first (a smooth field; ghosts get the same formula, so no exchange is needed).
  std::vector<double> x(m.rest);
  for (int i = 0; i < m.local; ++i)
    for (int d = 0; d < 3; ++d) x[3 * i + d] += 0.01 * std::sin(3.0 * m.rest[3 * i + (d + 1) % 3] + d);
  r->forces->connection_forces(x.data(), f.data());
  double local[4] = {0, 0, 0, 0}, total[4];
  for (int i = 0; i < m.owned; ++i)
    for (int d = 0; d < 3; ++d) local[d] += f[3 * i + d], local[3] += std::fabs(f[3 * i + d]);
  MPI_Allreduce(local, total, 4, MPI_DOUBLE, MPI_SUM, m.comm);
  for (int d = 0; d < 3; ++d) EXPECT_LT(std::fabs(total[d]), 1e-13 * total[3]);
  // Equilibrium: the connection forces at the held molecules (the reactions) sum to minus the applied load.
  r->forces->connection_forces(r->state->x.array(), f.data());
  double reaction[3] = {0, 0, 0}, sum[3];
  for (int i = 0; i < m.owned; ++i)
    if (r->forces->held()[3 * i + 2])
      for (int d = 0; d < 3; ++d) reaction[d] += f[3 * i + d];
  MPI_Allreduce(reaction, sum, 3, MPI_DOUBLE, MPI_SUM, m.comm);
  EXPECT_NEAR(sum[2], -20.0, 1e-8 * 20.0);  // the held face is pulled down by the body: it holds -F
  EXPECT_NEAR(sum[0], 0.0, 1e-8 * 20.0);
}

// The residual's round-off floor includes the positions' own (eps R at magnitude R): a slender beam 1 km from the
// origin (its positions resolved to 1e-13 m, its springs 0.25 m long) stalled below the springs-only floor, and
// Newton failed after 8 cut-backs. Here it converges, and its tip deflects as the same beam at the origin does.
TEST(Foundation, BeamFarFromTheOriginResolvesItsRoundOff) {
  const char* beam = R"(
title = "slender beam"
[body]
molecules = [41, 3, 3]
spacing = [0.25, 0.25, 0.25]
youngs_modulus = 1.0e3
density = 1000.0
[calibration]
method = "homogenized"
[[fix]]
face = "x-"
mode = "clamped"
[[load]]
face = "x+"
force = [0.0, 0.0, -1e-4]
[solver]
kind = "static"
)";
  auto tip = [&](double offset) {
    auto r = run(beam, PETSC_COMM_WORLD, {"body.offset=[" + std::to_string(offset) + ", 0.0, 0.0]"});
    EXPECT_TRUE(r->report.converged) << offset;
    double sums[2] = {0, 0};
    for (int i = 0; i < r->model.owned; ++i)
      if (std::fabs(r->model.rest[3 * i] - offset - 10.0) < 1e-9)
        sums[0] += r->state->x.array()[3 * i + 2] - r->model.rest[3 * i + 2], sums[1] += 1;
    MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
    return sums[0] / sums[1];
  };
  const double near = tip(0.0), far = tip(1000.0);
  PetscPrintf(PETSC_COMM_WORLD, "tip deflection at the origin %.9e, 1 km away %.9e\n", near, far);
  EXPECT_LT(near, 0.0);
  EXPECT_NEAR(far / near, 1.0, 1e-6);
}

// Undamped velocity Verlet from a perturbed start, no load: the total (leapfrog) energy is conserved to 1e-6
// over 10,000 steps at a tenth of the critical time step, and so is the momentum (the centre of mass drifts
// at the initial velocity, here zero).
TEST(Foundation, DynamicConservesEnergy) {
  const char* free_body = R"(
title = "free"
[body]
molecules = [5, 5, 5]
spacing = [0.01, 0.01, 0.01]
topology = "face-diagonals"
youngs_modulus = 1.0e6
density = 1100.0
[calibration]
method = "linear"
[solver]
kind = "dynamic"
steps = 10000
)";
  // The critical time step of this body, from the same Gershgorin bound the solver uses.
  auto probe = run(free_body, PETSC_COMM_WORLD, {}, false);
  const double dt = 0.1 * critical_time_step(*probe->forces);
  auto r = run(free_body, PETSC_COMM_WORLD, {"solver.time_step=" + std::to_string(dt)}, true, [](RunResult& run) {
    double* x = run.state->x.array();
    for (int i = 0; i < run.model.local; ++i)  // a smooth shear, 0.1% of the spacing
      x[3 * i + 0] += 1e-5 * std::sin(200.0 * run.model.rest[3 * i + 1]);
  });
  ASSERT_GT(r->report.energy_initial, 0.0);
  EXPECT_LT(std::fabs(r->report.energy_final - r->report.energy_initial) / r->report.energy_initial, 1e-6);
  EXPECT_EQ(r->state->step, 10000);
  Measurements start = measure(r->scene, r->model, r->test, r->model.rest.data(), nullptr);
  // The perturbation moves the centre of mass; from there it must stay put (zero momentum).
  auto moved = run(free_body, PETSC_COMM_WORLD, {"solver.steps=0"}, true, [](RunResult& run) {
    double* x = run.state->x.array();
    for (int i = 0; i < run.model.local; ++i) x[3 * i + 0] += 1e-5 * std::sin(200.0 * run.model.rest[3 * i + 1]);
  });
  for (int d = 0; d < 3; ++d)
    EXPECT_NEAR(r->measured.center_of_mass[d], moved->measured.center_of_mass[d], 1e-14);
  (void)start;
}

// The paper's Fig. 8 box: 10 x 10 x 10 face diagonals has exactly 1000 molecules and 7560 connections; the
// other topologies by counting: rectangular 3 n^2 (n-1), body-diagonals adds 4 (n-1)^3, tetrahedral has
// 3 n^2 (n-1) edges + 3 n (n-1)^2 face diagonals + (n-1)^3 body diagonals.
TEST(Foundation, TopologyCounts) {
  std::string scene = R"(
[body]
molecules = [10, 10, 10]
spacing = [0.111111, 0.111111, 0.0955556]
youngs_modulus = 1.0e5
[solver]
kind = "dynamic"
)";
  auto count = [&](const char* topology) {
    Scene s = parse_scene(scene, "count.toml", {std::string("body.topology=") + topology});
    return build_body(s).connections.size();
  };
  EXPECT_EQ(count("face-diagonals"), 7560u);
  EXPECT_EQ(count("rectangular"), 2700u);
  EXPECT_EQ(count("body-diagonals"), 7560u + 4 * 729u);
  EXPECT_EQ(count("tetrahedral"), 2700u + 2430u + 729u);
  Scene s = parse_scene(scene, "count.toml");
  Body b = build_body(s);
  EXPECT_EQ(b.molecules(), 1000);
  // Mass from density: the tributary volumes tile the hull of the molecule centres.
  double mass = 0;
  for (double m : b.mass) mass += m;
  EXPECT_NEAR(mass, 1000.0 * 9 * 0.111111 * 9 * 0.111111 * 9 * 0.0955556, 1e-9);
}
