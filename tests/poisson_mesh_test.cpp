// Any Poisson ratio and fibres on meshes and random clouds (issue 15 item 3, issue 17 item 2; docs/poisson.md,
// "Meshes and random clouds"): homogenized + the per-tetrahedron term against closed forms, at strain 1e-7:
//  - a Gmsh unit cube (tests/meshes/cube.geo) in tension on rollers: E and both lateral nu for nu in
//    {0.1, 0.25, 0.45} (the issue asks 0.5 %; the term is exact for affine states, so 1e-6 is asked);
//  - a random cloud in a box: the same;
//  - fibres along x on the cube: tension along x reads E_L and nu_LT (both lateral axes), along z E_T, nu_TL and
//    nu_TT (the issue asks 1 % on meshes; 1e-6 is asked);
//  - the term's force against a finite difference of its energy, its tangent against one of its force (on one rank
//    column by column; on 1-3 ranks along a direction, with the matrix-free product and the diagonal: the
//    patches' rank-one blocks reach two rings, so rows of ghosts are assembled off-process);
//  - no volumetric locking (nodal averaging): a Gmsh cantilever 10 x 1 x 1 at nu = 0.499 deflects within 15 % of
//    the nu = 0.25 one at h = 0.34 and within the issue's 5 % at h = 0.12 (the per-tetrahedron volumetric part
//    deflected 0.31 of it at h = 0.34), both within 30 % of Timoshenko's closed form;
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
#include <petscmat.h>
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

// The assembled tangent (owned rows and, off-process, ghosts' rows), the matrix-free product and the diagonal on
// PETSC_COMM_WORLD against central differences of the force along a direction, and the force against the energy's.
TEST(PoissonMesh, TangentOnEveryRankCount) {
  for (const std::string& body : {cube(0.5), kCloud}) {
    Case c;
    c.body = body, c.nu = 0.49;
    if (body == kCloud) c.axis = 'x', c.area = 0.64;
    auto r = run(scene_text(c), PETSC_COMM_WORLD, {}, /*do_solve=*/false);
    const LocalModel& m = r->model;
    const ForceModel& fm = *r->forces;
    std::vector<double> x, v(3 * m.local), f(3 * m.local), fp(3 * m.local), fmin(3 * m.local);
    deform(m, x);
    for (int i = 0; i < m.local; ++i)
      for (int d = 0; d < 3; ++d)
        v[3 * i + d] = fm.held()[3 * i + d] ? 0.0 : std::sin(0.37 * static_cast<double>(m.id[i]) + 1.1 * d + 0.2);
    const double eps = 1e-6;
    std::vector<double> xp(x), xm(x);
    for (std::size_t q = 0; q < x.size(); ++q) xp[q] += eps * v[q], xm[q] -= eps * v[q];
    fm.forces(x.data(), nullptr, f.data());
    fm.forces(xp.data(), nullptr, fp.data());
    fm.forces(xm.data(), nullptr, fmin.data());
    double scale = 0, local[2] = {0, 0}, global[2];
    for (int j = 0; j < 3 * m.owned; ++j) scale = std::max(scale, std::fabs(f[j]));
    MPI_Allreduce(MPI_IN_PLACE, &scale, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
    ASSERT_GT(scale, 0);
    for (int j = 0; j < 3 * m.owned; ++j) local[0] -= f[j] * v[j];  // dE/ds = -f . v
    local[1] = (fm.potential_energy(xp.data()) - fm.potential_energy(xm.data())) / (2 * eps);
    MPI_Allreduce(local, global, 2, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
    EXPECT_NEAR(global[1], global[0], 1e-6 * scale * std::sqrt(3.0 * static_cast<double>(m.global_molecules))) << body;
    // J v assembled
    Mat J;
    ASSERT_EQ(fm.create_tangent(&J), 0);
    ASSERT_EQ(fm.assemble_tangent(x.data(), J), 0);
    Vec in, out;
    ASSERT_EQ(MatCreateVecs(J, &in, &out), 0);
    double* a;
    VecGetArray(in, &a);
    std::copy(v.begin(), v.begin() + 3 * m.owned, a);
    VecRestoreArray(in, &a);
    ASSERT_EQ(MatMult(J, in, out), 0);
    const double* Jv;
    VecGetArrayRead(out, &Jv);
    std::vector<double> scratch(v), applied(3 * m.owned), diag(3 * m.owned);
    ASSERT_EQ(fm.apply_tangent(x.data(), scratch.data(), applied.data()), 0);
    ASSERT_EQ(fm.tangent_diagonal(x.data(), diag.data()), 0);
    Vec d;
    ASSERT_EQ(MatCreateVecs(J, &d, nullptr), 0);
    ASSERT_EQ(MatGetDiagonal(J, d), 0);
    const double* Jd;
    VecGetArrayRead(d, &Jd);
    for (int j = 0; j < 3 * m.owned; ++j) {
      EXPECT_NEAR(applied[j], Jv[j], 1e-9 * scale) << "matrix-free " << j << " " << body;
      EXPECT_NEAR(diag[j], Jd[j], 1e-9 * std::fabs(Jd[j]) + 1e-12) << "diagonal " << j << " " << body;
      if (fm.held()[j]) continue;
      EXPECT_NEAR(Jv[j], -(fp[j] - fmin[j]) / (2 * eps), 1e-6 * scale) << "tangent row " << j << " " << body;
    }
    VecRestoreArrayRead(d, &Jd);
    VecRestoreArrayRead(out, &Jv);
    VecDestroy(&d), VecDestroy(&in), VecDestroy(&out), MatDestroy(&J);
  }
}

// Nodal averaging takes the locking away as the mesh is refined: a 10 x 1 x 1 Gmsh beam (tests/meshes/beam.geo)
// clamped at x-, a tip load on x+; the tip's mean deflection at nu = 0.499 over the nu = 0.25 one is 0.72 at
// h = 0.5, 0.875 at h = 0.34 (587 molecules), 0.945 at h = 0.17 and 0.962 at h = 0.12 (6,560 molecules: the issue's
// 5 %); the per-tetrahedron volumetric part deflected 0.31 of it at h = 0.34. Both deflections are within 30 % of
// Timoshenko's P L^3 / (3 E I) + P L / (k G A), k = 10 (1 + nu) / (12 + 11 nu) (0.84 and 0.73 at h = 0.34: linear
// tetrahedra three deep are stiff in bending at any nu, and the clamp is stiffer than the beam theory's).
// body: the [body] lines of the beam's mesh; returns the deflection ratio 0.499 / 0.25.
double cantilever_ratio(const std::string& body) {
  const double P = 1e-4, L = 10, I = 1.0 / 12, A = 1;
  auto tip = [&](double nu) {
    Case c;
    c.body = body;
    c.nu = nu;
    std::string text = scene_text(c);
    const std::string fix = "face = \"z-\"\nmode = \"roller\"", load = "face = \"z+\"";
    text.replace(text.find(fix), fix.size(), "face = \"x-\"\nmode = \"clamped\"");
    text.replace(text.find(load), load.size(), "face = \"x+\"");
    text.replace(text.find("force = ["), 9, "force = [0.0, 0.0, -1e-4] #");
    auto r = run(text, PETSC_COMM_WORLD);
    EXPECT_TRUE(r->report.converged) << nu;
    double sums[2] = {0, 0};
    for (int i = 0; i < r->model.owned; ++i)
      if (std::fabs(r->model.rest[3 * i] - L) < 1e-9)
        sums[0] += r->state->x.array()[3 * i + 2] - r->model.rest[3 * i + 2], sums[1] += 1;
    MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
    const double G = E / (2 * (1 + nu)), k = 10 * (1 + nu) / (12 + 11 * nu);
    const double closed = P * L * L * L / (3 * E * I) + P * L / (k * G * A);
    const double deflection = -sums[0] / sums[1];
    PetscPrintf(PETSC_COMM_WORLD, "cantilever nu %g: tip deflection %.6e, Timoshenko %.6e, ratio %.4f\n", nu,
                deflection, closed, deflection / closed);
    EXPECT_NEAR(deflection / closed, 1.0, 0.3) << nu;
    return deflection;
  };
  const double quarter = tip(0.25), near_half = tip(0.499);
  EXPECT_GT(quarter, 0.0);
  return near_half / quarter;
}

TEST(PoissonMesh, CantileverDoesNotLock) {
  const std::string body = "shape = \"mesh\"\nfile = \"" + std::string(TISSUE_SOURCE_DIR) + "/tests/meshes/beam_h0.34.msh\"\n";
  EXPECT_NEAR(cantilever_ratio(body), 1.0, 0.15);
}

// The issue's 5 % on the beam meshed at run time at h = 0.12 (its .geo, mesh_size; ~20 s of two solves, so
// tests/CMakeLists.txt runs it at 2 ranks only: the rank counts' agreement is SameOnEveryRankCount's).
TEST(PoissonMesh, FineCantileverWithinFivePercent) {
  const std::string body = "shape = \"mesh\"\nfile = \"" + std::string(TISSUE_SOURCE_DIR) +
                           "/tests/meshes/beam.geo\"\nmesh_size = 0.12\n";
  EXPECT_NEAR(cantilever_ratio(body), 1.0, 0.05);
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
