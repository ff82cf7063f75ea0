// Per-body calibration (Scene::calibrations, calibrate_scene in src/calibration/calibration.cpp): in a scene of
// several bodies each body is calibrated by its own method, and gets exactly what that method gives the body alone
// in a one-body scene: the same k per connection bit for bit, and the same elongation under the same load (to
// 1e-10, the solver's tolerance: the two bodies are solved as one system). Run at 1, 2 and 3 ranks.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <cmath>
#include <memory>

#include "tests/pipeline.hpp"
#include "io/scene.hpp"
#include "partition/local_model.hpp"
#include "partition/metis_partition.hpp"
#include "src/calibration/calibration.hpp"
#include "src/measure/measure.hpp"
#include "src/model/body.hpp"
#include "src/solvers/solver.hpp"

using namespace tissue;
using tissue::test_pipeline::RunResult;
using tissue::test_pipeline::gather_positions;
using tissue::test_pipeline::run;

namespace {

// Every connection's k by global connection id, on every rank.
std::vector<double> gather_stiffness(const LocalModel& m) {
  std::vector<double> mine(m.global_connections, 0.0), all(mine.size());
  for (int c : m.written_here()) mine[m.connection_id(c)] = m.k(c);
  MPI_Allreduce(mine.data(), all.data(), static_cast<int>(mine.size()), MPI_DOUBLE, MPI_SUM, m.comm);
  return all;
}

// The body's elongation along z: mean z-displacement of its z+ face minus that of its z- face.
double elongation(const RunResult& r, int b) {
  const auto x = gather_positions(r);
  Body body = scene_shape(r.scene);
  const BoxGeometry& g = body.body(b);
  double sum[2] = {0, 0};
  long count[2] = {0, 0};
  for (std::int64_t id = g.first; id < g.first + g.molecules(); ++id)
    for (int side = 0; side < 2; ++side)
      if (g.on_face(id, 2, side)) sum[side] += x[3 * id + 2] - g.rest_position(id)[2], ++count[side];
  return sum[1] / count[1] - sum[0] / count[0];
}

// Body A: face diagonals, homogenized (its own inline table), roller support: E exact. Body B: rectangular, the
// top-level [calibration] (linear), clamped: E exact too. The loads stretch each by about 1e-5.
const std::string body_a = R"(
molecules = [4, 4, 5]
spacing = [0.1, 0.1, 0.1]
topology = "face-diagonals"
youngs_modulus = 1.0e5
calibration = { method = "homogenized" }
)";
const std::string body_b = R"(
molecules = [3, 4, 5]
spacing = [0.1, 0.12, 0.09]
topology = "rectangular"
youngs_modulus = 3.0e5
offset = [1.0, 0.0, 0.0]
)";
const double force_a = 1.0e5 * 0.3 * 0.3 * 1e-5, force_b = 3.0e5 * 0.2 * 0.36 * 1e-5;
const std::string common = R"(
[calibration]
method = "linear"
[solver]
kind = "static"
tolerance = 1e-12
)";
std::string holds(int body, const char* mode, double force) {
  return "[[fix]]\nface = \"z+\"\nmode = \"" + std::string(mode) + "\"\nbody = " + std::to_string(body) +
         "\n[[load]]\nface = \"z-\"\nbody = " + std::to_string(body) + "\nforce = [0.0, 0.0, " +
         std::to_string(-force) + "]\n";
}
const std::string two = "title = \"two bodies, two methods\"\n[[body]]" + body_a + "[[body]]" + body_b +
                        holds(0, "roller", force_a) + holds(1, "clamped", force_b) + common;
const std::string alone_a = "title = \"A alone\"\n[body]" + body_a + holds(0, "roller", force_a) + common;
const std::string alone_b = "title = \"B alone\"\n[body]" + body_b + holds(0, "clamped", force_b) + common;

}  // namespace

TEST(Bodies, EachBodyGetsWhatItsMethodGivesItAlone) {
  auto r = run(two, PETSC_COMM_WORLD);
  ASSERT_TRUE(r->report.converged);
  ASSERT_EQ(r->scene.calibrations.size(), 2u);
  EXPECT_EQ(r->scene.calibrations[0].method, "homogenized");
  EXPECT_EQ(r->scene.calibrations[1].method, "linear");
  EXPECT_FALSE(r->refresh);
  auto a = run(alone_a, PETSC_COMM_WORLD), b = run(alone_b, PETSC_COMM_WORLD);
  ASSERT_TRUE(a->report.converged && b->report.converged);

  // k bit for bit: body A's connections come first in the global order, then body B's.
  const auto k = gather_stiffness(r->model), ka = gather_stiffness(a->model), kb = gather_stiffness(b->model);
  ASSERT_EQ(k.size(), ka.size() + kb.size());
  long differ = 0;
  for (std::size_t c = 0; c < ka.size(); ++c) differ += k[c] != ka[c];
  for (std::size_t c = 0; c < kb.size(); ++c) differ += k[ka.size() + c] != kb[c];
  EXPECT_EQ(differ, 0) << "connections whose k differs from the body's alone";
  // and the methods really differ: linear k on body A would be another set
  double sums[2] = {0, 0}, total[2];
  const CalibrationContext ctx{a->scene, a->model, a->inputs};
  for (int c : a->model.written_here()) sums[0] += linear_stiffness(ctx, c), sums[1] += a->model.k(c);
  MPI_Allreduce(sums, total, 2, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_GT(std::fabs(total[0] - total[1]), 0.1 * total[1]);

  // The same elongation, and each alone measures its material (homogenized + rollers, rectangular + linear).
  const double ea = elongation(*r, 0), eb = elongation(*r, 1);
  EXPECT_NEAR(ea, elongation(*a, 0), 1e-10 * std::fabs(ea));
  EXPECT_NEAR(eb, elongation(*b, 0), 1e-10 * std::fabs(eb));
  ASSERT_TRUE(a->measured.youngs_modulus && b->measured.youngs_modulus);
  EXPECT_NEAR(*a->measured.youngs_modulus, 1.0e5, 1e-4 * 1.0e5);
  EXPECT_NEAR(*b->measured.youngs_modulus, 3.0e5, 1e-6 * 3.0e5);
  EXPECT_NEAR(*a->measured.elongation, elongation(*a, 0), 1e-12 * std::fabs(ea));

  // the rank count changes nothing: the same scene on this rank alone
  auto self = run(two, MPI_COMM_SELF, {}, false);
  const auto kself = gather_stiffness(self->model);
  differ = 0;
  for (std::size_t c = 0; c < k.size(); ++c) differ += k[c] != kself[c];
  EXPECT_EQ(differ, 0);
}

// Bodies whose method follows the deformation (angles-update) each get a refresher; calibrate_scene chains them,
// and each body's k after a refresh is that of the body alone; a body with a fixed method keeps its k.
TEST(Bodies, AnglesUpdateRefreshersAreChainedPerBody) {
  const std::string c = "[calibration]\nmethod = \"angles-update\"\n[solver]\nkind = \"relaxation\"\n";
  const std::string a_text = R"(
molecules = [3, 3, 4]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 1.0e5
)";
  const std::string b_text = R"(
molecules = [4, 3, 3]
spacing = [0.1, 0.1, 0.1]
topology = "body-diagonals"
youngs_modulus = 2.0e5
offset = [1.0, 0.0, 0.0]
)";
  const std::string l_text = R"(
molecules = [3, 3, 3]
spacing = [0.1, 0.1, 0.1]
youngs_modulus = 4.0e5
offset = [2.0, 0.0, 0.0]
calibration = { method = "divided", divisor = 2.0 }
)";
  const std::string fix = "[[fix]]\nface = \"z+\"\n";
  auto r = run("[[body]]" + a_text + "[[body]]" + b_text + "[[body]]" + l_text + fix + c, PETSC_COMM_WORLD, {}, false);
  auto a = run("[body]" + a_text + fix + c, PETSC_COMM_WORLD, {}, false);
  auto b = run("[body]" + b_text + fix + c, PETSC_COMM_WORLD, {}, false);
  auto l = run("[body]" + l_text + fix + c, PETSC_COMM_WORLD, {}, false);
  ASSERT_TRUE(r->refresh && a->refresh && b->refresh);
  EXPECT_FALSE(l->refresh);
  // A deformation that is a function of the rest position only (so ghosts are consistent): a shear and a stretch.
  auto deform = [](RunResult& q) {
    std::vector<double> x(q.model.rest);
    for (int i = 0; i < q.model.local; ++i) x[3 * i] += 0.05 * x[3 * i + 2], x[3 * i + 2] *= 1.02;
    q.refresh(x.data());
  };
  const auto before = gather_stiffness(r->model);
  deform(*r), deform(*a), deform(*b);
  const auto k = gather_stiffness(r->model), ka = gather_stiffness(a->model), kb = gather_stiffness(b->model),
             kl = gather_stiffness(l->model);
  ASSERT_EQ(k.size(), ka.size() + kb.size() + kl.size());
  long differ = 0, changed = 0;
  for (std::size_t i = 0; i < ka.size(); ++i) differ += k[i] != ka[i], changed += k[i] != before[i];
  for (std::size_t i = 0; i < kb.size(); ++i)
    differ += k[ka.size() + i] != kb[i], changed += k[ka.size() + i] != before[ka.size() + i];
  for (std::size_t i = 0; i < kl.size(); ++i) differ += k[ka.size() + kb.size() + i] != kl[i];
  EXPECT_EQ(differ, 0);
  EXPECT_GT(changed, 0);  // the refresh did change the angles bodies' k
}
