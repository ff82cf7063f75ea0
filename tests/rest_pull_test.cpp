// The rest tangent's springs in the pull form (src/physics/rest_pull.hpp, issue 18) against the push form
// (SpringKernel::rest_tangent without it) and against the assembled tangent at the rest positions, on boxes with a
// roller and a clamped face, and the bench_poisson block (homogenized: other types at the faces; clamped base):
//  - the product equals the push form's to 1e-14 relative (the same springs summed in another order), at random
//    u with random ghost values; every row of each kind (full, masked, listed) appears on some rank;
//  - the finest level's matrix (RestTangent with the pull form) equals the assembled tangent at rest to 1e-13;
//  - the rows go to final_rows in order, each once, all of them;
//  - the work is by rows: the kinds' counts add up to the owned rows, and the listed rows' springs are at most the
//    springs of those rows (no segment times reach).
// Run at 1, 2 and 3 ranks: the partition's cut makes listed rows, and the ghosts are read.
#include <gtest/gtest.h>

#include <petscksp.h>

#include <cmath>
#include <random>

#include "src/physics/force_model.hpp"
#include "src/physics/rest_pull.hpp"
#include "src/solvers/rest_tangent.hpp"
#include "tests/pipeline.hpp"
#include "tests/tangent_scenes.hpp"

using namespace tissue;
using tissue::test_pipeline::run;

namespace {

std::string with(std::string text, const std::string& from, const std::string& to) {
  return text.replace(text.find(from), from.size(), to);
}
const std::string springs = with(tangent_scenes::springs, "[10, 7, 12]", "[16, 14, 18]");
const std::string springs_mm = with(springs, "[1.0, 1.0, 1.0]", "[1e-3, 1.2e-3, 0.9e-3]");
const std::string body_diagonals =
    with(with(springs, "face-diagonals", "body-diagonals"), "face = 0.7 }", "face = 0.7, body = 0.4 }");
const std::string rectangular = with(springs, "face-diagonals", "rectangular");
// run_scripts/scenes/poisson_block.toml at 16 x 14 x 18 (nu = 1/4: springs only).
const std::string poisson_block = R"(
title = "rest pull: bench_poisson block"
[body]
molecules = [16, 14, 18]
spacing = [0.001, 0.001, 0.001]
topology = "face-diagonals"
youngs_modulus = 1.0e7
density = 1000.0
[calibration]
method = "homogenized"
[[fix]]
face = "z-"
[solver]
kind = "static"
)";

int ranks() {
  int size = 1;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  return size;
}
long sum(long v) {
  long all = 0;
  MPI_Allreduce(&v, &all, 1, MPI_LONG, MPI_SUM, PETSC_COMM_WORLD);
  return all;
}
double largest(double v) {
  double all = 0;
  MPI_Allreduce(&v, &all, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD);
  return all;
}

// The pull form against the push form on this rank's rows, at u random on every local row (ghosts too).
void compare_forms(const std::string& text, bool expect_listed) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  const LocalModel& m = r->model;
  const SpringKernel& kernel = r->forces->kernel();
  RestStencil push = kernel.rest_stencil();
  ASSERT_TRUE(largest(push.exact ? 0.0 : 1.0) == 0.0) << text;
  // Every rank of these boxes has the pattern on most of its rows (a rank may still keep the push form: a small
  // rank of a partition into bricks of two row lengths).
  std::unique_ptr<RestPull> made = RestPull::make(m);
  EXPECT_GE(sum(made ? 1 : 0), std::max(1, ranks() - 1)) << text;
  const long counts[3] = {made ? made->rows(RestPull::kFull) : 0, made ? made->rows(RestPull::kMasked) : 0,
                          made ? made->rows(RestPull::kListed) : 0};
  if (made) EXPECT_EQ(counts[0] + counts[1] + counts[2], m.owned);
  // By rows: a listed row has at most the pattern's springs both ways and a few more (a lattice: 2 x 13).
  if (made) EXPECT_LE(made->listed_springs(), 26 * counts[2]);
  EXPECT_GT(sum(counts[0]), 0);
  EXPECT_GT(sum(counts[1]), 0);
  if (expect_listed) EXPECT_GT(sum(counts[2]), 0);
  PetscPrintf(PETSC_COMM_WORLD, "%s: %ld full, %ld masked, %ld listed rows (all ranks)\n", r->scene.title.c_str(),
              sum(counts[0]), sum(counts[1]), sum(counts[2]));
  RestStencil pulled = push;
  pulled.pull = std::move(made);
  std::mt19937_64 random(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<double> u(3 * static_cast<std::size_t>(m.local)), a(3 * static_cast<std::size_t>(m.owned)),
      b(3 * static_cast<std::size_t>(m.owned), 1e300), ghost(3 * static_cast<std::size_t>(m.local - m.owned));
  for (int trial = 0; trial < 3; ++trial) {
    for (double& v : u) v = uniform(random);
    kernel.rest_tangent(push, u.data(), a.data(), ghost.data());
    kernel.rest_tangent(pulled, u.data(), b.data(), ghost.data());
    double diff = 0, size = 0;
    for (std::size_t q = 0; q < a.size(); ++q) diff = std::max(diff, std::abs(b[q] - a[q])), size = std::max(size, std::abs(a[q]));
    diff = largest(diff), size = largest(size);
    EXPECT_GT(size, 0.0);
    EXPECT_LT(diff, 1e-14 * size) << text;
  }
  // final_rows: in order, each row once, all of them.
  struct Seen {
    int next = 0;
    bool ordered = true;
  } seen;
  kernel.rest_tangent(pulled, u.data(), b.data(), ghost.data(), [](void* p, int begin, int end) {
    Seen& s = *static_cast<Seen*>(p);
    s.ordered = s.ordered && begin == s.next && end > begin;
    s.next = end;
  }, &seen);
  EXPECT_TRUE(seen.ordered);
  EXPECT_EQ(seen.next, m.owned);
}

// The finest level's matrix with the pull form against the assembled tangent at the rest positions (a copy: the
// general path), held rows and columns included.
void compare_assembled(const std::string& text) {
  auto r = run(text, PETSC_COMM_WORLD, {}, false);
  std::vector<double> scratch(3 * static_cast<std::size_t>(r->model.local));
  std::unique_ptr<RestTangent> rest;
  ASSERT_EQ(RestTangent::make(r->model, *r->forces, scratch.data(), false, &rest), 0);
  ASSERT_TRUE(rest);
  Mat A;
  ASSERT_EQ(r->forces->create_tangent(&A), 0);
  const std::vector<double> x = r->model.rest;
  ASSERT_EQ(r->forces->assemble_tangent(x.data(), A), 0);
  Vec u, yr, ya;
  ASSERT_EQ(MatCreateVecs(A, &u, &yr), 0);
  VecDuplicate(yr, &ya);
  PetscRandom random;
  PetscRandomCreate(PETSC_COMM_WORLD, &random);
  PetscRandomSetInterval(random, -1.0, 1.0);
  for (int trial = 0; trial < 2; ++trial) {
    VecSetRandom(u, random);
    ASSERT_EQ(MatMult(rest->matrix(), u, yr), 0);
    ASSERT_EQ(MatMult(A, u, ya), 0);
    PetscReal diff = 0, ref = 0;
    VecNorm(ya, NORM_2, &ref);
    VecAXPY(yr, -1.0, ya);
    VecNorm(yr, NORM_2, &diff);
    EXPECT_GT(ref, 0.0);
    EXPECT_LT(diff, 1e-13 * ref) << text;
  }
  PetscRandomDestroy(&random);
  VecDestroy(&u), VecDestroy(&yr), VecDestroy(&ya);
  MatDestroy(&A);
}

}  // namespace

TEST(RestPull, EqualsPushFormSprings) { compare_forms(springs, ranks() > 1); }
TEST(RestPull, EqualsPushFormNonIntegerSpacing) { compare_forms(springs_mm, ranks() > 1); }
TEST(RestPull, EqualsPushFormBodyDiagonals) { compare_forms(body_diagonals, ranks() > 1); }
TEST(RestPull, EqualsPushFormRectangular) { compare_forms(rectangular, ranks() > 1); }
TEST(RestPull, EqualsPushFormPoissonBlock) { compare_forms(poisson_block, ranks() > 1); }
TEST(RestPull, EqualsAssembledAtRest) {
  compare_assembled(springs);
  compare_assembled(springs_mm);
  compare_assembled(poisson_block);
}
// Off with -static_rest_pull false: the push form (then the product is the push form's own, checked above).
TEST(RestPull, OffByOption) {
  ASSERT_EQ(PetscOptionsSetValue(nullptr, "-static_rest_pull", "false"), 0);
  compare_assembled(springs);
  ASSERT_EQ(PetscOptionsClearValue(nullptr, "-static_rest_pull"), 0);
}
