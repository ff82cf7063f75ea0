// Shared by the cell-term tests (poisson_test, poisson_mesh_test, anisotropy_test): a deterministic large
// deformation and the check that the force is minus the gradient of the energy and the assembled tangent minus the
// gradient of the force (central differences), on one rank holding everything; and the check that a run on
// PETSC_COMM_WORLD has the forces, solution and energy of the same run on one rank.
#pragma once
#include <gtest/gtest.h>
#include <petscmat.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_map>
#include <vector>

#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"

namespace tissue::test_pipeline {

// A deterministic, partition-independent large deformation: about 5 % strain plus a rotation, plus `stretch` times
// the rest position (a uniform dilation).
inline void deform(const LocalModel& m, std::vector<double>& x, double stretch = 0.0) {
  x.assign(m.rest.begin(), m.rest.end());
  for (int i = 0; i < m.local; ++i) {
    const double* X = m.rest.data() + 3 * i;
    const double g = static_cast<double>(m.id[i]);
    x[3 * i + 0] += 0.04 * X[0] - 0.1 * X[1] + stretch * X[0] + 0.01 * std::sin(1.3 * g);
    x[3 * i + 1] += 0.1 * X[0] - 0.03 * X[1] + 0.02 * X[2] + stretch * X[1] + 0.01 * std::cos(0.7 * g);
    x[3 * i + 2] += 0.05 * X[2] + stretch * X[2] + 0.015 * std::sin(2.1 * g + 0.4);
  }
}

// Force = -dE/dx and tangent = -df/dx at x by central differences (step 1e-6), to 1e-6 of the largest force, on
// every unheld component; returns how many columns were checked.
inline int expect_consistent_derivatives(const LocalModel& m, const ForceModel& fm, std::vector<double> x,
                                         const std::string& what) {
  std::vector<double> f(3 * m.local), fp(3 * m.local), fmin(3 * m.local);
  fm.forces(x.data(), nullptr, f.data());
  Mat J;
  EXPECT_EQ(fm.create_tangent(&J), 0);
  EXPECT_EQ(fm.assemble_tangent(x.data(), J), 0);
  double fscale = 0;
  for (int j = 0; j < 3 * m.owned; ++j) fscale = std::max(fscale, std::fabs(f[j]));
  const double eps = 1e-6;
  int checked = 0;
  for (int j = 0; j < 3 * m.owned; ++j) {
    if (fm.held()[j]) continue;
    const double keep = x[j];
    x[j] = keep + eps;
    const double ep = fm.potential_energy(x.data());
    fm.forces(x.data(), nullptr, fp.data());
    x[j] = keep - eps;
    const double em = fm.potential_energy(x.data());
    fm.forces(x.data(), nullptr, fmin.data());
    x[j] = keep;
    EXPECT_NEAR(f[j], -(ep - em) / (2 * eps), 1e-6 * fscale) << "force " << j << " " << what;
    // Column j of the tangent against -(f(x + eps e_j) - f(x - eps e_j)) / (2 eps), on the unheld rows.
    for (int i = 0; i < 3 * m.owned; ++i) {
      if (fm.held()[i]) continue;
      PetscInt row = 3 * m.block[i / 3] + i % 3, col = 3 * m.block[j / 3] + j % 3;
      PetscScalar Kij;
      EXPECT_EQ(MatGetValues(J, 1, &row, 1, &col, &Kij), 0);
      EXPECT_NEAR(Kij, -(fp[i] - fmin[i]) / (2 * eps), 1e-6 * fscale) << "tangent " << i << " " << j << " " << what;
    }
    ++checked;
  }
  MatDestroy(&J);
  return checked;
}

// `world` (PETSC_COMM_WORLD) and `self` (MPI_COMM_SELF) ran the same scene: forces at deform()'s large deformation
// bit for bit equal, static solutions to `position_tolerance`, potential energies to 1e-12.
template <class Run>
void expect_same_as_one_rank(const Run& world, const Run& self, double position_tolerance) {
  std::unordered_map<std::int64_t, int> at;
  for (int i = 0; i < self.model.owned; ++i) at[self.model.id[i]] = i;
  std::vector<double> xw, xs, fw(3 * world.model.local), fs(3 * self.model.local);
  deform(world.model, xw);
  deform(self.model, xs);
  world.forces->forces(xw.data(), nullptr, fw.data());
  self.forces->forces(xs.data(), nullptr, fs.data());
  const double* pw = world.state->x.array();
  const double* ps = self.state->x.array();
  for (int i = 0; i < world.model.owned; ++i) {
    const int k = at.at(world.model.id[i]);
    for (int d = 0; d < 3; ++d) {
      EXPECT_EQ(fw[3 * i + d], fs[3 * k + d]) << "molecule " << world.model.id[i];
      EXPECT_NEAR(pw[3 * i + d], ps[3 * k + d], position_tolerance) << "molecule " << world.model.id[i];
    }
  }
  double ew = world.forces->potential_energy(xw.data()), total = 0;
  EXPECT_NE(ew, 0.0);
  MPI_Allreduce(&ew, &total, 1, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  EXPECT_NEAR(total, self.forces->potential_energy(xs.data()), 1e-12 * std::fabs(total));
}

}  // namespace tissue::test_pipeline
