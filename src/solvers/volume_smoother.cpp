#include "src/solvers/volume_smoother.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>

namespace tissue {

namespace {

// The smoother's state: the cells, D^-1 (held components 0) on local molecules, diag(T)^-1 and omega.
class VolumeSmoother {
public:
  VolumeSmoother(const LocalModel& model, const std::vector<std::uint8_t>& held, Term::VolumeCoupling cells,
                 int steps)
      : model_(model), held_(held), cells_(std::move(cells)), steps_(std::max(steps, 1)) {}
  ~VolumeSmoother() {
    (void)VecDestroy(&ghosted_);
    (void)VecDestroy(&diag_);
  }

  static PetscErrorCode setup(PC pc) {
    PetscFunctionBeginUser;
    VolumeSmoother* self;
    PetscCall(PCShellGetContext(pc, &self));
    PetscCall(self->set_up(pc));
    PetscFunctionReturn(0);
  }
  static PetscErrorCode apply(PC pc, Vec r, Vec z) {
    PetscFunctionBeginUser;
    VolumeSmoother* self;
    PetscCall(PCShellGetContext(pc, &self));
    PetscCall(self->smooth(r, z));
    PetscFunctionReturn(0);
  }
  static PetscErrorCode destroy(PC pc) {
    PetscFunctionBeginUser;
    VolumeSmoother* self;
    PetscCall(PCShellGetContext(pc, &self));
    delete self;
    PetscFunctionReturn(0);
  }

private:
  int cells() const { return static_cast<int>(cells_.k.size()); }

  // s_c = b_c . v on every cell (v local, ghosts up to date; held components 0 in v): the axis differences of the
  // corners' values (corner c's offsets along x, y, z are bits 0, 1, 2 of c), as the cell term's gradient.
  void divergence(const double* v, double* s) const {
    const int n = cells();
    for (int c = 0; c < n; ++c) {
      const int* k = cells_.corners.data() + 8 * static_cast<std::size_t>(c);
      const double* g = cells_.g.data() + 3 * static_cast<std::size_t>(c);
      const double *v0 = v + 3 * k[0], *v1 = v + 3 * k[1], *v2 = v + 3 * k[2], *v3 = v + 3 * k[3],
                   *v4 = v + 3 * k[4], *v5 = v + 3 * k[5], *v6 = v + 3 * k[6], *v7 = v + 3 * k[7];
      const double dx = (v1[0] - v0[0]) + (v3[0] - v2[0]) + (v5[0] - v4[0]) + (v7[0] - v6[0]);
      const double dy = (v2[1] - v0[1]) + (v3[1] - v1[1]) + (v6[1] - v4[1]) + (v7[1] - v5[1]);
      const double dz = (v4[2] - v0[2]) + (v5[2] - v1[2]) + (v6[2] - v2[2]) + (v7[2] - v3[2]);
      s[c] = dx * g[0] + dy * g[1] + dz * g[2];
    }
  }
  // out_i += w_i (B^T q)_i on owned molecules (w = D^-1, held 0).
  void spread(const double* q, const double* w, double* out) const {
    const int n = cells(), owned = model_.owned;
    for (int c = 0; c < n; ++c) {
      const int* k = cells_.corners.data() + 8 * static_cast<std::size_t>(c);
      const double* g = cells_.g.data() + 3 * static_cast<std::size_t>(c);
      const double t[3] = {q[c] * g[0], q[c] * g[1], q[c] * g[2]};
      if (inner_[c]) {  // every corner owned
        for (int a = 0; a < 8; ++a) {
          const std::size_t m = 3 * static_cast<std::size_t>(k[a]);
          out[m] += w[m] * ((a & 1) ? t[0] : -t[0]);
          out[m + 1] += w[m + 1] * ((a & 2) ? t[1] : -t[1]);
          out[m + 2] += w[m + 2] * ((a & 4) ? t[2] : -t[2]);
        }
        continue;
      }
      for (int a = 0; a < 8; ++a) {
        if (k[a] >= owned) continue;
        for (int d = 0; d < 3; ++d) out[3 * k[a] + d] += w[3 * k[a] + d] * (((a >> d) & 1) ? t[d] : -t[d]);
      }
    }
  }
  // The ghosted array's owned part from v (3 * owned), then its ghosts from their owners.
  PetscErrorCode exchange(const double* v) {
    PetscFunctionBeginUser;
    std::memcpy(local_.data(), v, sizeof(double) * 3 * model_.owned);
    PetscCall(VecGhostUpdateBegin(ghosted_, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecGhostUpdateEnd(ghosted_, INSERT_VALUES, SCATTER_FORWARD));
    PetscFunctionReturn(0);
  }
  // t = T q = q / k + B D^-1 B^T q (one exchange).
  PetscErrorCode schur(const double* q, double* t) {
    PetscFunctionBeginUser;
    std::fill(owned_.begin(), owned_.end(), 0.0);
    spread(q, dinv_.data(), owned_.data());
    PetscCall(exchange(owned_.data()));
    divergence(local_.data(), t);
    for (int c = 0; c < cells(); ++c) t[c] += q[c] / cells_.k[c];
    PetscFunctionReturn(0);
  }

  PetscErrorCode set_up(PC pc) {
    PetscFunctionBeginUser;
    const int owned = model_.owned;
    if (!ghosted_) {
      const std::vector<PetscInt> ghosts = model_.block.slice(model_.owned, model_.local);
      local_.assign(3 * static_cast<std::size_t>(model_.local), 0.0);
      PetscCall(VecCreateGhostBlockWithArray(model_.comm, 3, 3 * owned, PETSC_DECIDE,
                                             static_cast<PetscInt>(ghosts.size()), ghosts.data(), local_.data(),
                                             &ghosted_));
      owned_.assign(3 * static_cast<std::size_t>(owned), 0.0);
      s_.assign(cells(), 0.0), q_.assign(cells(), 0.0), t_.assign(cells(), 0.0);
      inner_.assign(cells(), 1);
      for (int c = 0; c < cells(); ++c)
        for (int a = 0; a < 8; ++a) inner_[c] = inner_[c] && cells_.corners[8 * static_cast<std::size_t>(c) + a] < owned;
    }
    Mat A, P;
    PetscCall(PCGetOperators(pc, &A, &P));
    if (!diag_) PetscCall(MatCreateVecs(P, &diag_, nullptr));
    PetscCall(MatGetDiagonal(P, diag_));
    // D: the diagonal less the cells' volumetric part (which M holds through B^T K B); kept at least a tenth of the
    // tangent's own (the cells' part is the rest tangent's: at large strain the real one may differ).
    const PetscScalar* d;
    PetscCall(VecGetArrayRead(diag_, &d));
    std::fill(owned_.begin(), owned_.end(), 0.0);
    for (int c = 0; c < cells(); ++c) {
      const int* k = cells_.corners.data() + 8 * static_cast<std::size_t>(c);
      const double* g = cells_.g.data() + 3 * static_cast<std::size_t>(c);
      for (int a = 0; a < 8; ++a)
        if (k[a] < owned)
          for (int e = 0; e < 3; ++e) owned_[3 * k[a] + e] += cells_.k[c] * g[e] * g[e];
    }
    for (int i = 0; i < 3 * owned; ++i) owned_[i] = held_[i] ? 0.0 : 1.0 / std::max(d[i] - owned_[i], 0.1 * d[i]);
    PetscCall(VecRestoreArrayRead(diag_, &d));
    PetscCall(exchange(owned_.data()));
    dinv_ = local_;
    // diag(T)^-1, and omega from a power iteration on diag(T)^-1 T (collective: every rank takes part).
    tinv_.assign(cells(), 0.0);
    for (int c = 0; c < cells(); ++c) {
      const int* k = cells_.corners.data() + 8 * static_cast<std::size_t>(c);
      const double* g = cells_.g.data() + 3 * static_cast<std::size_t>(c);
      double t = 1.0 / cells_.k[c];
      for (int a = 0; a < 8; ++a)
        for (int e = 0; e < 3; ++e) t += g[e] * g[e] * dinv_[3 * k[a] + e];
      tinv_[c] = 1.0 / t;
    }
    // Each cell is on every rank holding one of its corners: a cell's value is counted on the rank owning its
    // corner 0 only, in the norms.
    auto norm = [&](const std::vector<double>& v, double* out) -> PetscErrorCode {
      PetscFunctionBeginUser;
      double sum = 0;
      for (int c = 0; c < cells(); ++c)
        if (cells_.corners[8 * static_cast<std::size_t>(c)] < owned) sum += v[c] * v[c];
      PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &sum, 1, MPI_DOUBLE, MPI_SUM, model_.comm));
      *out = std::sqrt(sum);
      PetscFunctionReturn(0);
    };
    // A start vector from the cells' corner-0 molecule ids (the same on every rank count).
    for (int c = 0; c < cells(); ++c) {
      const std::uint64_t id = static_cast<std::uint64_t>(model_.id[cells_.corners[8 * static_cast<std::size_t>(c)]]);
      q_[c] = 0.5 + static_cast<double>((id * 2654435761u) % 1000) / 1000.0;
    }
    // Once: the tangent's diagonal moves little between Newton iterations (strains of a static step), and a
    // power iteration costs ~7 products of the tangent.
    if (omega_ > 0) PetscFunctionReturn(0);
    double top = 1.0, size = 0.0;
    PetscCall(norm(q_, &size));
    for (int it = 0; it < kPower && size > 0; ++it) {
      for (double& v : q_) v /= size;
      PetscCall(schur(q_.data(), t_.data()));
      for (int c = 0; c < cells(); ++c) q_[c] = tinv_[c] * t_[c];
      PetscCall(norm(q_, &size));
      top = size;
    }
    omega_ = 1.0 / (1.05 * top);
    PetscCall(PetscInfo(pc, "volume smoother: %d cells here, lambda_max(diag(T)^-1 T) ~ %g, %d Neumann steps\n",
                        cells(), top, steps_));
    PetscFunctionReturn(0);
  }

  PetscErrorCode smooth(Vec rv, Vec zv) {
    PetscFunctionBeginUser;
    const int owned = model_.owned, n = cells();
    const PetscScalar* r;
    PetscScalar* z;
    PetscCall(VecGetArrayRead(rv, &r));
    PetscCall(VecGetArray(zv, &z));
    // y = D^-1 r (held rows: the identity's, z = r; their y is 0 in B D^-1 r).
    for (int i = 0; i < 3 * owned; ++i) owned_[i] = dinv_[i] * r[i];
    PetscCall(exchange(owned_.data()));
    for (int i = 0; i < 3 * owned; ++i) z[i] = held_[i] ? r[i] : owned_[i];
    divergence(local_.data(), s_.data());
    // q = sum of m Neumann steps: q_0 = omega diag(T)^-1 s, q_j+1 = q_j + omega diag(T)^-1 (s - T q_j).
    for (int c = 0; c < n; ++c) q_[c] = omega_ * tinv_[c] * s_[c];
    for (int j = 1; j < steps_; ++j) {
      PetscCall(schur(q_.data(), t_.data()));
      for (int c = 0; c < n; ++c) q_[c] += omega_ * tinv_[c] * (s_[c] - t_[c]);
    }
    // z = y - D^-1 B^T q.
    std::fill(owned_.begin(), owned_.end(), 0.0);
    spread(q_.data(), dinv_.data(), owned_.data());
    for (int i = 0; i < 3 * owned; ++i) z[i] -= owned_[i];
    PetscCall(VecRestoreArray(zv, &z));
    PetscCall(VecRestoreArrayRead(rv, &r));
    PetscFunctionReturn(0);
  }

  static constexpr int kPower = 15;
  const LocalModel& model_;
  const std::vector<std::uint8_t>& held_;
  Term::VolumeCoupling cells_;
  const int steps_;
  double omega_ = 0.0;
  Vec ghosted_ = nullptr, diag_ = nullptr;
  std::vector<double> local_;  // the ghosted vector's array (3 * local)
  std::vector<double> owned_;  // 3 * owned scratch
  std::vector<double> dinv_;   // D^-1, local, held 0
  std::vector<double> tinv_, s_, q_, t_;  // per cell
  std::vector<char> inner_;               // per cell: all 8 corners owned
};

}  // namespace

PetscErrorCode make_volume_smoother(const LocalModel& model, const std::vector<std::uint8_t>& held,
                                    Term::VolumeCoupling cells, int steps, PC pc) {
  PetscFunctionBeginUser;
  auto* self = new VolumeSmoother(model, held, std::move(cells), steps);
  PetscCall(PCSetType(pc, PCSHELL));
  PetscCall(PCShellSetContext(pc, self));
  PetscCall(PCShellSetSetUp(pc, VolumeSmoother::setup));
  PetscCall(PCShellSetApply(pc, VolumeSmoother::apply));
  PetscCall(PCShellSetDestroy(pc, VolumeSmoother::destroy));
  PetscCall(PCShellSetName(pc, "volume smoother (Woodbury on the cells' volume coupling)"));
  PetscFunctionReturn(0);
}

PetscErrorCode use_volume_smoother(const LocalModel& model, const ForceModel& forces, PC pc, bool by_default) {
  PetscFunctionBeginUser;
  PetscBool on = by_default ? PETSC_TRUE : PETSC_FALSE;
  PetscInt steps = 1, coarse_steps = kCellCoarseSteps;
  PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-static_volume_smoother", &on, nullptr));
  PetscCall(PetscOptionsGetInt(nullptr, nullptr, "-static_volume_smoother_steps", &steps, nullptr));
  PetscCall(PetscOptionsGetInt(nullptr, nullptr, "-static_cell_coarse_steps", &coarse_steps, nullptr));
  Term::VolumeCoupling cells;
  int mine[2] = {0, 0};  // this rank has cells; some cell is near cubic and has a volumetric part
  for (const auto& t : forces.terms())
    if (t->volume_coupling(cells)) {
      mine[0] = 1;
      for (std::size_t c = 0; c < cells.k.size() && !mine[1]; ++c) {
        const double* g = &cells.g[3 * c];
        const double lo = std::min({g[0], g[1], g[2]}), hi = std::max({g[0], g[1], g[2]});
        mine[1] = cells.k[c] > 0 && hi <= kCellCoarseAspect * lo;
      }
      break;
    }
  // A rank without cells still takes part in the smoother's collectives: installed where any rank has cells.
  int any[2] = {0, 0};
  PetscCallMPI(MPI_Allreduce(mine, any, 2, MPI_INT, MPI_MAX, model.comm));
  if (!any[0]) PetscFunctionReturn(0);
  PetscInt levels;
  PetscCall(PCMGGetLevels(pc, &levels));
  // The coarse levels' operators hold the cells' volume coupling per coarse cell (Galerkin), and their point
  // smoother leaves the same slow, nearly volume-preserving errors as the finest's; their products cost about a
  // third of a fine one. Flatter or taller cells gain few iterations (their counts are the cells' anisotropy's):
  // docs/benchmarks.md, "The nu = 0.45 static solve: macro-cells modelled, the coarse levels' smoothing".
  // Set before SNESSetFromOptions: -mg_levels_ksp_max_it and -mg_levels_N_ksp_max_it still win.
  if (any[1] && coarse_steps > 0)
    for (PetscInt l = 1; l + 1 < levels; ++l) {
      KSP smoother;
      PetscCall(PCMGGetSmoother(pc, l, &smoother));
      PetscCall(KSPSetTolerances(smoother, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, coarse_steps));
    }
  if (!on) PetscFunctionReturn(0);
  KSP smoother;
  PC spc;
  PetscCall(PCMGGetSmoother(pc, levels - 1, &smoother));
  PetscCall(KSPGetPC(smoother, &spc));
  PetscCall(make_volume_smoother(model, forces.held(), std::move(cells), static_cast<int>(steps), spc));
  PetscFunctionReturn(0);
}

}  // namespace tissue
