// The finest level's rest tangent (src/solvers/rest_tangent.hpp, issue 18) against the matrix-free Newton tangent
// at the rest positions (src/solvers/matrix_free.hpp, given a copy of them, so that every term takes its general
// path), on box lattices with a roller and a clamped face:
//  - its product and diagonal equal the Newton tangent's to 1e-13 relative: springs at unit and at non-integer
//    spacings (1 mm, 1.2 mm, 0.9 mm), the cell term at nu = 0.45 on cubic cells (volumetric only: the F = I form,
//    row blocks and gathered cells) and on 1 : 1.2 : 0.9 cells (the general cell path);
//  - it is refused where the rest tangent is not what the hierarchy is built from (a term with history) and with
//    -static_rest_smoother false;
//  - the finest level takes it only at rest on every rank (use(): at the rest positions the rest tangent, at
//    deformed ones J), smoother and residual alike;
//  - a static tension test with and without it: the same Newton count, the elongation to 1e-9.
// Run at 1, 2 and 3 ranks: ghosts travel, and the decision is agreed.
#include <gtest/gtest.h>

#include <petscksp.h>

#include <cmath>
#include <cstring>
#include <petsc/private/pcmgimpl.h>  // the finest level's residual operator

#include "src/physics/force_model.hpp"
#include "src/solvers/lattice_mg.hpp"
#include "src/solvers/matrix_free.hpp"
#include "src/solvers/rest_tangent.hpp"
#include "tests/pipeline.hpp"
#include "tests/tangent_scenes.hpp"

using namespace tissue;
using tissue::test_pipeline::RunResult;
using tissue::test_pipeline::run;

namespace {

using tangent_scenes::cells;
using tangent_scenes::fixes;
using tangent_scenes::springs;

using tangent_scenes::visco;

std::string with(std::string text, const std::string& from, const std::string& to) {
  return text.replace(text.find(from), from.size(), to);
}
// Springs alone at non-integer spacings: each spring's rest separation differs from its direction's in the last bits.
const std::string springs_mm = with(springs, "[1.0, 1.0, 1.0]", "[1e-3, 1.2e-3, 0.9e-3]");
// Cubic cells at nu = 0.45: volumetric only (the F = I form), row blocks of 20 cells and gathered ones.
const std::string cubic = with(with(cells, "[1e-3, 1.2e-3, 0.9e-3]", "[1e-3, 1e-3, 1e-3]"), "[9, 7, 11]", "[21, 9, 13]");
// The same with rows of 66 cells: full row blocks (kCellBlock = 64 cells, 65 molecules a row) and short gathered ones.
const std::string cubic_long = with(cubic, "[21, 9, 13]", "[67, 4, 5]");
// Rows of 8 cells, the fewest a row block takes (9 molecules a row, each row's y and z differences read at both
// ends), on a thin lattice whose every row is on the box's edge or face.
const std::string cubic_short = with(cubic, "[21, 9, 13]", "[9, 3, 4]");
// Two row blocks in all (rows of 8 cells, one layer of cells): every product's blocks fewer than the split rows the
// cell term keeps from one row block for the next (src/physics/terms/cell_elasticity.cpp, RestRows), so a product
// would find the last product's rows if they were not dropped before it.
const std::string cubic_tiny = with(cubic, "[21, 9, 13]", "[9, 3, 2]");

// Rows of 99 cells (row blocks of 64 and 35, as at 10^6 molecules) and of 140 (64 + 64 + 12: a cell row of three
// blocks, longer than the rest form's sign tables' span).
const std::string cubic_99 = with(cubic, "[21, 9, 13]", "[100, 4, 3]");
const std::string cubic_140 = with(cubic, "[21, 9, 13]", "[141, 3, 3]");
// A block cut into whole planes at 2 and 3 ranks (its ranks' rows pulled, ghost rows read).
const std::string cubic_planes = with(cubic, "[21, 9, 13]", "[24, 24, 24]");

double relative(Vec a, Vec b) {  // |a - b| / |b|
  Vec d;
  PetscReal diff = 0, ref = 0;
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(a, &d));
  PetscCallAbort(PETSC_COMM_WORLD, VecWAXPY(d, -1.0, b, a));
  PetscCallAbort(PETSC_COMM_WORLD, VecNorm(d, NORM_2, &diff));
  PetscCallAbort(PETSC_COMM_WORLD, VecNorm(b, NORM_2, &ref));
  PetscCallAbort(PETSC_COMM_WORLD, VecDestroy(&d));
  EXPECT_GT(ref, 0.0);
  return diff / ref;
}

// The rest tangent's product (random u, held components included) and diagonal against the Newton tangent's at a
// copy of the rest positions, and both products against the assembled tangent there (the cell term's dual
// numbers: at a copy of the rest positions the volumetric cells' shell product also takes the F = I form).
void compare_at_rest(const std::string& text) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  std::vector<double> scratch(3 * static_cast<std::size_t>(r->model.local));
  std::unique_ptr<RestTangent> rest;
  ASSERT_EQ(RestTangent::make(r->model, *r->forces, scratch.data(), false, &rest), 0);
  ASSERT_TRUE(rest) << text;
  MatrixFreeTangent newton(r->model, *r->forces);
  Mat J;
  ASSERT_EQ(newton.create(&J), 0);
  const std::vector<double> x = r->model.rest;  // a copy: the general paths
  ASSERT_EQ(newton.set_positions(x.data(), J), 0);
  Mat A;
  ASSERT_EQ(r->forces->create_tangent(&A), 0);
  ASSERT_EQ(r->forces->assemble_tangent(x.data(), A), 0);
  Vec u, yr, yn, ya, dr, dn;
  ASSERT_EQ(MatCreateVecs(J, &u, &yr), 0);
  VecDuplicate(yr, &yn), VecDuplicate(yr, &ya), VecDuplicate(yr, &dr), VecDuplicate(yr, &dn);
  PetscRandom random;
  PetscRandomCreate(PETSC_COMM_WORLD, &random);
  PetscRandomSetInterval(random, -1.0, 1.0);
  for (int trial = 0; trial < 3; ++trial) {
    VecSetRandom(u, random);
    ASSERT_EQ(MatMult(rest->matrix(), u, yr), 0);
    ASSERT_EQ(MatMult(J, u, yn), 0);
    EXPECT_LT(relative(yr, yn), 1e-13) << text;
    ASSERT_EQ(MatMult(A, u, ya), 0);
    EXPECT_LT(relative(yr, ya), 1e-13) << text;
    EXPECT_LT(relative(yn, ya), 1e-13) << text;
  }
  ASSERT_EQ(MatGetDiagonal(rest->matrix(), dr), 0);
  ASSERT_EQ(MatGetDiagonal(J, dn), 0);
  EXPECT_LT(relative(dr, dn), 1e-13) << text;
  // Held rows and columns the identity's: a u on the held components only comes back unchanged.
  VecSet(u, 0.0);
  PetscScalar* pu;
  VecGetArray(u, &pu);
  for (int h : r->forces->held_owned()) pu[h] = 1.0 + h;
  VecRestoreArray(u, &pu);
  ASSERT_EQ(MatMult(rest->matrix(), u, yr), 0);
  PetscReal diff = 0;
  VecAXPY(yr, -1.0, u);
  VecNorm(yr, NORM_INFINITY, &diff);
  EXPECT_EQ(diff, 0.0) << text;
  PetscRandomDestroy(&random);
  for (Vec* v : {&u, &yr, &yn, &ya, &dr, &dn}) VecDestroy(v);
  MatDestroy(&J), MatDestroy(&A);
}

// The cell term's rest product by molecule rows (its pull form, the default where every cell block is a row block)
// against its push form (-static_cell_pull false: each block adds to its four corner rows), both the rest tangent's
// whole product, random u: equal to the bit (the same terms in the same order for every molecule).
// The option is read with the term, its arrays made at the first rest product.
void pull_equals_push(const std::string& text) {
  auto a = run(text, PETSC_COMM_WORLD, {}, false);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-static_cell_pull", "false"), 0);
  auto b = run(text, PETSC_COMM_WORLD, {}, false);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-static_cell_pull"), 0);
  std::vector<double> sa(3 * static_cast<std::size_t>(a->model.local)), sb(sa.size());
  std::unique_ptr<RestTangent> ra, rb;
  ASSERT_EQ(RestTangent::make(a->model, *a->forces, sa.data(), false, &ra), 0);
  ASSERT_EQ(RestTangent::make(b->model, *b->forces, sb.data(), false, &rb), 0);
  ASSERT_TRUE(ra && rb) << text;
  Vec ua, ub, ya, yb;
  ASSERT_EQ(MatCreateVecs(ra->matrix(), &ua, &ya), 0);
  ASSERT_EQ(MatCreateVecs(rb->matrix(), &ub, &yb), 0);
  PetscRandom random;
  PetscRandomCreate(PETSC_COMM_WORLD, &random);
  PetscRandomSetInterval(random, -1.0, 1.0);
  for (int trial = 0; trial < 3; ++trial) {
    VecSetRandom(ua, random);
    ASSERT_EQ(VecCopy(ua, ub), 0);
    ASSERT_EQ(MatMult(ra->matrix(), ua, ya), 0);
    ASSERT_EQ(MatMult(rb->matrix(), ub, yb), 0);
    const PetscScalar *pa, *pb;
    PetscInt n = 0;
    VecGetLocalSize(ya, &n);
    VecGetArrayRead(ya, &pa), VecGetArrayRead(yb, &pb);
    int differ = 0;
    for (PetscInt i = 0; i < n; ++i) differ += std::memcmp(pa + i, pb + i, sizeof(double)) != 0;
    VecRestoreArrayRead(ya, &pa), VecRestoreArrayRead(yb, &pb);
    int all = 0;
    MPI_Allreduce(&differ, &all, 1, MPI_INT, MPI_SUM, PETSC_COMM_WORLD);
    EXPECT_EQ(all, 0) << text;
    PetscReal norm = 0;
    VecNorm(ya, NORM_2, &norm);
    EXPECT_GT(norm, 0.0);
  }
  PetscRandomDestroy(&random);
  for (Vec* v : {&ua, &ub, &ya, &yb}) VecDestroy(v);
}

}  // namespace

TEST(RestTangent, CellPullEqualsPushVolumetricCells) { pull_equals_push(cubic); }
TEST(RestTangent, CellPullEqualsPushShortRows) { pull_equals_push(cubic_short); }
TEST(RestTangent, CellPullEqualsPushTwoBlocks) { pull_equals_push(cubic_tiny); }
TEST(RestTangent, CellPullEqualsPushRowsOf99) { pull_equals_push(cubic_99); }
TEST(RestTangent, CellPullEqualsPushRowsOf140) { pull_equals_push(cubic_140); }
TEST(RestTangent, CellPullEqualsPushPlanes) { pull_equals_push(cubic_planes); }
TEST(RestTangent, EqualsNewtonTangentAtRestVolumetricCellsRowsOf140) { compare_at_rest(cubic_140); }

TEST(RestTangent, EqualsNewtonTangentAtRestSprings) { compare_at_rest(springs); }
TEST(RestTangent, EqualsNewtonTangentAtRestSpringsNonIntegerSpacing) { compare_at_rest(springs_mm); }
TEST(RestTangent, EqualsNewtonTangentAtRestVolumetricCells) { compare_at_rest(cubic); }
TEST(RestTangent, EqualsNewtonTangentAtRestVolumetricCellsLongRows) { compare_at_rest(cubic_long); }
TEST(RestTangent, EqualsNewtonTangentAtRestVolumetricCellsShortRows) { compare_at_rest(cubic_short); }
TEST(RestTangent, EqualsNewtonTangentAtRestVolumetricCellsTwoBlocks) { compare_at_rest(cubic_tiny); }
TEST(RestTangent, EqualsNewtonTangentAtRestGeneralCells) { compare_at_rest(cells); }

TEST(RestTangent, RefusedWithHistoryOrOff) {
  std::vector<double> scratch;
  {
    auto r = run(visco, PETSC_COMM_WORLD, {}, false);
    scratch.assign(3 * static_cast<std::size_t>(r->model.local), 0.0);
    std::unique_ptr<RestTangent> rest;
    ASSERT_EQ(RestTangent::make(r->model, *r->forces, scratch.data(), false, &rest), 0);
    EXPECT_FALSE(rest);
  }
  auto r = run(springs, PETSC_COMM_WORLD, {}, false);
  scratch.assign(3 * static_cast<std::size_t>(r->model.local), 0.0);
  std::unique_ptr<RestTangent> rest;
  ASSERT_EQ(RestTangent::make(r->model, *r->forces, scratch.data(), true, &rest), 0);  // a refreshing calibration
  EXPECT_FALSE(rest);
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-static_rest_smoother", "false"), 0);
  ASSERT_EQ(RestTangent::make(r->model, *r->forces, scratch.data(), false, &rest), 0);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-static_rest_smoother"), 0);
  EXPECT_FALSE(rest);
}

// use(): the finest smoother's operators and PCMG's residual operator there are the rest tangent at the rest
// positions and J elsewhere; one rank away from rest is enough for J on every rank.
TEST(RestTangent, FinestLevelAtRestOnly) {
  auto r = run(springs, PETSC_COMM_WORLD, {"body.molecules=[14, 12, 16]"}, false);
  std::vector<double> scratch(3 * static_cast<std::size_t>(r->model.local));
  std::unique_ptr<RestTangent> rest;
  ASSERT_EQ(RestTangent::make(r->model, *r->forces, scratch.data(), false, &rest), 0);
  ASSERT_TRUE(rest);
  MatrixFreeTangent newton(r->model, *r->forces);
  Mat J;
  ASSERT_EQ(newton.create(&J), 0);
  PC pc;
  PetscInt levels = 0;
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &pc), 0);
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), pc, 40, &levels, nullptr), 0);
  ASSERT_GE(levels, 2);
  auto finest = [&](Mat* A, Mat* P, Mat* residual) {
    KSP smoother;
    PCMGGetSmoother(pc, levels - 1, &smoother);
    KSPGetOperators(smoother, A, P);
    *residual = reinterpret_cast<PC_MG*>(pc->data)->levels[levels - 1]->A;
  };
  std::vector<double> x = r->model.rest;
  Mat A, P, R;
  ASSERT_EQ(rest->use(pc, x.data(), J), 0);
  finest(&A, &P, &R);
  EXPECT_TRUE(rest->at_rest());
  EXPECT_EQ(A, rest->matrix());
  EXPECT_EQ(P, rest->matrix());
  EXPECT_EQ(R, rest->matrix());
  int rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  if (rank == 0 && r->model.owned > 0) x[0] += 1e-9;  // rank 0 only
  ASSERT_EQ(rest->use(pc, x.data(), J), 0);
  finest(&A, &P, &R);
  EXPECT_FALSE(rest->at_rest());
  EXPECT_EQ(A, J);
  EXPECT_EQ(P, J);
  EXPECT_EQ(R, J);
  PCDestroy(&pc);
  MatDestroy(&J);
}

// A static tension test with the rest tangent on the finest level (the default) and without it: the same Newton
// count, the elongation and displacements to 1e-9 (the two preconditioners differ by O(strain)), Krylov counts
// printed. Above 1,000 molecules (the lattice multigrid).
void compare_static(const std::string& text, const std::string& molecules, const std::string& load) {
  const std::string scene = text + load;
  auto on = run(scene, PETSC_COMM_WORLD, {"solver.tolerance=1e-10", "body.molecules=" + molecules});
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-static_rest_smoother", "false"), 0);
  auto off = run(scene, PETSC_COMM_WORLD, {"solver.tolerance=1e-10", "body.molecules=" + molecules});
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-static_rest_smoother"), 0);
  ASSERT_TRUE(on->report.converged && off->report.converged);
  EXPECT_EQ(on->report.note.find("matrix-free not used"), std::string::npos) << on->report.note;
  EXPECT_EQ(on->report.iterations, off->report.iterations);
  ASSERT_TRUE(on->measured.elongation && off->measured.elongation);
  EXPECT_NEAR(*on->measured.elongation / *off->measured.elongation, 1.0, 1e-9);
  double diff = 0, size = 0;
  for (int i = 0; i < 3 * on->model.owned; ++i) {
    const double a = off->state->x.array()[i] - off->model.rest[i], b = on->state->x.array()[i] - on->model.rest[i];
    diff = std::max(diff, std::abs(b - a)), size = std::max(size, std::abs(a));
  }
  double all[2] = {diff, size}, out[2];
  MPI_Allreduce(all, out, 2, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_LT(out[0], 1e-9 * out[1]) << text;
  EXPECT_GT(out[1], 0.0);
  PetscPrintf(PETSC_COMM_WORLD, "%s: rest tangent %ld Newton / %ld Krylov, without %ld Newton / %ld Krylov; "
              "max |du| / max |u| = %.2e, elongation %.17g / %.17g\n", on->scene.title.c_str(), on->report.iterations,
              on->report.linear_iterations, off->report.iterations, off->report.linear_iterations, out[0] / out[1],
              *on->measured.elongation, *off->measured.elongation);
}

TEST(RestTangent, StaticTensionSprings) {
  compare_static(springs_mm, "[14, 12, 16]", "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-3]\n");
}
TEST(RestTangent, StaticTensionVolumetricCells) {
  compare_static(with(cells, "[1e-3, 1.2e-3, 0.9e-3]", "[1e-3, 1e-3, 1e-3]"), "[12, 11, 14]",
                 "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-4]\n");
}
TEST(RestTangent, StaticTensionGeneralCells) {
  compare_static(cells, "[12, 11, 14]", "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-4]\n");
}
