// The lattice multigrid's volume smoother (src/solvers/volume_smoother.hpp) on a cell-term scene with a roller and
// a clamped face (0-3 free components a molecule), run at 1, 2 and 3 ranks:
//  - with many Neumann steps (Q -> T^-1) the shell applies M^-1 exactly: M z = r, with M = D + B^T K B assembled
//    independently as a PETSc matrix (D the assembled tangent's diagonal less the cells' volumetric part, each
//    cell's k b b^T added once, by the rank owning its corner 0; held rows the identity's), to 1e-8;
//  - with one step r.z > 0 and z is not M^-1 r (|M z - r| > 1e-6 |r|: Q is T^-1 only approximately);
//  - a static tension test with -static_volume_smoother gives the default's elongation to the solve's tolerance.
#include <gtest/gtest.h>

#include <petscksp.h>

#include <cmath>
#include <cstdio>

#include "src/physics/force_model.hpp"
#include "src/solvers/volume_smoother.hpp"
#include "tests/pipeline.hpp"
#include "tests/tangent_scenes.hpp"

using namespace tissue;
using tissue::test_pipeline::run;

namespace {

const std::string cells = R"(
title = "volume smoother"
[body]
molecules = [7, 6, 8]
spacing = [1e-3, 1.2e-3, 0.9e-3]
topology = "face-diagonals"
youngs_modulus = 1e4
poisson_ratio = 0.45
[calibration]
method = "homogenized"
)" + tangent_scenes::fixes;

// M = D + B^T K B from the tangent A (assembled at rest) and the cells.
Mat woodbury_matrix(const test_pipeline::RunResult& r, Mat A, const Term::VolumeCoupling& c) {
  const auto& held = r.forces->held();
  Mat M;
  Vec d;
  PetscCallAbort(PETSC_COMM_WORLD, MatCreateVecs(A, &d, nullptr));
  PetscCallAbort(PETSC_COMM_WORLD, MatGetDiagonal(A, d));
  PetscCallAbort(PETSC_COMM_WORLD, MatCreateAIJ(PETSC_COMM_WORLD, 3 * r.model.owned, 3 * r.model.owned,
                                                PETSC_DETERMINE, PETSC_DETERMINE, 81, nullptr, 81, nullptr, &M));
  PetscCallAbort(PETSC_COMM_WORLD, MatSetOption(M, MAT_NEW_NONZERO_ALLOCATION_ERR, PETSC_FALSE));
  // D's volumetric part, on owned rows: every cell at an owned corner is here.
  std::vector<double> vol(3 * r.model.owned, 0.0);
  const int n = static_cast<int>(c.k.size());
  for (int e = 0; e < n; ++e)
    for (int a = 0; a < 8; ++a) {
      const int m = c.corners[8 * e + a];
      if (m < r.model.owned)
        for (int q = 0; q < 3; ++q) vol[3 * m + q] += c.k[e] * c.g[3 * e + q] * c.g[3 * e + q];
    }
  const PetscScalar* pd;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetArrayRead(d, &pd));
  for (int i = 0; i < 3 * r.model.owned; ++i) {
    const PetscInt row = 3 * r.model.block[i / 3] + i % 3;
    const double v = held[i] ? 1.0 : pd[i] - vol[i];
    PetscCallAbort(PETSC_COMM_WORLD, MatSetValue(M, row, row, v, ADD_VALUES));
  }
  PetscCallAbort(PETSC_COMM_WORLD, VecRestoreArrayRead(d, &pd));
  for (int e = 0; e < n; ++e) {
    if (c.corners[8 * e] >= r.model.owned) continue;  // the owner of corner 0 adds the cell
    PetscInt idx[24];
    double b[24];
    for (int a = 0; a < 8; ++a)
      for (int q = 0; q < 3; ++q) {
        const int m = c.corners[8 * e + a];
        idx[3 * a + q] = 3 * r.model.block[m] + q;
        b[3 * a + q] = held[3 * m + q] ? 0.0 : (((a >> q) & 1) ? 1.0 : -1.0) * c.g[3 * e + q];
      }
    double K[24 * 24];
    for (int p = 0; p < 24; ++p)
      for (int q = 0; q < 24; ++q) K[24 * p + q] = c.k[e] * b[p] * b[q];
    PetscCallAbort(PETSC_COMM_WORLD, MatSetValues(M, 24, idx, 24, idx, K, ADD_VALUES));
  }
  PetscCallAbort(PETSC_COMM_WORLD, MatAssemblyBegin(M, MAT_FINAL_ASSEMBLY));
  PetscCallAbort(PETSC_COMM_WORLD, MatAssemblyEnd(M, MAT_FINAL_ASSEMBLY));
  PetscCallAbort(PETSC_COMM_WORLD, VecDestroy(&d));
  return M;
}

Term::VolumeCoupling coupling(const test_pipeline::RunResult& r) {
  Term::VolumeCoupling c;
  bool found = false;
  for (const auto& t : r.forces->terms()) found = found || t->volume_coupling(c);
  EXPECT_TRUE(found);  // every rank holds cells on this lattice
  return c;
}

}  // namespace

TEST(VolumeSmoother, ManyStepsApplyTheInverseOfM) {
  auto r = run(cells, PETSC_COMM_WORLD, {}, false);
  const Term::VolumeCoupling c = coupling(*r);
  Mat A;
  ASSERT_EQ(r->forces->create_tangent(&A), 0);
  ASSERT_EQ(r->forces->assemble_tangent(r->model.rest.data(), A), 0);
  Mat M = woodbury_matrix(*r, A, c);
  Vec rhs, z, mz;
  ASSERT_EQ(MatCreateVecs(A, &rhs, &z), 0);
  ASSERT_EQ(VecDuplicate(rhs, &mz), 0);
  PetscScalar* pr;
  VecGetArray(rhs, &pr);
  for (int i = 0; i < r->model.owned; ++i)
    for (int d = 0; d < 3; ++d) pr[3 * i + d] = std::sin(0.37 * static_cast<double>(r->model.id[i]) + 1.3 * d);
  VecRestoreArray(rhs, &pr);
  for (int steps : {1, 2000}) {
    PC pc;
    ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &pc), 0);
    ASSERT_EQ(make_volume_smoother(r->model, r->forces->held(), c, steps, pc), 0);
    ASSERT_EQ(PCSetOperators(pc, A, A), 0);
    ASSERT_EQ(PCSetUp(pc), 0);
    ASSERT_EQ(PCApply(pc, rhs, z), 0);
    ASSERT_EQ(MatMult(M, z, mz), 0);
    ASSERT_EQ(VecAXPY(mz, -1.0, rhs), 0);
    PetscReal res = 0, ref = 0, rz = 0;
    VecNorm(mz, NORM_2, &res);
    VecNorm(rhs, NORM_2, &ref);
    VecDot(rhs, z, &rz);
    EXPECT_GT(rz, 0.0);
    if (steps > 1) {
      EXPECT_LT(res, 1e-8 * ref) << "M z - r";
    } else {
      // One step: M^-1 only approximately, and not Jacobi (the cells' correction is there).
      EXPECT_GT(res, 1e-6 * ref);
    }
    PetscPrintf(PETSC_COMM_WORLD, "volume smoother, %d Neumann steps: |M z - r| / |r| = %.2e\n", steps,
                static_cast<double>(res / ref));
    PCDestroy(&pc);
  }
  VecDestroy(&rhs), VecDestroy(&z), VecDestroy(&mz);
  MatDestroy(&M), MatDestroy(&A);
}

TEST(VolumeSmoother, StaticSolveKeepsTheElongation) {
  const std::string scene = cells + "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-4]\n";
  const std::vector<std::string> set = {"body.molecules=[12, 11, 14]"};
  auto d = run(scene, PETSC_COMM_WORLD, set);
  PetscOptionsSetValue(nullptr, "-static_volume_smoother", "1");
  auto v = run(scene, PETSC_COMM_WORLD, set);
  PetscOptionsClearValue(nullptr, "-static_volume_smoother");
  ASSERT_TRUE(d->report.converged && v->report.converged);
  ASSERT_TRUE(d->measured.elongation && v->measured.elongation);
  EXPECT_NEAR(*v->measured.elongation / *d->measured.elongation, 1.0, 1e-8);
  PetscPrintf(PETSC_COMM_WORLD, "static 12 x 11 x 14, nu = 0.45: Newton / Krylov default %ld / %ld, volume smoother "
              "%ld / %ld\n", static_cast<long>(d->report.iterations), static_cast<long>(d->report.linear_iterations),
              static_cast<long>(v->report.iterations), static_cast<long>(v->report.linear_iterations));
}

// The coarse levels' Chebyshev steps with cells (kCellCoarseSteps, -static_cell_coarse_steps): on cubic cells at
// nu = 0.45 the same elongation to the solve's tolerance in fewer Krylov iterations than the levels' default 2
// steps; where they do not apply (flat cells at nu = 0.45; nu = 0.1, whose cell term carries only shear) nothing
// changes, to the bit.
TEST(VolumeSmoother, CoarseStepsWithCells) {
  const std::string scene = cells + "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-4]\n";
  const std::vector<std::string> sets[3] = {
      {"body.molecules=[24, 22, 28]", "body.spacing=[1e-3, 1e-3, 1e-3]"},
      {"body.molecules=[24, 22, 28]", "body.spacing=[1e-3, 1e-3, 0.5e-3]"},
      {"body.molecules=[24, 22, 28]", "body.poisson_ratio=0.1", "body.spacing=[1e-3, 1e-3, 0.5e-3]"}};
  const char* what[3] = {"nu = 0.45, cubic cells", "nu = 0.45, 1:1:0.5 cells", "nu = 0.1, 1:1:0.5 cells"};
  for (int k = 0; k < 3; ++k) {
    auto d = run(scene, PETSC_COMM_WORLD, sets[k]);
    PetscOptionsSetValue(nullptr, "-static_cell_coarse_steps", "0");
    auto o = run(scene, PETSC_COMM_WORLD, sets[k]);
    PetscOptionsClearValue(nullptr, "-static_cell_coarse_steps");
    ASSERT_TRUE(d->report.converged && o->report.converged);
    ASSERT_TRUE(d->measured.elongation && o->measured.elongation);
    PetscPrintf(PETSC_COMM_WORLD, "static 24 x 22 x 28, %s: Newton / Krylov by default %ld / %ld, with the levels' "
                "2 steps %ld / %ld\n", what[k], static_cast<long>(d->report.iterations),
                static_cast<long>(d->report.linear_iterations), static_cast<long>(o->report.iterations),
                static_cast<long>(o->report.linear_iterations));
    if (k == 0) {
      EXPECT_NEAR(*d->measured.elongation / *o->measured.elongation, 1.0, 1e-8);
      EXPECT_LT(d->report.linear_iterations, o->report.linear_iterations);
    } else {
      EXPECT_EQ(*d->measured.elongation, *o->measured.elongation);
      EXPECT_EQ(d->report.linear_iterations, o->report.linear_iterations);
    }
  }
}
