// The matrix-free static solver (solver.operator = "matrix-free"; src/solvers/matrix_free.hpp) against the
// assembled tangent it replaces, on box lattices with roller and clamped faces and every lattice term present
// (springs only; the cell term at nu = 0.45; fibres; the viscoelastic tangent factor of a quasi-static step):
//  - the shell's MatMult and diagonal equal the assembled matrix's at deformed positions, to round-off;
//  - the lattice multigrid's coarse operators from the force model's block stream equal those from the
//    assembled matrix (LatticeGalerkin::update both ways), to round-off;
//  - the finest level's Gershgorin bound from the block stream (ForceModel::jacobi_gershgorin) equals the
//    assembled matrix's row sums, and is refused (not exact) when a term adds blocks;
//  - the finest interpolation as a shell (lattice_interpolation.hpp) applies the AIJ one's products, transposed
//    products and products added in place or not, to round-off;
//  - a static tension test gives the same displacements and elongation as the assembled solve, to the
//    solve's tolerance, with the Newton and Krylov counts printed.
// Run at 1, 2 and 3 ranks: ghosts of the shell's input and coarse rows owned elsewhere travel.
#include <gtest/gtest.h>

#include <petscksp.h>

#include <malloc.h>

#include <cmath>
#include <cstdio>

#include "src/physics/force_model.hpp"
#include "src/solvers/lattice_galerkin.hpp"
#include "src/solvers/lattice_interpolation.hpp"
#include "src/solvers/lattice_mg.hpp"
#include "src/solvers/matrix_free.hpp"
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

const std::string fibres = R"(
title = "matrix-free: fibres"
[body]
molecules = [8, 9, 10]
spacing = [1e-3, 1e-3, 1e-3]
topology = "face-diagonals"
youngs_modulus = 1e4
poisson_ratio = 0.3
[body.fibres]
direction = [1.0, 2.0, 2.0]
youngs_modulus = 5e4
poisson_ratio = 0.3
shear_modulus = 1e4
[calibration]
method = "homogenized"
)" + fixes;

// The rest positions moved by a smooth displacement (each molecule's from its own rest position, so ghosts agree
// with their owners and every rank count sees the same configuration).
std::vector<double> deformed(const RunResult& r, double amplitude) {
  std::vector<double> x(r.model.rest);
  double h = 1e300;  // the smallest spacing: the displacement scales with it
  for (int d = 0; d < 3; ++d) h = std::min(h, r.scene.body.spacing[d]);
  for (int i = 0; i < r.model.local; ++i)
    for (int d = 0; d < 3; ++d)
      x[3 * i + d] += amplitude * h * std::sin(0.7 * x[3 * i + (d + 1) % 3] / h + 0.3 * d + x[3 * i + d] / h);
  return x;
}

double norm_difference(Vec a, Vec b) {
  Vec d;
  PetscReal diff = 0, ref = 0;
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(a, &d));
  PetscCallAbort(PETSC_COMM_WORLD, VecWAXPY(d, -1.0, b, a));
  PetscCallAbort(PETSC_COMM_WORLD, VecNorm(d, NORM_2, &diff));
  PetscCallAbort(PETSC_COMM_WORLD, VecNorm(b, NORM_2, &ref));
  PetscCallAbort(PETSC_COMM_WORLD, VecDestroy(&d));
  return diff / ref;
}

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

// B's product with u and its diagonal against A's, relative to A's (A the reference); the product is not zero.
void expect_same_products(Mat A, Mat B, Vec u, double tol, const std::string& what) {
  Vec ya, yb, da, db;
  ASSERT_EQ(MatCreateVecs(A, nullptr, &ya), 0);
  VecDuplicate(ya, &yb), VecDuplicate(ya, &da), VecDuplicate(ya, &db);
  ASSERT_EQ(MatMult(A, u, ya), 0);
  ASSERT_EQ(MatMult(B, u, yb), 0);
  ASSERT_EQ(MatGetDiagonal(A, da), 0);
  ASSERT_EQ(MatGetDiagonal(B, db), 0);
  EXPECT_LT(norm_difference(yb, ya), tol) << what;
  EXPECT_LT(norm_difference(db, da), tol) << what;
  PetscReal size = 0;
  VecNorm(ya, NORM_2, &size);
  EXPECT_GT(size, 0.0);
  for (Vec* v : {&ya, &yb, &da, &db}) VecDestroy(v);
}

// Shell against assembled (MatMult, diagonal) and stream against matrix (coarse operators) at two deformations.
void compare_operators(const std::string& text, bool viscoelastic_step) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  if (viscoelastic_step) r->forces->begin_step(0.1);  // the history's tangent factor of a 0.1 s step
  Mat A, S;
  ASSERT_EQ(r->forces->create_tangent(&A), 0);
  MatrixFreeTangent shell(r->model, *r->forces);
  ASSERT_EQ(shell.create(&S), 0);
  PC by_matrix, by_stream;
  PetscInt levels = 0, levels2 = 0;
  LatticeLevels h1, h2;
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &by_matrix), 0);
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &by_stream), 0);
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), by_matrix, 40, &levels, &h1), 0);
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), by_stream, 40, &levels2, &h2), 0);
  ASSERT_GE(levels, 3);
  LatticeGalerkin g1(r->model, r->forces->held(), std::move(h1)), g2(r->model, r->forces->held(), std::move(h2));
  for (double amplitude : {0.03, 0.08}) {
    const std::vector<double> x = deformed(*r, amplitude);
    ASSERT_EQ(r->forces->assemble_tangent(x.data(), A), 0);
    ASSERT_EQ(shell.set_positions(x.data(), S), 0);
    bool stencil = false;
    ASSERT_EQ(g2.applies(*r->forces, x.data(), &stencil), 0);
    EXPECT_TRUE(stencil);
    Vec u;
    ASSERT_EQ(MatCreateVecs(A, &u, nullptr), 0);
    PetscScalar* pu;
    VecGetArray(u, &pu);
    for (int i = 0; i < r->model.owned; ++i)
      for (int d = 0; d < 3; ++d) pu[3 * i + d] = std::sin(0.37 * static_cast<double>(r->model.id[i]) + 1.3 * d);
    VecRestoreArray(u, &pu);
    expect_same_products(A, S, u, 1e-14, text + " amplitude " + std::to_string(amplitude));
    VecDestroy(&u);

    ASSERT_EQ(g1.update(A, by_matrix), 0);
    ASSERT_EQ(g2.update(*r->forces, x.data(), by_stream), 0);
    for (PetscInt l = 0; l + 1 < levels; ++l) {  // the coarse levels (PCMG numbers the finest levels - 1)
      KSP k1, k2;
      Mat c1, c2;
      PCMGGetSmoother(by_matrix, l, &k1), PCMGGetSmoother(by_stream, l, &k2);
      KSPGetOperators(k1, &c1, nullptr), KSPGetOperators(k2, &c2, nullptr);
      EXPECT_LT(relative_difference(c2, c1), 1e-13) << text << " level " << l << " amplitude " << amplitude;
    }
  }
  PCDestroy(&by_matrix), PCDestroy(&by_stream);
  MatDestroy(&A), MatDestroy(&S);
}

// Level 1 as a shell over its stencil rows (LatticeGalerkin::keep_level_one_as_stencil, the matrix-free solve's
// default): its products and diagonal equal those of the CSR level 1 summed from the assembled matrix, and the
// coarser levels summed from those rows equal the matrix's, to round-off.
void compare_stencil_level(const std::string& text) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  Mat A;
  ASSERT_EQ(r->forces->create_tangent(&A), 0);
  PC by_matrix, by_stencil;
  PetscInt levels = 0, levels2 = 0;
  LatticeLevels h1, h2;
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &by_matrix), 0);
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &by_stencil), 0);
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), by_matrix, 40, &levels, &h1), 0);
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), by_stencil, 40, &levels2, &h2), 0);
  ASSERT_GE(levels, 3);
  LatticeGalerkin g1(r->model, r->forces->held(), std::move(h1)), g2(r->model, r->forces->held(), std::move(h2));
  g2.keep_level_one_as_stencil();
  for (double amplitude : {0.03, 0.08}) {  // the second update refills the same shell
    const std::vector<double> x = deformed(*r, amplitude);
    ASSERT_EQ(r->forces->assemble_tangent(x.data(), A), 0);
    ASSERT_EQ(g1.update(A, by_matrix), 0);
    ASSERT_EQ(g2.update(*r->forces, x.data(), by_stencil), 0);
    for (PetscInt l = 0; l + 1 < levels; ++l) {  // PCMG's numbering: levels - 2 is our level 1
      KSP k1, k2;
      Mat c1, c2;
      PCMGGetSmoother(by_matrix, l, &k1), PCMGGetSmoother(by_stencil, l, &k2);
      KSPGetOperators(k1, &c1, nullptr), KSPGetOperators(k2, &c2, nullptr);
      PetscBool shell = PETSC_FALSE;
      PetscObjectTypeCompare(reinterpret_cast<PetscObject>(c2), MATSHELL, &shell);
      EXPECT_EQ(shell == PETSC_TRUE, l == levels - 2) << "level " << l;
      if (!shell) {
        EXPECT_LT(relative_difference(c2, c1), 1e-13) << text << " level " << l << " amplitude " << amplitude;
        continue;
      }
      Vec u;
      ASSERT_EQ(MatCreateVecs(c1, &u, nullptr), 0);
      PetscInt lo, hi;
      VecGetOwnershipRange(u, &lo, &hi);
      PetscScalar* pu;
      VecGetArray(u, &pu);
      for (PetscInt i = lo; i < hi; ++i) pu[i - lo] = std::sin(0.37 * static_cast<double>(i) + 0.2);
      VecRestoreArray(u, &pu);
      expect_same_products(c1, c2, u, 1e-13, text + " level 1 amplitude " + std::to_string(amplitude));
      VecDestroy(&u);
    }
  }
  PCDestroy(&by_matrix), PCDestroy(&by_stencil);
  MatDestroy(&A);
}

// 1 + sum_j!=i |A_ij| / A_ii, largest over the assembled matrix's rows (held rows: the identity's, 1).
double matrix_gershgorin(Mat A) {
  PetscInt lo, hi;
  PetscCallAbort(PETSC_COMM_WORLD, MatGetOwnershipRange(A, &lo, &hi));
  double bound = 1.0;
  for (PetscInt r = lo; r < hi; ++r) {
    PetscInt n;
    const PetscInt* cols;
    const PetscScalar* v;
    PetscCallAbort(PETSC_COMM_WORLD, MatGetRow(A, r, &n, &cols, &v));
    double diag = 0, off = 0;
    for (PetscInt e = 0; e < n; ++e) (cols[e] == r ? diag : off) += cols[e] == r ? v[e] : std::abs(v[e]);
    bound = std::max(bound, 1.0 + off / diag);
    PetscCallAbort(PETSC_COMM_WORLD, MatRestoreRow(A, r, &n, &cols, &v));
  }
  double all = 0;
  MPI_Allreduce(&bound, &all, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  return all;
}

void compare_gershgorin(const std::string& text, bool expect_exact) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  Mat A;
  ASSERT_EQ(r->forces->create_tangent(&A), 0);
  for (double amplitude : {0.03, 0.08}) {
    const std::vector<double> x = deformed(*r, amplitude);
    ASSERT_EQ(r->forces->assemble_tangent(x.data(), A), 0);
    double bound = 0;
    bool exact = false;
    ASSERT_EQ(r->forces->jacobi_gershgorin(x.data(), &bound, &exact), 0);
    EXPECT_EQ(exact, expect_exact) << text;
    if (!expect_exact) continue;
    const double reference = matrix_gershgorin(A);
    EXPECT_GT(reference, 1.5);  // the rows are coupled: not the identity's bound
    EXPECT_NEAR(bound / reference, 1.0, 1e-13) << text << " amplitude " << amplitude;
  }
  MatDestroy(&A);
}

// A vector of P's column (coarse) or row (fine) layout with smooth values from the global index.
Vec smooth_vector(Mat P, bool columns, double phase) {
  Vec v;
  if (columns) PetscCallAbort(PETSC_COMM_WORLD, MatCreateVecs(P, &v, nullptr));
  else PetscCallAbort(PETSC_COMM_WORLD, MatCreateVecs(P, nullptr, &v));
  PetscInt lo, hi;
  PetscScalar* p;
  VecGetOwnershipRange(v, &lo, &hi);
  VecGetArray(v, &p);
  for (PetscInt i = lo; i < hi; ++i) p[i - lo] = std::sin(0.37 * static_cast<double>(i) + phase);
  VecRestoreArray(v, &p);
  return v;
}

// The finest interpolation as a shell against setup_lattice_mg's AIJ matrix: P c, f + P c (in place and into
// another vector: PCMG's MatInterpolateAdd) and P^T f (its restriction).
void compare_interpolation(const std::string& text) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  PC by_matrix, by_shell;
  PetscInt levels = 0, levels2 = 0;
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &by_matrix), 0);
  ASSERT_EQ(PCCreate(PETSC_COMM_WORLD, &by_shell), 0);
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), by_matrix, 40, &levels, nullptr, false), 0);
  ASSERT_EQ(setup_lattice_mg(r->model, r->forces->held(), by_shell, 40, &levels2, nullptr, true), 0);
  ASSERT_GE(levels, 3);
  ASSERT_EQ(levels, levels2);
  for (PetscInt l = 1; l < levels; ++l) {
    Mat A, S;
    ASSERT_EQ(PCMGGetInterpolation(by_matrix, l, &A), 0);
    ASSERT_EQ(PCMGGetInterpolation(by_shell, l, &S), 0);
    PetscBool shell = PETSC_FALSE;
    PetscObjectTypeCompare(reinterpret_cast<PetscObject>(S), MATSHELL, &shell);
    EXPECT_EQ(shell == PETSC_TRUE, l == levels - 1) << "only the finest interpolation is a shell";
    if (!shell) continue;
    Vec c = smooth_vector(A, true, 0.2), f = smooth_vector(A, false, 1.1), ya, ys, ys2, za, zs;
    MatCreateVecs(A, nullptr, &ya), VecDuplicate(ya, &ys), VecDuplicate(ya, &ys2);
    MatCreateVecs(A, &za, nullptr), VecDuplicate(za, &zs);
    ASSERT_EQ(MatMult(A, c, ya), 0);
    ASSERT_EQ(MatMult(S, c, ys), 0);
    EXPECT_LT(norm_difference(ys, ya), 1e-14) << text << ": P c";
    ASSERT_EQ(MatMultAdd(A, c, f, ya), 0);
    ASSERT_EQ(MatMultAdd(S, c, f, ys), 0);
    EXPECT_LT(norm_difference(ys, ya), 1e-14) << text << ": f + P c";
    VecCopy(f, ys2);
    ASSERT_EQ(MatMultAdd(S, c, ys2, ys2), 0);
    EXPECT_LT(norm_difference(ys2, ya), 1e-14) << text << ": f + P c in place";
    ASSERT_EQ(MatMultTranspose(A, f, za), 0);
    ASSERT_EQ(MatMultTranspose(S, f, zs), 0);
    EXPECT_LT(norm_difference(zs, za), 1e-14) << text << ": P^T f";
    PetscReal size = 0;
    VecNorm(za, NORM_2, &size);
    EXPECT_GT(size, 0.0);
    for (Vec* v : {&c, &f, &ya, &ys, &ys2, &za, &zs}) VecDestroy(v);
  }
  PCDestroy(&by_matrix), PCDestroy(&by_shell);
}

// ForceModel::tangent_diagonal (the shell's MatGetDiagonal: the fine smoother's D^-1) against the plain sum it
// replaced: every connection in order, its diagonal terms k (g + (1 - g) d_r^2 / |d|^2) added to its owned ends,
// held components 1. Equal to the bit (the vectorized terms do the same operations in the same order); the
// same sum with d_r^2 rounded first already differs.
void compare_diagonal_to_the_bit(const std::string& text) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  const LocalModel& m = r->model;
  const int n = m.owned;
  for (double amplitude : {0.0, 0.08}) {
    const std::vector<double> x = deformed(*r, amplitude);
    std::vector<double> diag(3 * n, -1.0), expected(3 * n, 0.0);
    ASSERT_EQ(r->forces->tangent_diagonal(x.data(), diag.data()), 0);
    for (int c = 0; c < m.connections(); ++c) {
      const int a = m.end_a[c], b = m.end_b[c];
      double d[3];
      for (int k = 0; k < 3; ++k) d[k] = x[3 * b + k] - x[3 * a + k];
      const double len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2], geo = 1.0 - m.l0(c) / std::sqrt(len2);
      for (int k = 0; k < 3; ++k) {
        const double K = m.k(c) * (geo + (1.0 - geo) * d[k] * d[k] / len2);
        if (a < n) expected[3 * a + k] += K;
        if (b < n) expected[3 * b + k] += K;
      }
    }
    for (int h : r->forces->held_owned()) expected[h] = 1.0;
    int positive = 0;
    for (int q = 0; q < 3 * n; ++q) {
      ASSERT_EQ(diag[q], expected[q]) << text << " component " << q << " amplitude " << amplitude;
      positive += diag[q] > 0.0;
    }
    EXPECT_EQ(positive, 3 * n);
  }
}

}  // namespace

// ForceModel::release_block_rows gives the connections by row back to malloc, not only empties them: the bytes
// in use (mallinfo2, heap and mapped) fall by at least one int per owned end of every connection (row_conns).
// Emptied with `= {}` they kept their capacity through the static solve (35 MB a rank at 10^6).
TEST(MatrixFree, ReleaseBlockRowsFreesThem) {
  auto r = run(springs, PETSC_COMM_WORLD, {}, false);
  const LocalModel& m = r->model;
  std::size_t ends = 0;
  for (int c = 0; c < m.connections(); ++c) ends += (m.end_a[c] < m.owned) + (m.end_b[c] < m.owned);
  ASSERT_GT(ends, 0u);
  const std::vector<double> x = deformed(*r, 0.0);
  auto nothing = [](void*, int, int, const double*) -> PetscErrorCode { return 0; };
  ASSERT_EQ(r->forces->tangent_blocks(x.data(), nothing, nullptr), 0);  // builds the rows
  auto in_use = [] {
    const struct mallinfo2 info = mallinfo2();
    return info.uordblks + info.hblkhd;
  };
  const std::size_t before = in_use();
  r->forces->release_block_rows();
  const std::size_t after = in_use();
  EXPECT_GE(before, after + sizeof(int) * ends) << "freed " << before - after << " B of " << sizeof(int) * ends;
}

TEST(MatrixFree, InterpolationShellSprings) { compare_interpolation(springs); }
TEST(MatrixFree, InterpolationShellCellTerm) { compare_interpolation(cells); }

TEST(MatrixFree, DiagonalToTheBitSprings) { compare_diagonal_to_the_bit(springs); }
TEST(MatrixFree, GershgorinBoundSprings) { compare_gershgorin(springs, true); }
TEST(MatrixFree, GershgorinBoundRefusedWithCellTerm) { compare_gershgorin(cells, false); }

TEST(MatrixFree, ShellEqualsAssembledSprings) { compare_operators(springs, false); }
TEST(MatrixFree, ShellEqualsAssembledCellTerm) { compare_operators(cells, false); }
// Cubic cells at nu > 1/4: the cell term is its volumetric part alone, whose blocks are in closed form.
// Their product keeps no state (F recomputed from the positions on every product), the other cells' F and
// mu J^(-2/3) per cell (10 doubles a cell): the comparison above runs the former.
const Term* cell_term_of(const RunResult& r) {
  for (const auto& t : r.forces->terms())
    if (t->has_tangent_state()) return t.get();
  return nullptr;
}
TEST(MatrixFree, ShellEqualsAssembledVolumetricCells) {
  std::string cubic = cells;
  cubic.replace(cubic.find("[1e-3, 1.2e-3, 0.9e-3]"), 22, "[1e-3, 1e-3, 1e-3]");
  compare_operators(cubic, false);
  const std::string* texts[2] = {&cubic, &cells};
  for (const std::string* text : texts) {
    auto r = run(*text, PETSC_COMM_WORLD, {}, false);
    const Term* cell = cell_term_of(*r);
    ASSERT_NE(cell, nullptr);
    if (text == &cubic) EXPECT_EQ(cell->tangent_state_size(), 1u);
    else EXPECT_GT(cell->tangent_state_size(), 1u);
    std::vector<double> state(cell->tangent_state_size());
    cell->tangent_state(r->model.rest.data(), state.data());
    EXPECT_EQ(state[0], text == &cubic ? -1.0 : 10.0);  // -1: volumetric at the rest positions (the F = I form)
    std::vector<double> x = r->model.rest;
    if (!x.empty()) x[0] += 1e-9;  // one coordinate off rest: the general form
    cell->tangent_state(x.data(), state.data());
    if (!x.empty()) EXPECT_EQ(state[0], text == &cubic ? 0.0 : 10.0);
  }
}
// The shell's product runs the cell term's blocks inside the springs' sweep, each once the springs' part of its
// rows is final (MatrixFreeTangent::mult): every component equal, to the bit, to the two passes it replaces
// (the springs' product whole, then the term's from its state), for the volumetric-only cells (no state) and
// the others (F and mu J^(-2/3) a cell), with roller and clamped rows.
TEST(MatrixFree, CellProductInTheSpringsSweepEqualsTwoPasses) {
  std::string cubic = cells;
  cubic.replace(cubic.find("[1e-3, 1.2e-3, 0.9e-3]"), 22, "[1e-3, 1e-3, 1e-3]");
  cubic.replace(cubic.find("[9, 7, 11]"), 10, "[21, 9, 13]");  // row blocks of 20 cells and gathered ones
  const std::string* texts[2] = {&cubic, &cells};
  for (const std::string* text : texts) {
    auto r = run(*text, PETSC_COMM_WORLD, {}, false);
    const Term* cell = cell_term_of(*r);
    ASSERT_NE(cell, nullptr);
    ASSERT_TRUE(cell->tangent_by_rows());
    MatrixFreeTangent shell(r->model, *r->forces);
    Mat S;
    ASSERT_EQ(shell.create(&S), 0);
    const std::vector<double> x = deformed(*r, 0.05);
    ASSERT_EQ(shell.set_positions(x.data(), S), 0);
    // u by molecule id, so that the ghosts' values are known here too.
    auto value = [&](int i, int d) { return std::sin(0.37 * static_cast<double>(r->model.id[i]) + 1.3 * d); };
    Vec u, y;
    ASSERT_EQ(MatCreateVecs(S, &u, &y), 0);
    PetscScalar* pu;
    VecGetArray(u, &pu);
    for (int i = 0; i < r->model.owned; ++i)
      for (int d = 0; d < 3; ++d) pu[3 * i + d] = value(i, d);
    VecRestoreArray(u, &pu);
    ASSERT_EQ(MatMult(S, u, y), 0);
    // The two passes: the springs (held rows the identity's), then the term, the held rows put back.
    std::vector<double> w(3 * static_cast<std::size_t>(r->model.local)), two(3 * static_cast<std::size_t>(r->model.owned));
    for (int i = 0; i < r->model.local; ++i)
      for (int d = 0; d < 3; ++d) w[3 * i + d] = value(i, d);
    std::vector<double> state(cell->tangent_state_size());
    cell->tangent_state(x.data(), state.data());
    ASSERT_EQ(r->forces->apply_tangent(x.data(), w.data(), two.data(), true), 0);
    const std::vector<double> identity = two;
    cell->apply_tangent_state(x.data(), state.data(), w.data(), two.data());
    for (int h : r->forces->held_owned()) two[h] = identity[h];
    const PetscScalar* py;
    VecGetArrayRead(y, &py);
    int differ = 0, changed = 0;
    for (std::size_t q = 0; q < two.size(); ++q) differ += py[q] != two[q], changed += two[q] != identity[q];
    VecRestoreArrayRead(y, &py);
    EXPECT_EQ(differ, 0) << "components of the product that differ from the two passes' (of " << two.size() << ")";
    EXPECT_GT(changed, static_cast<int>(two.size()) / 2);  // the term's part is there
    VecDestroy(&u), VecDestroy(&y), MatDestroy(&S);
  }
}
TEST(MatrixFree, ShellEqualsAssembledFibres) { compare_operators(fibres, false); }
TEST(MatrixFree, ShellEqualsAssembledViscoelasticStep) { compare_operators(visco, true); }
TEST(MatrixFree, StencilLevelOneSprings) { compare_stencil_level(springs); }
TEST(MatrixFree, StencilLevelOneCellTerm) { compare_stencil_level(cells); }

// A static tension test both ways: displacements and elongation to the solve's tolerance.
// Above 1,000 molecules: smaller lattices get GAMG, and the assembled tangent with a note.
void compare_static(const std::string& text, const std::string& molecules, const std::string& load) {
  const std::string scene = text + load;
  auto a = run(scene, PETSC_COMM_WORLD,
               {"solver.tolerance=1e-10", "body.molecules=" + molecules, "solver.operator=assembled"});
  auto m = run(scene, PETSC_COMM_WORLD,
               {"solver.tolerance=1e-10", "body.molecules=" + molecules, "solver.operator=matrix-free"});
  ASSERT_TRUE(a->report.converged && m->report.converged);
  EXPECT_EQ(m->report.note.find("matrix-free not used"), std::string::npos) << m->report.note;
  ASSERT_TRUE(a->measured.elongation && m->measured.elongation);
  EXPECT_NEAR(*m->measured.elongation / *a->measured.elongation, 1.0, 1e-8);
  double diff = 0, size = 0;
  for (int i = 0; i < 3 * a->model.owned; ++i) {
    const double ua = a->state->x.array()[i] - a->model.rest[i], um = m->state->x.array()[i] - m->model.rest[i];
    diff = std::max(diff, std::abs(um - ua)), size = std::max(size, std::abs(ua));
  }
  double all[2] = {diff, size}, out[2];
  MPI_Allreduce(all, out, 2, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  EXPECT_LT(out[0], 1e-8 * out[1]) << text;
  EXPECT_GT(out[1], 0.0);
  PetscPrintf(PETSC_COMM_WORLD, "%s: assembled %ld Newton / %ld Krylov, matrix-free %ld Newton / %ld Krylov; "
              "max |du| / max |u| = %.2e\n", a->scene.title.c_str(), a->report.iterations, a->report.linear_iterations,
              m->report.iterations, m->report.linear_iterations, out[0] / out[1]);
}

TEST(MatrixFree, StaticTensionSprings) {
  compare_static(springs, "[14, 12, 16]", "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1.5]\n");
}
TEST(MatrixFree, StaticTensionCellTerm) {
  compare_static(cells, "[12, 11, 14]", "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-4]\n");
}

// solver.operator not given: matrix-free on a lattice with the lattice multigrid, springs only or with the cell
// term (its own product, Term::tangent_state_fast), assembled with fibres (that product is not cheap there), with
// another term (the viscoelastic springs) or where the multigrid does not apply (840 molecules), and no note
// either way: each the named operator's answer bit for bit.
void expect_default_is(const std::string& scene, const std::vector<std::string>& set, const std::string& named) {
  auto d = run(scene, PETSC_COMM_WORLD, set);
  std::vector<std::string> with = set;
  with.push_back("solver.operator=" + named);
  auto n = run(scene, PETSC_COMM_WORLD, with);
  ASSERT_TRUE(d->report.converged && n->report.converged);
  EXPECT_EQ(d->report.note.find("matrix-free not used"), std::string::npos) << d->report.note;
  ASSERT_TRUE(d->measured.elongation && n->measured.elongation);
  EXPECT_EQ(*d->measured.elongation, *n->measured.elongation) << named;
  EXPECT_EQ(d->report.linear_iterations, n->report.linear_iterations) << named;
  EXPECT_EQ(d->report.residual, n->report.residual) << named;
}

TEST(MatrixFree, DefaultOperator) {
  const std::string pull = "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1.5]\n";
  expect_default_is(springs + pull, {"body.molecules=[14, 12, 16]"}, "matrix-free");
  expect_default_is(springs + pull, {}, "assembled");
  expect_default_is(cells + "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-4]\n", {"body.molecules=[12, 11, 14]"},
                    "matrix-free");
  expect_default_is(fibres + "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1e-4]\n", {"body.molecules=[12, 11, 14]"},
                    "assembled");
  expect_default_is(visco + pull, {"body.molecules=[14, 12, 16]"}, "assembled");
  // The two operators differ at round-off (other summation order): the default is not the assembled one here.
  auto a = run(springs + pull, PETSC_COMM_WORLD, {"body.molecules=[14, 12, 16]", "solver.operator=assembled"});
  auto d = run(springs + pull, PETSC_COMM_WORLD, {"body.molecules=[14, 12, 16]"});
  ASSERT_TRUE(a->measured.elongation && d->measured.elongation);
  EXPECT_TRUE(*a->measured.elongation != *d->measured.elongation || a->report.residual != d->report.residual);
}

// Where the lattice multigrid does not apply (840 molecules: GAMG), matrix-free says so and the assembled
// tangent solves: the same answer as asking for it.
TEST(MatrixFree, NotApplicableFallsBackWithANote) {
  const std::string scene = springs + "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1.5]\n";
  auto a = run(scene, PETSC_COMM_WORLD, {"solver.operator=assembled"});
  auto m = run(scene, PETSC_COMM_WORLD, {"solver.operator=matrix-free"});
  EXPECT_NE(m->report.note.find("matrix-free not used"), std::string::npos) << m->report.note;
  ASSERT_TRUE(a->measured.elongation && m->measured.elongation);
  EXPECT_EQ(*m->measured.elongation, *a->measured.elongation);
}

// Where the lattice multigrid applies but the matrix-free tangent does not (-snes_lag_preconditioner: our reuse is
// off), the finest interpolation is made again as a matrix for PCMG's products: the assembled solve's answer, bit
// for bit.
TEST(MatrixFree, LagGivenFallsBackToTheAssembledSolve) {
  const std::string scene = springs + "[[load]]\nface = \"z+\"\nforce = [0.0, 0.0, 1.5]\n";
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-snes_lag_preconditioner", "1"), 0);
  auto a = run(scene, PETSC_COMM_WORLD, {"body.molecules=[14, 12, 16]", "solver.operator=assembled"});
  auto m = run(scene, PETSC_COMM_WORLD, {"body.molecules=[14, 12, 16]", "solver.operator=matrix-free"});
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-snes_lag_preconditioner"), 0);
  EXPECT_NE(m->report.note.find("matrix-free not used"), std::string::npos) << m->report.note;
  ASSERT_TRUE(a->report.converged && m->report.converged);
  ASSERT_TRUE(a->measured.elongation && m->measured.elongation);
  EXPECT_EQ(*m->measured.elongation, *a->measured.elongation);
  EXPECT_EQ(m->report.linear_iterations, a->report.linear_iterations);
}
