// Viscoelastic connections and the quasi-static solver (issue 16) against closed forms, at 1, 2 and 3 ranks:
// step-strain relaxation (the reaction follows E A eps0 G(t), G(t) = 1 + sum gamma_i exp(-t/tau_i)), standard-
// linear-solid creep under a step force (error falling as dt^2), the static solve at the relaxed modulus and the
// first quasi-static step at the instantaneous one, loads and holds landing on their histories' breakpoints, and
// the same curves on every rank count (the one-rank run, MPI_COMM_SELF, as reference).
#include <gtest/gtest.h>
#include <petscsys.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "io/scene.hpp"
#include "src/driver/simulation.hpp"
#include "src/measure/measure.hpp"
#include "tests/pipeline.hpp"

using namespace tissue;

namespace {

struct Row {
  double time;
  std::vector<Vec3> reactions;
  double elongation;
};

// Runs a scene and records, after every time step, the time, the reactions and the elongation.
std::vector<Row> run_rows(const std::string& text, MPI_Comm comm, const std::vector<std::string>& set = {},
                          std::unique_ptr<Simulation>* keep = nullptr) {
  Scene scene = parse_scene(text, "test.toml", set);
  scene.output.progress = false;
  auto sim = std::make_unique<Simulation>(std::move(scene), comm);
  sim->build(read_mesh);
  sim->calibrate();
  sim->make_forces();
  std::vector<Row> rows;
  SolverHooks hooks;
  Simulation* s = sim.get();
  hooks.record = [&](const SolverState& state) {
    std::vector<double> scratch(3 * s->model().local);
    Row row{state.time, s->forces().reactions(state.x.array(), state.v.data(), scratch.data()), 0.0};
    Measurements m = measure(s->scene(), s->model(), s->test(), state.x.array(), state.v.data());
    row.elongation = m.elongation ? *m.elongation : NAN;
    rows.push_back(row);
  };
  sim->solve(hooks);
  if (sim->failed()) throw std::runtime_error(sim->failure());
  sim->measure();
  if (keep) *keep = std::move(sim);
  return rows;
}

// A 3 x 3 x 5 bar, rectangular springs (nu = 0: a uniform stretch, no lateral stress), the bottom clamped and the
// top clamped and pulled up by eps0 * l0 at t = 0 and held.
const char* relaxation = R"(
title = "step-strain relaxation"
[body]
molecules = [3, 3, 5]
size = [0.02, 0.02, 0.04]
topology = "rectangular"
youngs_modulus = 1.0e5
[body.viscoelastic]
gamma = [1.5, 0.8]
tau = [0.5, 5.0]
[calibration]
method = "linear"
[[fix]]
face = "z-"
[[fix]]
face = "z+"
displacement = [0.0, 0.0, 4.0e-6]
[solver]
kind = "quasi-static"
time_step = 0.25
end_time = 10.0
)";

// The same bar, face diagonals on rollers, under a step force on its top: creep.
const char* creep = R"(
title = "creep"
[body]
molecules = [3, 3, 4]
size = [0.02, 0.02, 0.03]
topology = "face-diagonals"
youngs_modulus = 1.0e5
[body.viscoelastic]
gamma = [2.0]
tau = [1.0]
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
mode = "roller"
[[load]]
face = "z+"
force = [0.0, 0.0, 4.0e-5]
[solver]
kind = "quasi-static"
time_step = 0.2
end_time = 2.0
tolerance = 1e-8
)";

double G(double t) { return 1.0 + 1.5 * std::exp(-t / 0.5) + 0.8 * std::exp(-t / 5.0); }

}  // namespace

// Step strain: the reaction of the pulled face is E A eps0 G(t) at every step (the elastic reaction at the same
// strain times the relaxation function), to 1e-9 relative; the first row is t = 0 at the instantaneous modulus.
TEST(Viscoelastic, StepStrainReactionFollowsTheRelaxationFunction) {
  const std::vector<Row> rows = run_rows(relaxation, PETSC_COMM_WORLD);
  const std::vector<Row> elastic = run_rows(relaxation, PETSC_COMM_WORLD, {"solver.end_time=0.0",
                                                                         "body.viscoelastic.gamma=[0.0,0.0]"});
  ASSERT_EQ(rows.size(), 41u);  // t = 0, then 40 steps of 0.25 s
  ASSERT_EQ(elastic.size(), 1u);
  const double E = 1.0e5, A = 0.02 * 0.02, eps0 = 4.0e-6 / 0.04;
  const double reference = elastic[0].reactions[1][2];
  EXPECT_NEAR(reference, E * A * eps0, 1e-6 * E * A * eps0) << "the elastic reaction is E A eps0";
  EXPECT_EQ(rows[0].time, 0.0);
  double worst = 0;
  for (const Row& r : rows) {
    worst = std::max(worst, std::fabs(r.reactions[1][2] - reference * G(r.time)) / std::fabs(reference));
    // The two holds carry the same force, opposite.
    EXPECT_NEAR(r.reactions[0][2], -r.reactions[1][2], 1e-9 * std::fabs(reference));
  }
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) std::printf("relaxation: largest |R(t) - R_elastic G(t)| / R_elastic %.3e\n", worst);
  EXPECT_LT(worst, 1e-9) << "reaction / (E A eps0) against G(t)";
  EXPECT_NEAR(rows.back().time, 10.0, 1e-12);
}

// Standard linear solid under a step force: eps(t) = (sigma0/E)[1 - gamma/(1+gamma) exp(-t/(tau(1+gamma)))] with
// sigma0/E the static (relaxed) elongation; at t = 0 the instantaneous one, 1/(1+gamma) of it. The time error
// falls as dt^2 (the exact exponential update is exact only for a force linear within the step).
TEST(Viscoelastic, CreepOfTheStandardLinearSolidConvergesAsDtSquared) {
  const double gamma = 2.0, tau = 1.0;
  auto relaxed = tissue::test_pipeline::run(creep, PETSC_COMM_WORLD, {"solver.kind=\"static\""});
  const double e_inf = *relaxed->measured.elongation;
  auto closed = [&](double t) { return e_inf * (1.0 - gamma / (1.0 + gamma) * std::exp(-t / (tau * (1.0 + gamma)))); };
  double error[2];
  for (int level = 0; level < 2; ++level) {
    const double dt = level == 0 ? 0.2 : 0.1;
    const std::vector<Row> rows = run_rows(creep, PETSC_COMM_WORLD, {"solver.time_step=" + std::to_string(dt)});
    ASSERT_EQ(rows.size(), static_cast<std::size_t>(std::lround(2.0 / dt)) + 1);
    // The first step: the instantaneous modulus E (1 + gamma), to the lattice's geometric nonlinearity (strains
    // of 1e-6 here).
    EXPECT_NEAR(rows[0].elongation, e_inf / (1.0 + gamma), 1e-6 * e_inf);
    error[level] = 0;
    for (const Row& r : rows) error[level] = std::max(error[level], std::fabs(r.elongation - closed(r.time)) / e_inf);
  }
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0) std::printf("creep: largest error / eps_inf %.3e (dt 0.2), %.3e (dt 0.1)\n", error[0], error[1]);
  EXPECT_LT(error[0], 2e-3);
  const double order = std::log2(error[0] / error[1]);
  EXPECT_GT(order, 1.9) << "errors " << error[0] << ", " << error[1];
  EXPECT_LT(order, 2.1) << "errors " << error[0] << ", " << error[1];
}

// A static solve of a scene with a Prony table is the elastic solve (the relaxed equilibrium), bit for bit.
TEST(Viscoelastic, StaticSolveIsTheRelaxedElasticSolve) {
  auto with = tissue::test_pipeline::run(creep, PETSC_COMM_WORLD, {"solver.kind=\"static\""});
  auto without = tissue::test_pipeline::run(creep, PETSC_COMM_WORLD,
                                            {"solver.kind=\"static\"", "body.viscoelastic.gamma=[0.0]"});
  EXPECT_EQ(*with->measured.elongation, *without->measured.elongation);
}

// A ramp-and-hold load history lands on its breakpoints (0.35 s is not a multiple of the step), and the applied
// force follows the factor; the curve is the one-rank run's on every rank count.
TEST(Viscoelastic, RampAndHoldLandsOnBreakpointsOnEveryRankCount) {
  const std::vector<std::string> set = {"load.0.history=[[0.0,0.0],[0.35,1.0],[1.0,1.0]]", "solver.end_time=1.0"};
  const std::vector<Row> rows = run_rows(creep, PETSC_COMM_WORLD, set);
  const std::vector<Row> one = run_rows(creep, MPI_COMM_SELF, set);
  ASSERT_EQ(rows.size(), one.size());
  bool landed = false;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    landed = landed || rows[i].time == 0.35;
    EXPECT_EQ(rows[i].time, one[i].time);
    EXPECT_NEAR(rows[i].elongation, one[i].elongation, 1e-10 * std::fabs(one.back().elongation));
  }
  EXPECT_TRUE(landed);
  EXPECT_EQ(rows[0].elongation, 0.0);  // factor 0 at t = 0: nothing happens
  // Equilibrium: the roller's reaction balances the applied force at every step, to the solver's tolerance
  // (1e-8 of the applied force: the unbalanced force on the free molecules is what is left over).
  for (const Row& r : rows) {
    const double applied = 4.0e-5 * history_factor({{0.0, 0.0}, {0.35, 1.0}, {1.0, 1.0}}, r.time);
    EXPECT_NEAR(r.reactions[0][2], -applied, 1e-8 * 4.0e-5);
  }
}

// Dynamic runs carry the history: the critical time step follows the instantaneous modulus E (1 + sum gamma)
// (the Gershgorin bound scales by exactly 1 / sqrt(1 + sum gamma)), and a free vibration loses energy (the Prony
// terms dissipate) where the elastic one keeps it.
TEST(Viscoelastic, DynamicRunsUseTheInstantaneousModulusAndDissipate) {
  // tau = 1 ms, about the period of the bar's vibration: strong damping within the run's 40 ms.
  const std::vector<std::string> dynamic = {"solver.kind=\"dynamic\"", "solver.time_step=1e-4",
                                            "body.viscoelastic.tau=[1e-3]"};
  std::string text = creep;
  text.replace(text.find("end_time = 2.0"), 14, "steps = 400");
  std::vector<std::string> elastic = dynamic;
  elastic.push_back("body.viscoelastic.gamma=[0.0]");
  auto with = tissue::test_pipeline::run(text, PETSC_COMM_WORLD, dynamic);
  auto without = tissue::test_pipeline::run(text, PETSC_COMM_WORLD, elastic);
  EXPECT_NEAR(with->sim->critical_time_step() * std::sqrt(1.0 + 2.0), without->sim->critical_time_step(),
              1e-12 * without->sim->critical_time_step());
  // The leapfrog energy (springs, kinetic, minus the load's work; the history's stored energy is not in it) is
  // conserved by the elastic run and falls with the history. Scale: the load's work at the static elongation,
  // F e_inf = 4e-5 N x 3e-8 m.
  const double scale = 4.0e-5 * 3.0e-8;
  const double elastic_drift = std::fabs(without->report.energy_final - without->report.energy_initial);
  const double lost = with->report.energy_initial - with->report.energy_final;
  EXPECT_LT(elastic_drift, 1e-6 * scale);
  EXPECT_GT(lost, 0.05 * scale);
}

// A sinusoidal strain (a history of 100 points a period, one Prony term, omega tau = 1): once the start has died
// out, the loop of reaction against displacement encloses pi E'' eps_a^2 V, E'' = E gamma w tau / (1 + w^2 tau^2)
// (the work dissipated per cycle). The bar has face diagonals (the rectangular one buckles in compression) and
// clamped ends, so its elastic stiffness K is measured (an elastic step) rather than E A / l0: the loop is
// pi (E''/E) K d_a^2 by the correspondence principle. The piecewise linear history and the trapezoid rule cost
// O(dt^2), the strain of 1e-4 its geometric nonlinearity.
TEST(Viscoelastic, HysteresisLoopAreaIsPiLossModulusStrainSquared) {
  const double pi = std::acos(-1.0), omega = 1.0, period = 2.0 * pi / omega, amplitude = 4.0e-6;
  const int per_period = 100, periods = 3;  // the start is gone (exp(-4 pi)) before the last period
  std::string history = "fix.1.history=[";
  std::vector<double> times;
  for (int i = 0; i <= per_period * periods; ++i) {
    const double t = period * i / per_period;
    times.push_back(t);
    char point[80];
    std::snprintf(point, sizeof point, "%s[%.17g,%.17g]", i ? "," : "", t, std::sin(omega * t));
    history += point;
  }
  history += "]";
  auto number = [](double x) {
    char text[40];
    std::snprintf(text, sizeof text, "%.17g", x);
    return std::string(text);
  };
  const std::vector<std::string> set = {history, "body.viscoelastic.gamma=[1.0]", "body.viscoelastic.tau=[1.0]",
                                        "solver.time_step=1.0", "solver.end_time=" + number(times.back())};
  const std::vector<std::string> bar = {"body.topology=\"face-diagonals\"", "calibration.method=\"homogenized\""};
  std::vector<std::string> cyclic = bar, elastic = bar;
  cyclic.insert(cyclic.end(), set.begin(), set.end());
  elastic.insert(elastic.end(), {"body.viscoelastic.gamma=[0.0,0.0]", "solver.end_time=0.0"});
  const std::vector<Row> rows = run_rows(relaxation, PETSC_COMM_WORLD, cyclic);
  const double K = run_rows(relaxation, PETSC_COMM_WORLD, elastic)[0].reactions[1][2] / amplitude;
  ASSERT_EQ(rows.size(), times.size());  // every breakpoint landed on, none skipped
  double area = 0;
  for (std::size_t i = rows.size() - per_period; i < rows.size(); ++i) {
    const double d0 = amplitude * std::sin(omega * rows[i - 1].time), d1 = amplitude * std::sin(omega * rows[i].time);
    area += 0.5 * (rows[i - 1].reactions[1][2] + rows[i].reactions[1][2]) * (d1 - d0);
  }
  const double loss_over_E = 1.0 * omega * 1.0 / (1.0 + omega * omega);  // gamma w tau / (1 + w^2 tau^2)
  const double expected = pi * loss_over_E * K * amplitude * amplitude;
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0)
    std::printf("hysteresis: loop area %.9e J, pi (E''/E) K d_a^2 %.9e J, relative error %.2e\n", area, expected,
                area / expected - 1.0);
  EXPECT_NEAR(area, expected, 2e-3 * expected);
}
