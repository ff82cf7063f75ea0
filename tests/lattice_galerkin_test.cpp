// The lattice multigrid's structured coarse operators (src/solvers/lattice_galerkin.hpp) against PETSc's general
// triple product MatPtAP with the same interpolations, level by level, on a deformed lattice (geometric tangent
// terms), with roller and clamped faces (0-3 free components a node) and plane counts that leave a last plane
// one step from the one before it. Run at 1, 2 and 3 ranks: the rows of coarse nodes owned elsewhere travel.
#include <gtest/gtest.h>

#include <petscksp.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstring>

#include <Eigen/Dense>
#include <memory>
#include <vector>

#include "src/physics/force_model.hpp"
#include "src/solvers/lattice_galerkin.hpp"
#include "src/solvers/lattice_mg.hpp"
#include "tests/pipeline.hpp"
#include "tests/tangent_scenes.hpp"

using namespace tissue;
using tissue::test_pipeline::RunResult;
using tissue::test_pipeline::run;

namespace {

// The box of tests/tangent_scenes.hpp (springs at unit spacing, a roller and a clamped face).
const std::string scene = tangent_scenes::springs;

// || A - B ||_F / || B ||_F.
double relative_difference(Mat A, Mat B) {
  Mat D;
  PetscReal diff = 0, ref = 0;
  PetscCallAbort(PETSC_COMM_WORLD, MatDuplicate(A, MAT_COPY_VALUES, &D));
  PetscCallAbort(PETSC_COMM_WORLD, MatAXPY(D, -1.0, B, DIFFERENT_NONZERO_PATTERN));
  PetscCallAbort(PETSC_COMM_WORLD, MatNorm(D, NORM_FROBENIUS, &diff));
  PetscCallAbort(PETSC_COMM_WORLD, MatNorm(B, NORM_FROBENIUS, &ref));
  PetscCallAbort(PETSC_COMM_WORLD, MatDestroy(&D));
  return diff / ref;
}

// The tangent at the rest positions moved by a smooth displacement (the same on every rank count).
void assemble_at(const RunResult& r, double amplitude, Mat J) {
  std::vector<double> x(r.model.rest);
  for (int i = 0; i < r.model.local; ++i)
    for (int d = 0; d < 3; ++d) x[3 * i + d] += amplitude * std::sin(0.7 * x[3 * i + (d + 1) % 3] + 0.3 * d + x[3 * i + d]);
  PetscCallAbort(PETSC_COMM_WORLD, r.forces->assemble_tangent(x.data(), J));
}

}  // namespace

TEST(LatticeGalerkin, EqualsPetscTripleProductOnEveryLevel) {
  auto r = run(scene, PETSC_COMM_WORLD, {}, false);
  Mat J;
  ASSERT_EQ(r->forces->create_tangent(&J), 0);
  PC pc;
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &pc), 0);
  PetscInt levels = 0;
  LatticeLevels hierarchy;
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), pc, 40, &levels, &hierarchy), 0);
  ASSERT_GE(levels, 3);  // 840 molecules, at most 40 on the coarsest: 10x7x12 -> 6x4x7 -> 4x3x4 -> 3x2x3
  LatticeGalerkin galerkin(r->model, r->forces->held(), std::move(hierarchy));
  bool stencil = false;
  ASSERT_EQ(galerkin.applies(J, &stencil), 0);
  EXPECT_TRUE(stencil);
  // Every call after the first refills the matrices it made; at the rest positions (amplitude 0) nearly every row
  // is equal to the bit to others of its class (the box sums kept once a class, coarse rows copied).
  for (double amplitude : {0.05, 0.0, 0.12}) {
    assemble_at(*r, amplitude, J);
    ASSERT_EQ(galerkin.update(J, pc), 0);
    Mat fine = J;
    PetscObjectReference(reinterpret_cast<PetscObject>(fine));
    for (PetscInt l = levels - 1; l >= 1; --l) {  // PCMG numbers the finest level levels - 1
      Mat P, reference, ours;
      KSP smoother;
      ASSERT_EQ(PCMGGetInterpolation(pc, l, &P), 0);
      ASSERT_EQ(MatPtAP(fine, P, MAT_INITIAL_MATRIX, PETSC_DEFAULT, &reference), 0);
      ASSERT_EQ(PCMGGetSmoother(pc, l - 1, &smoother), 0);
      ASSERT_EQ(KSPGetOperators(smoother, &ours, nullptr), 0);
      PetscInt rows_ref, rows_ours;
      MatGetSize(reference, &rows_ref, nullptr);
      MatGetSize(ours, &rows_ours, nullptr);
      ASSERT_EQ(rows_ours, rows_ref) << "level " << l - 1;
      EXPECT_LT(relative_difference(ours, reference), 1e-13) << "level " << l - 1 << ", amplitude " << amplitude;
      MatDestroy(&fine);
      fine = reference;  // the next level from PETSc's own product of this one
    }
    MatDestroy(&fine);
  }
  PCDestroy(&pc);
  MatDestroy(&J);
}

// The matrix-free update's Gershgorin bound on the Jacobi-scaled tangent (summed from the block stream it coarsens)
// against the force model's own pass (the same sums: equal to the bit) and against the assembled tangent's rows
// (max over rows of sum_c |a_rc| / a_rr; held rows are identity rows there, held columns zero).
TEST(LatticeGalerkin, StreamGershgorinBoundEqualsForceModelsAndAssembledRows) {
  const auto rp = run(scene, PETSC_COMM_WORLD, {}, false);
  const RunResult& r = *rp;
  std::vector<double> x(r.model.rest);
  for (int i = 0; i < r.model.local; ++i)
    for (int d = 0; d < 3; ++d) x[3 * i + d] += 0.05 * std::sin(0.7 * x[3 * i + (d + 1) % 3] + 0.3 * d + x[3 * i + d]);
  Mat J;
  ASSERT_EQ(r.forces->create_tangent(&J), 0);
  ASSERT_EQ(r.forces->assemble_tangent(x.data(), J), 0);
  PC pc;
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &pc), 0);
  ASSERT_EQ(PCSetOperators(pc, J, J), 0);
  PetscInt levels = 0;
  LatticeLevels hierarchy;
  ASSERT_EQ(setup_lattice_mg(r.model, r.forces->held(), pc, 40, &levels, &hierarchy), 0);
  ASSERT_GE(levels, 3);
  LatticeGalerkin galerkin(r.model, r.forces->held(), std::move(hierarchy));
  ASSERT_EQ(galerkin.update(*r.forces, x.data(), pc), 0);
  double bound = 0.0;
  bool exact = false;
  ASSERT_EQ(r.forces->jacobi_gershgorin(x.data(), &bound, &exact), 0);
  ASSERT_TRUE(exact);
  EXPECT_EQ(galerkin.jacobi_bound(), bound);
  PetscInt lo, hi;
  ASSERT_EQ(MatGetOwnershipRange(J, &lo, &hi), 0);
  double rows = 1.0;
  for (PetscInt row = lo; row < hi; ++row) {
    PetscInt n;
    const PetscInt* cols;
    const PetscScalar* v;
    ASSERT_EQ(MatGetRow(J, row, &n, &cols, &v), 0);
    double diag = 0.0, sum = 0.0;
    for (PetscInt e = 0; e < n; ++e) {
      sum += std::abs(v[e]);
      if (cols[e] == row) diag = v[e];
    }
    ASSERT_EQ(MatRestoreRow(J, row, &n, &cols, &v), 0);
    ASSERT_GT(diag, 0.0);
    rows = std::max(rows, sum / diag);
  }
  double all = 0.0;
  MPI_Allreduce(&rows, &all, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_GT(all, 1.5);  // a real bound, not the held rows' 1
  EXPECT_NEAR(galerkin.jacobi_bound(), all, 1e-13 * all);
  PCDestroy(&pc);
  MatDestroy(&J);
}

// Level 1 kept as its halved stencil rows behind a shell (the matrix-free solve's, keep_level_one_as_stencil): its
// product and transposed product against PETSc's triple product P^T J P of the assembled tangent with the same
// interpolation (as a matrix), on random vectors. The springs' blocks are symmetric, so the shell takes its
// vectorised path for wholly free nodes and the masked one at the roller and clamped faces.
// Level 1's shell at positions moved by `amplitude` (0: the rest positions, where its rows are nearly all equal to
// the bit and kept once) against PETSc's product of the assembled tangent.
// The tangent J at the rest positions moved by `amplitude`, our hierarchy with LatticeGalerkin's coarse operators
// (level 1 kept as its stencil rows behind a shell when level_one_as_stencil) and PETSc's with the same
// interpolations as matrices, for the comparisons below.
struct TwoHierarchies {
  std::unique_ptr<RunResult> run;
  std::vector<double> x;
  Mat J = nullptr;
  PC ours = nullptr, matrix = nullptr;
  PetscInt levels = 0;
  std::unique_ptr<LatticeGalerkin> galerkin;  // our coarse operators (the shell's rows)
  ~TwoHierarchies() {
    PCDestroy(&ours);
    PCDestroy(&matrix);
    MatDestroy(&J);
  }
};
void build_hierarchies(double amplitude, const std::string& scene_text, bool level_one_as_stencil, TwoHierarchies* h) {
  h->run = run(scene_text, PETSC_COMM_WORLD, {}, false);
  const RunResult& r = *h->run;
  h->x = r.model.rest;
  for (int i = 0; i < r.model.local; ++i)
    for (int d = 0; d < 3; ++d)
      h->x[3 * i + d] += amplitude * std::sin(0.7 * h->x[3 * i + (d + 1) % 3] + 0.3 * d + h->x[3 * i + d]);
  ASSERT_EQ(r.forces->create_tangent(&h->J), 0);
  ASSERT_EQ(r.forces->assemble_tangent(h->x.data(), h->J), 0);
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &h->ours), 0);
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &h->matrix), 0);
  PetscInt matrix_levels = 0;
  LatticeLevels hierarchy, unused;
  ASSERT_EQ(setup_lattice_mg(r.model, r.forces->held(), h->ours, 40, &h->levels, &hierarchy, level_one_as_stencil), 0);
  ASSERT_EQ(setup_lattice_mg(r.model, r.forces->held(), h->matrix, 40, &matrix_levels, &unused, false), 0);
  ASSERT_GE(h->levels, 3);
  ASSERT_EQ(matrix_levels, h->levels);
  h->galerkin = std::make_unique<LatticeGalerkin>(r.model, r.forces->held(), std::move(hierarchy));
  if (level_one_as_stencil) h->galerkin->keep_level_one_as_stencil();
  ASSERT_EQ(h->galerkin->update(*r.forces, h->x.data(), h->ours), 0);
}

void compare_level_one_shell(double amplitude, const std::string& scene_text = scene) {
  TwoHierarchies h;
  build_hierarchies(amplitude, scene_text, true, &h);
  if (::testing::Test::HasFatalFailure()) return;
  const PetscInt levels = h.levels;
  KSP smoother;
  Mat ours, P, reference;
  ASSERT_EQ(PCMGGetSmoother(h.ours, levels - 2, &smoother), 0);  // level 1 (PCMG counts from the coarsest)
  ASSERT_EQ(KSPGetOperators(smoother, &ours, nullptr), 0);
  MatType type;
  ASSERT_EQ(MatGetType(ours, &type), 0);
  EXPECT_STREQ(type, MATSHELL);
  ASSERT_EQ(PCMGGetInterpolation(h.matrix, levels - 1, &P), 0);
  ASSERT_EQ(MatPtAP(h.J, P, MAT_INITIAL_MATRIX, PETSC_DEFAULT, &reference), 0);
  Vec u, y_ours, y_ref;
  ASSERT_EQ(MatCreateVecs(reference, &u, &y_ref), 0);
  ASSERT_EQ(VecDuplicate(y_ref, &y_ours), 0);
  PetscRandom rnd;
  ASSERT_EQ(PetscRandomCreate(PETSC_COMM_WORLD, &rnd), 0);
  for (int pass = 0; pass < 2; ++pass) {
    ASSERT_EQ(VecSetRandom(u, rnd), 0);
    ASSERT_EQ(MatMult(reference, u, y_ref), 0);
    ASSERT_EQ(pass == 0 ? MatMult(ours, u, y_ours) : MatMultTranspose(ours, u, y_ours), 0);
    PetscReal ref = 0, diff = 0;
    ASSERT_EQ(VecNorm(y_ref, NORM_2, &ref), 0);
    ASSERT_EQ(VecAXPY(y_ours, -1.0, y_ref), 0);
    ASSERT_EQ(VecNorm(y_ours, NORM_2, &diff), 0);
    EXPECT_GT(ref, 0.0);
    EXPECT_LT(diff / ref, 1e-13) << (pass == 0 ? "product" : "transposed product");
  }
  PetscRandomDestroy(&rnd);
  VecDestroy(&u);
  VecDestroy(&y_ours);
  VecDestroy(&y_ref);
  MatDestroy(&reference);
}

TEST(LatticeGalerkin, LevelOneShellEqualsPetscTripleProduct) { compare_level_one_shell(0.08); }
TEST(LatticeGalerkin, LevelOneShellAtRestEqualsPetscTripleProduct) { compare_level_one_shell(0.0); }
// At rest on a lattice of non-integer spacings (1 mm, 1.2 mm, 0.9 mm): the stream's separations come from the
// lattice offsets (ForceModel::tangent_blocks_unless), the matrix's from the positions, which differ from place
// to place in the last bits: equal to round-off.
TEST(LatticeGalerkin, LevelOneShellAtRestNonIntegerSpacing) {
  std::string mm = scene;
  mm.replace(mm.find("[1.0, 1.0, 1.0]"), 15, "[1e-3, 1.2e-3, 0.9e-3]");
  compare_level_one_shell(0.0, mm);
}

// The same box with the cell term (homogenized at nu = 0.45: cubic cells, the volumetric part alone). A cell's
// block K_ab = V0 (W'' (cof F g_a)(cof F g_b)^T + W' [F (g_a x g_b)]_x) is not symmetric (only K_ba = K_ab^T), so
// the shell's product reads each block's columns from its transposed copy; at rest (W' = 0) the rank-one part
// alone is still not symmetric.
const std::string cell_scene = R"(
title = "lattice Galerkin, cells"
[body]
molecules = [10, 7, 12]
spacing = [1.0, 1.0, 1.0]
topology = "face-diagonals"
youngs_modulus = 2.5
poisson_ratio = 0.45
[calibration]
method = "homogenized"
)" + tangent_scenes::fixes;

TEST(LatticeGalerkin, LevelOneShellWithCellsEqualsPetscTripleProduct) { compare_level_one_shell(0.08, cell_scene); }
TEST(LatticeGalerkin, LevelOneShellWithCellsAtRestEqualsPetscTripleProduct) {
  compare_level_one_shell(0.0, cell_scene);
}
// A larger box at rest: mostly interior coarse rows, whose blocks are symmetric to the bit (summed over the cells
// around a node the rank-one parts cancel in their asymmetric entries), beside the faces' asymmetric ones.
TEST(LatticeGalerkin, LevelOneShellWithCellsAtRestInteriorRows) {
  std::string big = cell_scene;
  big.replace(big.find("[10, 7, 12]"), 11, "[17, 15, 19]");
  compare_level_one_shell(0.0, big);
}
// At rest on a non-integer spacing with cells (cubic: the volumetric law alone, whose rest rows are keyed): each row is shown to the stream as its springs' inputs and the cell
// term's key (ForceModel::tangent_blocks_unless, Term::rest_row), and rows equal to their class's first are not
// computed at all; the springs' separations from the lattice offsets, the matrix's from the positions: equal to
// round-off. The roller and clamped faces make rows whose cells have held corners (masked, their own classes).
TEST(LatticeGalerkin, LevelOneShellWithCellsAtRestNonIntegerSpacing) {
  std::string mm = cell_scene;
  mm.replace(mm.find("[1.0, 1.0, 1.0]"), 15, "[1.2e-3, 1.2e-3, 1.2e-3]");
  compare_level_one_shell(0.0, mm);
}
// Every level's operator (assembled per level, as update(forces, x, pc) without the shell) against PETSc's triple
// products from the assembled tangent, with cells at rest and at an iterate: the rest rows' skip on every level.
void compare_every_level(double amplitude, const std::string& scene_text) {
  TwoHierarchies h;
  build_hierarchies(amplitude, scene_text, false, &h);
  if (::testing::Test::HasFatalFailure()) return;
  const PetscInt levels = h.levels;
  PC ours_pc = h.ours, matrix_pc = h.matrix;
  Mat fine = h.J;
  ASSERT_EQ(PetscObjectReference(reinterpret_cast<PetscObject>(fine)), 0);
  for (PetscInt l = levels - 1; l >= 1; --l) {  // PCMG's levels from the coarsest: l - 1 is one coarser
    Mat P, reference, ours;
    KSP smoother;
    ASSERT_EQ(PCMGGetInterpolation(matrix_pc, l, &P), 0);
    ASSERT_EQ(MatPtAP(fine, P, MAT_INITIAL_MATRIX, PETSC_DEFAULT, &reference), 0);
    ASSERT_EQ(PCMGGetSmoother(ours_pc, l - 1, &smoother), 0);
    ASSERT_EQ(KSPGetOperators(smoother, &ours, nullptr), 0);
    PetscInt rows_ref, rows_ours;
    MatGetSize(reference, &rows_ref, nullptr);
    MatGetSize(ours, &rows_ours, nullptr);
    ASSERT_EQ(rows_ours, rows_ref) << "level " << l - 1;
    EXPECT_LT(relative_difference(ours, reference), 1e-13) << "level " << l - 1 << ", amplitude " << amplitude;
    MatDestroy(&fine);
    fine = reference;
  }
  MatDestroy(&fine);
}
TEST(LatticeGalerkin, EveryLevelWithCellsAtRestNonIntegerSpacing) {
  std::string mm = cell_scene;
  mm.replace(mm.find("[1.0, 1.0, 1.0]"), 15, "[1.2e-3, 1.2e-3, 1.2e-3]");
  compare_every_level(0.0, mm);
}
TEST(LatticeGalerkin, EveryLevelWithCellsAtIterate) { compare_every_level(0.08, cell_scene); }
// Two kinds of cells whose springs are alike (a region of nu = 0.4 with E = 2.5 x 1.4 / 1.45: the same shear
// modulus, which the springs carry, and another kappa, which the cells carry), so that only the cell term's key
// (each cell's kind) tells the rows of the two sides apart.
TEST(LatticeGalerkin, EveryLevelWithTwoCellKindsAtRest) {
  std::string two = cell_scene;
  two.replace(two.find("[1.0, 1.0, 1.0]"), 15, "[1.2e-3, 1.2e-3, 1.2e-3]");
  two.replace(two.find("[calibration]"), 13,
              "[[body.region]]\nlo = [0.0, 0.0, 0.0]\nhi = [4.0e-3, 1.0, 1.0]\nyoungs_modulus = 2.413793103448276\npoisson_ratio = 0.4\n[calibration]");
  compare_every_level(0.0, two);
}

// Level 1's pulled nodes (summed in registers 8 at a time where the rows are one shared row's: a box's interior
// at rest) against the push form alone (-static_level_one_pull false): the same product and transposed product
// to the bit, on the faces' masked rows as well, and at an iterate, where every row differs and nothing is pulled.
void compare_pull_with_push(double amplitude, const std::string& scene_text, bool expect_pulled) {
  std::vector<Vec> results;
  std::size_t pulled[2] = {0, 0};
  Vec u = nullptr;
  for (int pull = 0; pull < 2; ++pull) {
    ASSERT_EQ(PetscOptionsSetValue(nullptr, "-static_level_one_pull", pull ? "true" : "false"), 0);
    TwoHierarchies h;
    build_hierarchies(amplitude, scene_text, true, &h);
    ASSERT_EQ(PetscOptionsClearValue(nullptr, "-static_level_one_pull"), 0);
    if (::testing::Test::HasFatalFailure()) return;
    pulled[pull] = h.galerkin->level_one_pulled();
    KSP smoother;
    Mat ours;
    ASSERT_EQ(PCMGGetSmoother(h.ours, h.levels - 2, &smoother), 0);
    ASSERT_EQ(KSPGetOperators(smoother, &ours, nullptr), 0);
    if (!u) {
      ASSERT_EQ(MatCreateVecs(ours, &u, nullptr), 0);
      PetscRandom rnd;
      ASSERT_EQ(PetscRandomCreate(PETSC_COMM_WORLD, &rnd), 0);
      ASSERT_EQ(VecSetRandom(u, rnd), 0);
      PetscRandomDestroy(&rnd);
    }
    for (int transposed = 0; transposed < 2; ++transposed) {
      Vec y;
      ASSERT_EQ(VecDuplicate(u, &y), 0);
      ASSERT_EQ(transposed ? MatMultTranspose(ours, u, y) : MatMult(ours, u, y), 0);
      results.push_back(y);
    }
  }
  unsigned long long counts[2] = {pulled[0], pulled[1]}, sums[2];
  MPI_Allreduce(counts, sums, 2, MPI_UNSIGNED_LONG_LONG, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_EQ(sums[0], 0u) << "-static_level_one_pull false pulls nothing";
  int size = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  if (expect_pulled && size == 1)  // (on more ranks the test pipeline's partitions need not leave whole rows)
    EXPECT_GT(sums[1], 0u) << "the box's interior at rest is pulled";
  else if (!expect_pulled)
    EXPECT_EQ(sums[1], 0u);
  for (int transposed = 0; transposed < 2; ++transposed) {
    const PetscScalar *push, *pull;
    PetscInt n = 0;
    ASSERT_EQ(VecGetLocalSize(u, &n), 0);
    ASSERT_EQ(VecGetArrayRead(results[transposed], &push), 0);
    ASSERT_EQ(VecGetArrayRead(results[2 + transposed], &pull), 0);
    int differ = 0, first = -1;
    for (PetscInt i = 0; i < n; ++i)
      if (std::memcmp(push + i, pull + i, sizeof(double)) != 0) differ += 1, first = first < 0 ? static_cast<int>(i) : first;
    EXPECT_EQ(differ, 0) << (transposed ? "transposed product" : "product") << ": first differing entry " << first
                         << " (" << (first >= 0 ? push[first] : 0.0) << " against " << (first >= 0 ? pull[first] : 0.0)
                         << ")";
    VecRestoreArrayRead(results[transposed], &push);
    VecRestoreArrayRead(results[2 + transposed], &pull);
  }
  for (Vec& v : results) VecDestroy(&v);
  VecDestroy(&u);
}
TEST(LatticeGalerkin, LevelOnePullEqualsPushBitForBitWithCells) {
  std::string big = cell_scene;
  big.replace(big.find("[10, 7, 12]"), 11, "[33, 27, 35]");
  compare_pull_with_push(0.0, big, true);
}
TEST(LatticeGalerkin, LevelOnePullEqualsPushBitForBitSprings) {
  std::string big = scene;
  big.replace(big.find("[10, 7, 12]"), 11, "[35, 29, 33]");
  compare_pull_with_push(0.0, big, true);
}
TEST(LatticeGalerkin, LevelOnePullAtAnIterateIsThePushForm) { compare_pull_with_push(0.08, cell_scene, false); }

// The largest eigenvalue of the Hermitian part of symbol(theta) over a grid of pi/32 a wave-vector component (the
// first in [0, pi]: theta and -theta give the same eigenvalues), four times finer than the code's.
template <class Symbol>
double largest_over_grid(Symbol symbol) {
  constexpr int kSteps = 32;
  double best = 0.0;
  for (int a = 0; a <= kSteps; ++a)
    for (int b = -kSteps + 1; b <= kSteps; ++b)
      for (int c = -kSteps + 1; c <= kSteps; ++c) {
        const double t[3] = {M_PI * a / kSteps, M_PI * b / kSteps, M_PI * c / kSteps};
        const Eigen::Matrix3cd A = symbol(t);
        const Eigen::Matrix3cd H = 0.5 * (A + A.adjoint());
        best = std::max(best, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3cd>(H, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff());
      }
  return best;
}

// The interior rows' symbol (LatticeGalerkin::symbol_bound, the finest Chebyshev interval with a term's blocks)
// against its closed form for springs at rest: each direction d of stiffness k adds k n n^T (2 - 2 cos theta.d) to
// the symbol and k n n^T twice to the diagonal; the largest eigenvalue of the Jacobi-scaled 3x3 matrix, over a
// grid four times finer than the code's. Edges k_e = 1, the faces' diagonals k_f = 0.7 (tangent_scenes::springs),
// on cells 1 x 1.3 x 0.8 (no two axes alike, so that an axis mixed up or a scaling by the wrong component shows).
TEST(LatticeGalerkin, SymbolBoundEqualsSpringsClosedForm) {
  const double h[3] = {1.0, 1.3, 0.8};
  std::string big = scene;
  big.replace(big.find("[10, 7, 12]"), 11, "[14, 13, 15]");
  big.replace(big.find("[1.0, 1.0, 1.0]"), 15, "[1.0, 1.3, 0.8]");
  TwoHierarchies run;
  build_hierarchies(0.0, big, true, &run);
  if (::testing::Test::HasFatalFailure()) return;
  std::vector<std::array<int, 3>> dirs = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  std::vector<double> k = {1.0, 1.0, 1.0};
  for (int a = 0; a < 3; ++a)
    for (int sgn : {1, -1}) {  // the faces' two diagonals in the plane normal to axis a
      std::array<int, 3> d{};
      d[(a + 1) % 3] = 1, d[(a + 2) % 3] = sgn;
      dirs.push_back(d), k.push_back(0.7);
    }
  Eigen::Matrix3d D = Eigen::Matrix3d::Zero();
  std::vector<Eigen::Matrix3d> nn;
  for (std::size_t q = 0; q < dirs.size(); ++q) {
    const Eigen::Vector3d n = Eigen::Vector3d(dirs[q][0] * h[0], dirs[q][1] * h[1], dirs[q][2] * h[2]).normalized();
    nn.push_back(k[q] * n * n.transpose());
    D += 2.0 * nn.back();
  }
  const double best = largest_over_grid([&](const double* t) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    for (std::size_t q = 0; q < dirs.size(); ++q)
      A += (2.0 - 2.0 * std::cos(t[0] * dirs[q][0] + t[1] * dirs[q][1] + t[2] * dirs[q][2])) * nn[q];
    Eigen::Matrix3cd S;
    for (int r = 0; r < 3; ++r)
      for (int q = 0; q < 3; ++q) S(r, q) = A(r, q) / std::sqrt(D(r, r) * D(q, q));
    return S;
  });
  EXPECT_NEAR(run.galerkin->symbol_bound(), best, 1e-12 * best);
  EXPECT_GT(best, 1.0);
}

// The same with the cell term (cubic cells at nu = 0.45, homogenized: springs and a volumetric part), against the
// symbol of the assembled tangent's row of the molecule nearest the box's centre (MatGetValues: not the coarse
// operators' block stream the code reads), on a grid four times finer than the code's.
TEST(LatticeGalerkin, SymbolBoundWithCellsEqualsAssembledRows) {
  std::string big = cell_scene;
  big.replace(big.find("[10, 7, 12]"), 11, "[15, 14, 16]");
  TwoHierarchies run;
  build_hierarchies(0.0, big, true, &run);
  if (::testing::Test::HasFatalFailure()) return;
  const auto& m = run.run->model;
  // The centre molecule (lattice spacing 1, molecules at integer positions from the origin).
  const double centre[3] = {7.0, 6.0, 7.0};
  double mine = 0.0;
  for (int i = 0; i < m.owned; ++i) {
    if (std::abs(m.rest[3 * i] - centre[0]) > 1e-9 || std::abs(m.rest[3 * i + 1] - centre[1]) > 1e-9 ||
        std::abs(m.rest[3 * i + 2] - centre[2]) > 1e-9)
      continue;
    std::vector<std::array<double, 9>> blocks(27);
    std::vector<bool> found(27, false);
    for (int j = 0; j < m.local; ++j) {
      int d[3];
      bool near = true;
      for (int a = 0; a < 3; ++a) {
        const double off = m.rest[3 * j + a] - m.rest[3 * i + a];
        d[a] = static_cast<int>(std::lround(off));
        near = near && std::abs(off - d[a]) < 1e-9 && std::abs(d[a]) <= 1;
      }
      if (!near) continue;
      const int slot = (d[0] + 1) + 3 * (d[1] + 1) + 9 * (d[2] + 1);
      PetscInt rows[3], cols[3];
      for (int r = 0; r < 3; ++r) rows[r] = 3 * m.block[i] + r, cols[r] = 3 * m.block[j] + r;
      ASSERT_EQ(MatGetValues(run.J, 3, rows, 3, cols, blocks[slot].data()), 0);
      found[slot] = true;
    }
    ASSERT_EQ(std::count(found.begin(), found.end(), true), 27);
    const std::array<double, 9>& dg = blocks[13];
    const double scale[3] = {1 / std::sqrt(dg[0]), 1 / std::sqrt(dg[4]), 1 / std::sqrt(dg[8])};
    mine = largest_over_grid([&](const double* t) {
      Eigen::Matrix3cd A = Eigen::Matrix3cd::Zero();
      for (int s = 0; s < 27; ++s) {
        const double phase = t[0] * (s % 3 - 1) + t[1] * (s / 3 % 3 - 1) + t[2] * (s / 9 - 1);
        for (int r = 0; r < 3; ++r)
          for (int q = 0; q < 3; ++q)
            A(r, q) += blocks[s][3 * r + q] * scale[r] * scale[q] * std::complex<double>(std::cos(phase), std::sin(phase));
      }
      return A;
    });
  }
  double best = 0.0;
  MPI_Allreduce(&mine, &best, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  ASSERT_GT(best, 2.0);  // the cells' volumetric part raises it above the springs' 2
  EXPECT_NEAR(run.galerkin->symbol_bound(), best, 1e-12 * best);
}
