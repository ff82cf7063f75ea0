// The angles solution, Eq. 6-7, and its update variant.
//
// Reading. Eq. 6 sums, along connection 0, the stiffness of the connections i that share an end with it, each
// weighted by cos_i, the cosine of the angle between 0 and i: k_f = k_0 + k_1 cos_1 + ... + k_n cos_n. With the
// paper's homogeneity assumption (all k_i / l_i equal, k_i = kappa l_i) this is k_f = kappa (l_0 + l_1 cos_1 +
// ... + l_n cos_n), so kappa = k_f / (l_0 + sum l_i cos_i) (Eq. 7) and connection 0 gets k_0 = kappa l_0. k_f is
// the stiffness the connection and its partners must give together along 0: the linear (Eq. 4) k of connection
// 0, which is exact when it is alone (rectangular topology). Hence
//
//     k_0 = k_linear(0) * l_0 / (l_0 + sum_i l_i cos_i),   the sum over i with cos_i > 0, at both ends of 0,
//
// where cos_i is measured between the two connections pointing away from the shared end. Only partners at an
// acute angle count: they span the same layer of the body as 0 and carry its load in parallel. A partner at an
// obtuse angle, such as the collinear continuation of 0 (cos = -1), lies on the other side of the shared
// molecule and is in series with 0, not beside it; a perpendicular one (cos = 0) adds nothing. So on the
// rectangular topology every partner drops out and angles == linear, as the paper's objects (a), (b) require;
// with face diagonals an interior edge shares its load with 8 diagonals (k = k_linear / 9) and a face diagonal
// with 4 edges and 4 diagonals. l_i cos_i is computed as d_i . u_0 (d_i the vector along i from the shared end,
// u_0 the unit vector along 0), from rest positions ("angles") or current positions ("angles-update", where
// l_0 is the current length too; k_linear stays that of the rest state).
//
// Parallel: the sum at an end molecule needs all of that molecule's connections, which only its owner has. The
// owner of every molecule computes S(m, c) = sum over m's connections i != c of max(0, d_i . u_c) for each of
// its connections c, stored in slots (neighbour id, S); a PETSc ghosted vector of block size 2 * (largest
// degree) then brings these slots to the ranks holding the molecule as a ghost. The sums run over a molecule's
// connections in global connection order on its owner, so k is bit-identical for any rank count.
#include <petscvec.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include "partition/local_model.hpp"
#include "src/calibration/calibration.hpp"

namespace tissue {

namespace {

void check(PetscErrorCode ierr, const char* what) {
  if (ierr) throw std::runtime_error(std::string("angles calibration: PETSc failed in ") + what);
}

class AnglesWorkspace {
public:
  explicit AnglesWorkspace(const CalibrationContext& ctx) : m_(ctx.model) {
    const LocalModel& m = ctx.model;
    // Connections of each local molecule, in global order (complete for owned molecules).
    start_.assign(m.local + 1, 0);
    for (int c = 0; c < m.connections(); ++c) ++start_[m.end_a[c] + 1], ++start_[m.end_b[c] + 1];
    for (int i = 0; i < m.local; ++i) start_[i + 1] += start_[i];
    list_.resize(start_[m.local]);
    std::vector<int> next(start_.begin(), start_.end() - 1);
    for (int c = 0; c < m.connections(); ++c) list_[next[m.end_a[c]]++] = c, list_[next[m.end_b[c]]++] = c;
    klinear_.resize(m.connections());
    for (int c = 0; c < m.connections(); ++c) klinear_[c] = linear_stiffness(ctx, c);
    int most = 1;
    for (int i = 0; i < m.local; ++i) most = std::max(most, ctx.inputs.degree[i]);
    MPI_Allreduce(&most, &slots_, 1, MPI_INT, MPI_MAX, m.comm);
    const PetscInt bs = 2 * slots_;
    std::vector<PetscInt> ghosts = m.block.slice(m.owned, m.local);
    check(VecCreateGhostBlock(m.comm, bs, bs * m.owned, PETSC_DECIDE, static_cast<PetscInt>(ghosts.size()),
                              ghosts.data(), &vec_), "VecCreateGhostBlock");
  }
  ~AnglesWorkspace() {
    if (vec_) VecDestroy(&vec_);
  }
  AnglesWorkspace(const AnglesWorkspace&) = delete;
  AnglesWorkspace& operator=(const AnglesWorkspace&) = delete;

  // x: 3 * local positions, ghosts up to date. Collective.
  void compute(const double* x, std::vector<double>& k) {
    const LocalModel& m = m_;
    const int bs = 2 * slots_;
    auto other = [&](int c, int i) { return m.end_a[c] == i ? m.end_b[c] : m.end_a[c]; };
    Vec local;
    double* a;
    check(VecGhostGetLocalForm(vec_, &local), "VecGhostGetLocalForm");
    check(VecGetArray(local, &a), "VecGetArray");
    for (int i = 0; i < m.owned; ++i) {
      double* slot = a + static_cast<std::size_t>(bs) * i;
      for (int s = 0; s < slots_; ++s) slot[2 * s] = -1.0, slot[2 * s + 1] = 0.0;
      const double* xi = x + 3 * i;
      for (int j = start_[i]; j < start_[i + 1]; ++j) {
        const int c = list_[j];
        const double* xo = x + 3 * other(c, i);
        double u[3] = {xo[0] - xi[0], xo[1] - xi[1], xo[2] - xi[2]};
        const double len = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
        for (double& v : u) v /= len;
        double sum = 0.0;
        for (int q = start_[i]; q < start_[i + 1]; ++q) {
          if (list_[q] == c) continue;
          const double* xq = x + 3 * other(list_[q], i);
          const double proj = (xq[0] - xi[0]) * u[0] + (xq[1] - xi[1]) * u[1] + (xq[2] - xi[2]) * u[2];
          if (proj > 0) sum += proj;
        }
        slot[2 * (j - start_[i])] = static_cast<double>(m.id[other(c, i)]);
        slot[2 * (j - start_[i]) + 1] = sum;
      }
    }
    check(VecRestoreArray(local, &a), "VecRestoreArray");
    check(VecGhostRestoreLocalForm(vec_, &local), "VecGhostRestoreLocalForm");
    check(VecGhostUpdateBegin(vec_, INSERT_VALUES, SCATTER_FORWARD), "VecGhostUpdateBegin");
    check(VecGhostUpdateEnd(vec_, INSERT_VALUES, SCATTER_FORWARD), "VecGhostUpdateEnd");

    check(VecGhostGetLocalForm(vec_, &local), "VecGhostGetLocalForm");
    const double* r;
    check(VecGetArrayRead(local, &r), "VecGetArrayRead");
    auto lookup = [&](int i, std::int64_t neighbour) {
      const double* slot = r + static_cast<std::size_t>(bs) * i;
      for (int s = 0; s < slots_; ++s)
        if (slot[2 * s] == static_cast<double>(neighbour)) return slot[2 * s + 1];
      throw std::logic_error("angles calibration: molecule " + std::to_string(m.id[i]) + " lacks its connection to " +
                             std::to_string(neighbour));
    };
    for (int c = 0; c < m.connections(); ++c) {
      const int ea = m.end_a[c], eb = m.end_b[c];
      const double sa = lookup(ea, m.id[eb]), sb = lookup(eb, m.id[ea]);
      double l2 = 0;
      for (int d = 0; d < 3; ++d) l2 += (x[3 * eb + d] - x[3 * ea + d]) * (x[3 * eb + d] - x[3 * ea + d]);
      const double l = std::sqrt(l2);
      k[c] = klinear_[c] * l / (l + sa + sb);
    }
    check(VecRestoreArrayRead(local, &r), "VecRestoreArrayRead");
    check(VecGhostRestoreLocalForm(vec_, &local), "VecGhostRestoreLocalForm");
  }

private:
  const LocalModel& m_;
  std::vector<int> start_, list_;
  std::vector<double> klinear_;
  int slots_ = 1;
  Vec vec_ = nullptr;
};

}  // namespace

void calibrate_angles(const CalibrationContext& ctx, std::vector<double>& k) {
  AnglesWorkspace(ctx).compute(ctx.model.rest.data(), k);
}

CalibrationRefresher angles_updater(const CalibrationContext& ctx, std::vector<double>& k) {
  auto workspace = std::make_shared<AnglesWorkspace>(ctx);
  std::vector<double>* target = &k;
  return [workspace, target](const double* x) { workspace->compute(x, *target); };
}

TISSUE_CALIBRATION(angles, {"angles", calibrate_angles,
                            "Eq. 6-7: the linear k shared with the connections at angles, rest cosines"});
TISSUE_CALIBRATION(angles_update, {"angles-update", calibrate_angles,
                                   "Eq. 6-7 with cosines from the current positions, every iteration", angles_updater});

}  // namespace tissue
