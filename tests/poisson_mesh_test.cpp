// Any Poisson ratio and fibres on meshes and random clouds (issue 15 item 3, issue 17 item 2; docs/poisson.md,
// "Meshes and random clouds"): homogenized + the per-tetrahedron term against closed forms, at strain 1e-7:
//  - a Gmsh unit cube (tests/meshes/cube.geo) in tension on rollers: E and both lateral nu for nu in
//    {0.1, 0.25, 0.45} (the issue asks 0.5 %; the term is exact for affine states, so 1e-6 is asked);
//  - a random cloud in a box: the same;
//  - fibres along x on the cube: tension along x reads E_L and nu_LT (both lateral axes), along z E_T, nu_TL and
//    nu_TT (the issue asks 1 % on meshes; 1e-6 is asked);
//  - the term's force against a finite difference of its energy, its tangent against one of its force;
//  - forces at a large deformation bit for bit those of one rank on any partition, and the static solution to
//    1e-10 of the one-rank one;
//  - the critical time step is a lower bound of the stability limit within 2.5x.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <unordered_map>
#include <vector>

#include "src/solvers/solver.hpp"
#include "tests/derivative_check.hpp"
#include "tests/pipeline.hpp"

using namespace tissue;
using namespace tissue::test_pipeline;

namespace {

const double E = 1000.0;  // Pa

struct Case {
  std::string body;            // the [body] lines before the material (shape, file or molecules, topology)
  double nu = 0.25;
  std::string fibres;          // [body.fibres] lines, or empty
  char axis = 'z';             // tension along this axis: roller on its "-" face, traction on its "+" face
  double modulus = E;          // the expected modulus along `axis` (sets the load for the strain)
  double area = 1.0;           // the loaded face's area (m^2)
  double strain = 1e-7;
  std::string solver = "static";
};

std::string cube(double h = 0.25) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "cube_h%g.msh", h);
  return "shape = \"mesh\"\nfile = \"" + std::string(TISSUE_SOURCE_DIR) + "/tests/meshes/" + buf + "\"\n";
}
const std::string kCloud = "molecules = [6, 5, 5]\nsize = [1.0, 0.8, 0.8]\ntopology = \"random\"\nseed = 7\n";

std::string scene_text(const Case& c) {
  char buf[512];
  std::string s = "title = \"poisson mesh test\"\n[body]\n" + c.body;
  std::snprintf(buf, sizeof buf, "youngs_modulus = %.17g\npoisson_ratio = %.17g\ndensity = 1000.0\n", E, c.nu);
  s += buf;
  if (!c.fibres.empty()) s += "[body.fibres]\n" + c.fibres;
  s += "[calibration]\nmethod = \"homogenized\"\n";
  const int a = c.axis - 'x';
  double force[3] = {0, 0, 0};
  force[a] = c.modulus * c.strain * c.area;
  std::snprintf(buf, sizeof buf,
                "[[fix]]\nface = \"%c-\"\nmode = \"roller\"\n[[load]]\nface = \"%c+\"\nforce = [%.17g, %.17g, %.17g]\n"
                "[solver]\nkind = \"%s\"\ntolerance = 1e-10\n[output]\ndirectory = \"/tmp/tissue_poisson_mesh_test\"\n"
                "progress = false\n",
                c.axis, c.axis, force[0], force[1], force[2], c.solver.c_str());
  return s + buf;
}

// Tension along c.axis reads `modulus` and the lateral ratios nu_lateral (x, y, z order without the axis).
void expect_tension(const Case& c, double nu_a, double nu_b, const std::string& what) {
  auto r = run(scene_text(c), PETSC_COMM_WORLD);
  ASSERT_TRUE(r->report.converged) << what;
  ASSERT_EQ(r->forces->term_names().size(), 1u) << what;
  ASSERT_TRUE(r->measured.youngs_modulus && r->measured.poisson_ratios) << what;
  EXPECT_NEAR(*r->measured.youngs_modulus / c.modulus, 1.0, 1e-6) << what;
  EXPECT_NEAR((*r->measured.poisson_ratios)[0], nu_a, 1e-6) << what;
  EXPECT_NEAR((*r->measured.poisson_ratios)[1], nu_b, 1e-6) << what;
}

TEST(PoissonMesh, GmshCubeTension) {
  for (double nu : {0.1, 0.25, 0.45}) {
    Case c;
    c.body = cube(), c.nu = nu;
    expect_tension(c, nu, nu, "cube, nu " + std::to_string(nu));
  }
}

TEST(PoissonMesh, RandomCloudTension) {
  for (double nu : {0.1, 0.45}) {
    Case c;
    c.body = kCloud, c.nu = nu, c.axis = 'x', c.area = 0.8 * 0.8;
    expect_tension(c, nu, nu, "cloud, nu " + std::to_string(nu));
  }
}

// Transverse isotropy with fibres along x: E_T = E, nu_TT = 0.3, E_L = 10 E, nu_LT = 0.35, G_L = 0.5 E.
TEST(PoissonMesh, FibresAlongX) {
  const double E_L = 10 * E, nu_LT = 0.35, nu_TT = 0.3;
  Case c;
  c.body = cube(), c.nu = nu_TT;
  char buf[256];
  std::snprintf(buf, sizeof buf, "direction = [1.0, 0.0, 0.0]\nyoungs_modulus = %.17g\npoisson_ratio = %.17g\n"
                "shear_modulus = %.17g\n", E_L, nu_LT, 0.5 * E);
  c.fibres = buf;
  c.axis = 'x', c.modulus = E_L;
  expect_tension(c, nu_LT, nu_LT, "along the fibres");  // lateral y, z
  c.axis = 'z', c.modulus = E;
  expect_tension(c, nu_LT * E / E_L, nu_TT, "across the fibres");  // lateral x (nu_TL), y (nu_TT)
}

// One rank holds everything here (MPI_COMM_SELF): the isotropic term at nu = 0.45 and the fibre terms.
TEST(PoissonMesh, TermDerivatives) {
  for (const std::string fibres : {std::string(), std::string("direction = [1.0, 2.0, 2.0]\nyoungs_modulus = 8000.0\n"
                                                              "poisson_ratio = 0.3\n")}) {
    Case c;
    c.body = cube(0.5), c.nu = 0.45, c.fibres = fibres;
    auto r = run(scene_text(c), MPI_COMM_SELF, {}, /*do_solve=*/false);
    ASSERT_EQ(r->forces->term_names().size(), 1u);
    std::vector<double> x;
    deform(r->model, x);
    EXPECT_GT(expect_consistent_derivatives(r->model, *r->forces, x, fibres.empty() ? "isotropic" : "fibres"), 30);
  }
}

TEST(PoissonMesh, SameOnEveryRankCount) {
  for (const std::string& body : {cube(), kCloud}) {
    Case c;
    c.body = body, c.nu = 0.45, c.strain = 1e-2;
    if (body == kCloud) c.axis = 'x', c.area = 0.64;
    auto world = run(scene_text(c), PETSC_COMM_WORLD);
    auto self = run(scene_text(c), MPI_COMM_SELF);
    ASSERT_TRUE(world->report.converged && self->report.converged);
    expect_same_as_one_rank(*world, *self, 1e-10);
  }
}

// The printed critical time step is a lower bound of the stability limit (Gershgorin on M^-1 K, or element by
// element): a dynamic run at it stays finite, one at 2.5 times it is stopped by the guards; it shrinks with c_p as
// nu -> 1/2.
TEST(PoissonMesh, CriticalTimeStep) {
  double previous = 0;
  for (double nu : {0.45, 0.25}) {
    Case c;
    c.body = cube(), c.nu = nu, c.strain = 1e-3;
    auto r = run(scene_text(c), PETSC_COMM_WORLD, {}, /*do_solve=*/false);
    const double dt = critical_time_step(*r->forces);
    ASSERT_TRUE(std::isfinite(dt) && dt > 0);
    if (previous > 0) EXPECT_GT(dt, previous);
    previous = dt;
    c.solver = "dynamic";
    char step[64];
    std::snprintf(step, sizeof step, "solver.time_step=%.17g", dt);
    auto d = run(scene_text(c), PETSC_COMM_WORLD, {"solver.steps=1500", "solver.allow_unstable_time_step=true", step});
    EXPECT_TRUE(std::isfinite(d->measured.kinetic_energy) && d->measured.kinetic_energy > 0) << nu;
    // Within 2.5x of the limit: the guards stop a run at 2.5 times it (measured limit: 1.5-2x, docs/poisson.md).
    std::snprintf(step, sizeof step, "solver.time_step=%.17g", 2.5 * dt);
    EXPECT_THROW(run(scene_text(c), PETSC_COMM_WORLD, {"solver.steps=1500", "solver.allow_unstable_time_step=true", step}),
                 SolverFailure) << nu;
  }
}

}  // namespace
