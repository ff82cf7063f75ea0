#include "src/solvers/matrix_free.hpp"

#include <algorithm>
#include <cstring>
#include <exception>

namespace tissue {

MatrixFreeTangent::MatrixFreeTangent(const LocalModel& model, const ForceModel& forces, double* scratch,
                                     const RestStencil* rest)
    : model_(model),
      forces_(forces),
      rest_(rest),
      x_(model.rest.data()),
      cached_(forces.has_cached_tangent()),
      by_state_(cached_ && std::all_of(forces.terms().begin(), forces.terms().end(),
                                       [](const auto& t) { return t->has_tangent_state(); })) {
  if (!scratch) own_.assign(3 * static_cast<std::size_t>(model.local), 0.0);
  w_ = scratch ? scratch : own_.data();
}

MatrixFreeTangent::~MatrixFreeTangent() { (void)VecDestroy(&in_); }

PetscErrorCode MatrixFreeTangent::create(Mat* J) {
  PetscFunctionBeginUser;
  const PetscInt n = 3 * model_.owned;
  if (!in_) {
    const std::vector<PetscInt> ghosts = model_.block.slice(model_.owned, model_.local);
    PetscCall(VecCreateGhostBlockWithArray(model_.comm, 3, n, PETSC_DECIDE, static_cast<PetscInt>(ghosts.size()),
                                           ghosts.data(), w_, &in_));
    PetscCall(VecSetLocalToGlobalMapping(in_, nullptr));  // for VecSetValuesLocal only (2 MB a rank at 10^6)
  }
  PetscCall(MatCreateShell(model_.comm, n, n, PETSC_DETERMINE, PETSC_DETERMINE, this, J));
  PetscCall(MatShellSetOperation(*J, MATOP_MULT, reinterpret_cast<void (*)(void)>(mult)));
  PetscCall(MatShellSetOperation(*J, MATOP_MULT_TRANSPOSE, reinterpret_cast<void (*)(void)>(mult)));
  PetscCall(MatShellSetOperation(*J, MATOP_GET_DIAGONAL, reinterpret_cast<void (*)(void)>(diagonal)));
  PetscCall(MatSetBlockSize(*J, 3));
  PetscCall(MatSetOption(*J, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatSetOption(*J, MAT_SYMMETRY_ETERNAL, PETSC_TRUE));
  PetscFunctionReturn(0);
}

PetscErrorCode MatrixFreeTangent::set_positions(const double* x, Mat J) {
  PetscFunctionBeginUser;
  x_ = x;
  if (by_state_) {
    const auto& terms = forces_.terms();
    state_.resize(terms.size());
    for (std::size_t t = 0; t < terms.size(); ++t) {
      state_[t].resize(terms[t]->tangent_state_size());
      terms[t]->tangent_state(x, state_[t].data());
    }
  } else if (cached_) {
    PetscCall(cache_blocks());
  }
  PetscCall(MatAssemblyBegin(J, MAT_FINAL_ASSEMBLY));  // a new state: PCSetUp sees a changed operator
  PetscCall(MatAssemblyEnd(J, MAT_FINAL_ASSEMBLY));
  PetscFunctionReturn(0);
}

PetscErrorCode MatrixFreeTangent::cache_blocks() {
  PetscFunctionBeginUser;
  const std::size_t n = model_.owned;
  if (cache_col_.empty()) cache_col_.assign(kSlots * n, -1), cache_K_.assign(9 * kSlots * n, 0.0);
  else std::fill(cache_K_.begin(), cache_K_.end(), 0.0);
  // A row's columns fill its slots in the order they first come (the same every time: the cells' order).
  auto put = [](void* p, int i, int j, const double K[9]) -> PetscErrorCode {
    auto& self = *static_cast<MatrixFreeTangent*>(p);
    int* col = self.cache_col_.data() + static_cast<std::size_t>(kSlots) * i;
    int s = 0;
    while (s < kSlots && col[s] >= 0 && col[s] != j) ++s;
    PetscCheck(s < kSlots, PETSC_COMM_SELF, PETSC_ERR_SUP, "matrix-free tangent: a term couples a molecule to more than 27");
    col[s] = j;
    double* to = self.cache_K_.data() + 9 * (static_cast<std::size_t>(kSlots) * i + s);
    const auto& held = self.forces_.held();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        if (!held[3 * i + r] && !held[3 * j + c]) to[3 * r + c] += K[3 * r + c];
    return 0;
  };
  PetscCall(forces_.cached_tangent_blocks(x_, put, this));
  PetscFunctionReturn(0);
}

PetscErrorCode MatrixFreeTangent::mult(Mat J, Vec in, Vec out) {
  PetscFunctionBeginUser;
  MatrixFreeTangent* self;
  PetscCall(MatShellGetContext(J, &self));
  // The input with its ghosts: in itself when it has the state's ghost slots (the solve's vectors are duplicates of
  // the state's ghosted positions, so every rank takes the same branch and the same scatter), else a copy into the
  // scratch's (24 B a molecule read and written a product). apply_tangent zeroes the held components of its input:
  // in's owned ones are put back at the end, to the bit, and its ghost slots are PETSc's scratch.
  Vec local = nullptr;
  PetscCall(VecGhostGetLocalForm(in, &local));
  PetscInt local_size = -1;
  if (local) PetscCall(VecGetLocalSize(local, &local_size));
  const bool direct = local && local_size == 3 * static_cast<PetscInt>(self->model_.local);
  double* w = self->w_;
  const std::vector<int>& held_in = self->forces_.held_owned();
  if (direct) {
    PetscCall(VecGhostUpdateBegin(in, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecGhostUpdateEnd(in, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecGetArray(local, &w));
    self->held_in_.resize(held_in.size());
    for (std::size_t h = 0; h < held_in.size(); ++h) self->held_in_[h] = w[held_in[h]];
  } else {
    if (local) PetscCall(VecGhostRestoreLocalForm(in, &local));
    const PetscScalar* u;
    PetscCall(VecGetArrayRead(in, &u));
    std::memcpy(self->w_, u, sizeof(double) * 3 * self->model_.owned);
    PetscCall(VecRestoreArrayRead(in, &u));
    PetscCall(VecGhostUpdateBegin(self->in_, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecGhostUpdateEnd(self->in_, INSERT_VALUES, SCATTER_FORWARD));
  }
  PetscScalar* y;
  PetscCall(VecGetArray(out, &y));
  const auto& terms = self->forces_.terms();
  // The first term's product in pieces from the springs' sweep, each once the springs' part of its rows is final
  // (one pass over u, x and out for both; every row sums springs, then the term's pieces in order: the same bits).
  struct Pass {
    const Term* term;
    const double *x, *state, *u;
    double* out;
    int next;
  } pass{self->by_state_ && terms[0]->tangent_by_rows() ? terms[0].get() : nullptr, self->x_, nullptr, w, y, 0};
  if (pass.term) {
    pass.state = self->state_[0].data();
    auto rows = [](void* context, int, int end) {
      Pass& p = *static_cast<Pass*>(context);
      p.next = p.term->apply_tangent_state_below(p.x, p.state, p.u, end, p.next, p.out);
    };
    PetscCall(self->forces_.apply_tangent(self->x_, w, y, self->cached_, rows, &pass, self->rest_));
  } else {
    PetscCall(self->forces_.apply_tangent(self->x_, w, y, self->cached_, nullptr, nullptr, self->rest_));
  }
  if (self->by_state_) {
    // w's held components are zero now (apply_tangent); the held rows keep the identity's values it wrote.
    const std::vector<int>& held = self->forces_.held_owned();
    self->held_out_.resize(held.size());
    for (std::size_t h = 0; h < held.size(); ++h) self->held_out_[h] = y[held[h]];
    std::size_t t = 0;
    if (pass.term) {  // its pieces the sweep left (none: its last rows are handed over at its end)
      pass.term->apply_tangent_state_below(self->x_, pass.state, w, self->model_.owned, pass.next, y);
      t = 1;
    }
    for (; t < terms.size(); ++t) terms[t]->apply_tangent_state(self->x_, self->state_[t].data(), w, y);
    for (std::size_t h = 0; h < held.size(); ++h) y[held[h]] = self->held_out_[h];
  } else if (self->cached_) {
    // Held rows and columns of the cached blocks are zero: the identity rows apply_tangent wrote stay.
    const int n = self->model_.owned;
    for (int i = 0; i < n; ++i) {
      const int* col = self->cache_col_.data() + static_cast<std::size_t>(kSlots) * i;
      const double* K = self->cache_K_.data() + 9 * static_cast<std::size_t>(kSlots) * i;
      double acc[3] = {0.0, 0.0, 0.0};
      for (int s = 0; s < kSlots && col[s] >= 0; ++s, K += 9) {
        const double* v = w + 3 * col[s];
        for (int r = 0; r < 3; ++r) acc[r] += K[3 * r] * v[0] + K[3 * r + 1] * v[1] + K[3 * r + 2] * v[2];
      }
      for (int r = 0; r < 3; ++r) y[3 * i + r] += acc[r];
    }
  }
  PetscCall(VecRestoreArray(out, &y));
  if (direct) {
    for (std::size_t h = 0; h < held_in.size(); ++h) w[held_in[h]] = self->held_in_[h];
    PetscCall(VecRestoreArray(local, &w));
    PetscCall(VecGhostRestoreLocalForm(in, &local));
  }
  PetscFunctionReturn(0);
}

PetscErrorCode MatrixFreeTangent::diagonal(Mat J, Vec d) {
  PetscFunctionBeginUser;
  MatrixFreeTangent* self;
  PetscCall(MatShellGetContext(J, &self));
  PetscScalar* y;
  PetscCall(VecGetArray(d, &y));
  PetscCall(self->forces_.tangent_diagonal(self->x_, y, self->cached_));
  if (self->by_state_) {
    const auto& terms = self->forces_.terms();
    for (std::size_t t = 0; t < terms.size(); ++t) terms[t]->add_tangent_state_diagonal(self->x_, self->state_[t].data(), y);
    for (int h : self->forces_.held_owned()) y[h] = 1.0;
  } else if (self->cached_) {
    const int n = self->model_.owned;
    for (int i = 0; i < n; ++i) {
      const int* col = self->cache_col_.data() + static_cast<std::size_t>(kSlots) * i;
      for (int s = 0; s < kSlots && col[s] >= 0; ++s)
        if (col[s] == i) {
          const double* K = self->cache_K_.data() + 9 * (static_cast<std::size_t>(kSlots) * i + s);
          for (int r = 0; r < 3; ++r) y[3 * i + r] += K[4 * r];
        }
    }
  }
  PetscCall(VecRestoreArray(d, &y));
  PetscFunctionReturn(0);
}

}  // namespace tissue
