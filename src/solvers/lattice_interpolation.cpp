#include "src/solvers/lattice_interpolation.hpp"

#include <algorithm>
#include <memory>

namespace tissue {

namespace {

struct Interpolation {
  std::vector<std::uint8_t> node;   // per fine molecule: number of coarse nodes | held components << 4
  std::vector<std::int32_t> at;     // per entry: 8 * offset in [owned coarse unknowns | ghosts] + free mask
  std::vector<std::uint8_t> which;  // per entry: its weight in `weights`
  std::vector<double> weights;      // the distinct weights (1, 1/2, 1/4, 1/8 on a lattice coarsened by 2)
  PetscInt nc = 0;                  // owned coarse unknowns
  Vec ghosts = nullptr;             // the coarse unknowns owned elsewhere that the rows read
  VecScatter scatter = nullptr;
  ~Interpolation() {
    (void)VecDestroy(&ghosts);
    (void)VecScatterDestroy(&scatter);
  }
};

Interpolation* context(Mat P) {
  void* p = nullptr;
  (void)MatShellGetContext(P, &p);
  return static_cast<Interpolation*>(p);
}

// y += P c (y: fine, local array).
PetscErrorCode add_interpolated(Interpolation* ip, Vec c, PetscScalar* y) {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(ip->scatter, c, ip->ghosts, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(ip->scatter, c, ip->ghosts, INSERT_VALUES, SCATTER_FORWARD));
  const PetscScalar *u, *g;
  PetscCall(VecGetArrayRead(c, &u));
  PetscCall(VecGetArrayRead(ip->ghosts, &g));
  std::size_t e = 0;
  for (std::size_t i = 0; i < ip->node.size(); ++i) {
    const int n = ip->node[i] & 15, held = ip->node[i] >> 4;
    double acc[3] = {0.0, 0.0, 0.0};
    for (int q = 0; q < n; ++q, ++e) {
      const std::int32_t at = ip->at[e] >> 3, mask = ip->at[e] & 7;  // at[e] >= 0
      const PetscScalar* src = at < ip->nc ? u + at : g + (at - ip->nc);
      const double w = ip->weights[ip->which[e]];
      if (mask == 7) {  // a wholly free coarse node (nearly every one): the loop below without its tests
        acc[0] += w * src[0], acc[1] += w * src[1], acc[2] += w * src[2];
        continue;
      }
      for (int k = 0, m = 0; k < 3; ++k)
        if (mask >> k & 1) acc[k] += w * src[m++];
    }
    for (int k = 0; k < 3; ++k)
      if (!(held >> k & 1)) y[3 * i + k] += acc[k];
  }
  PetscCall(VecRestoreArrayRead(ip->ghosts, &g));
  PetscCall(VecRestoreArrayRead(c, &u));
  PetscFunctionReturn(0);
}

PetscErrorCode mult(Mat P, Vec c, Vec f) {
  PetscFunctionBeginUser;
  PetscCall(VecZeroEntries(f));
  PetscScalar* y;
  PetscCall(VecGetArray(f, &y));
  PetscCall(add_interpolated(context(P), c, y));
  PetscCall(VecRestoreArray(f, &y));
  PetscFunctionReturn(0);
}

PetscErrorCode mult_add(Mat P, Vec c, Vec f, Vec out) {
  PetscFunctionBeginUser;
  if (out != f) PetscCall(VecCopy(f, out));
  PetscScalar* y;
  PetscCall(VecGetArray(out, &y));
  PetscCall(add_interpolated(context(P), c, y));
  PetscCall(VecRestoreArray(out, &y));
  PetscFunctionReturn(0);
}

// c = P^T f with f's values given by value(i, k) (held components 0): each fine value spread over its coarse nodes,
// the ghosts' shares added to their owners.
template <class Value>
PetscErrorCode spread_transpose(Interpolation* ip, Value value, Vec c) {
  PetscFunctionBeginUser;
  PetscCall(VecZeroEntries(c));
  PetscCall(VecZeroEntries(ip->ghosts));
  PetscScalar *u, *g;
  PetscCall(VecGetArray(c, &u));
  PetscCall(VecGetArray(ip->ghosts, &g));
  std::size_t e = 0;
  for (std::size_t i = 0; i < ip->node.size(); ++i) {
    const int n = ip->node[i] & 15, held = ip->node[i] >> 4;
    double v[3];
    for (int k = 0; k < 3; ++k) v[k] = held >> k & 1 ? 0.0 : value(i, k);
    for (int q = 0; q < n; ++q, ++e) {
      const std::int32_t at = ip->at[e] >> 3, mask = ip->at[e] & 7;
      PetscScalar* to = at < ip->nc ? u + at : g + (at - ip->nc);
      const double w = ip->weights[ip->which[e]];
      if (mask == 7) {
        to[0] += w * v[0], to[1] += w * v[1], to[2] += w * v[2];
        continue;
      }
      for (int k = 0, m = 0; k < 3; ++k)
        if (mask >> k & 1) to[m++] += w * v[k];
    }
  }
  PetscCall(VecRestoreArray(ip->ghosts, &g));
  PetscCall(VecRestoreArray(c, &u));
  PetscCall(VecScatterBegin(ip->scatter, ip->ghosts, c, ADD_VALUES, SCATTER_REVERSE));
  PetscCall(VecScatterEnd(ip->scatter, ip->ghosts, c, ADD_VALUES, SCATTER_REVERSE));
  PetscFunctionReturn(0);
}

PetscErrorCode mult_transpose(Mat P, Vec f, Vec c) {
  PetscFunctionBeginUser;
  const PetscScalar* r;
  PetscCall(VecGetArrayRead(f, &r));
  PetscCall(spread_transpose(context(P), [r](std::size_t i, int k) { return r[3 * i + k]; }, c));
  PetscCall(VecRestoreArrayRead(f, &r));
  PetscFunctionReturn(0);
}

PetscErrorCode destroy(Mat P) {
  PetscFunctionBeginUser;
  delete context(P);
  PetscFunctionReturn(0);
}

}  // namespace

PetscErrorCode interpolation_shell(MPI_Comm comm, const std::vector<std::uint8_t>& held, int fine_nodes,
                                   const std::vector<int>& start, std::vector<double>&& weights,
                                   std::vector<std::uint8_t>&& which, const std::vector<PetscInt>& packed,
                                   PetscInt cfirst, PetscInt ccount, Mat* P) {
  PetscFunctionBeginUser;
  auto ip = std::make_unique<Interpolation>();
  ip->nc = ccount;
  const PetscInt clast = cfirst + ccount;
  // The coarse nodes owned elsewhere (8 * first unknown + mask), sorted, and where each one's values start among
  // the ghosts.
  std::vector<PetscInt> away;
  for (PetscInt p : packed)
    if (p / 8 < cfirst || p / 8 >= clast) away.push_back(p);
  std::sort(away.begin(), away.end());
  away.erase(std::unique(away.begin(), away.end()), away.end());
  std::vector<PetscInt> offset(away.size() + 1, 0), gidx;
  for (std::size_t a = 0; a < away.size(); ++a) {
    const int m = static_cast<int>(away[a] % 8);
    for (int k = 0; k < __builtin_popcount(m); ++k) gidx.push_back(away[a] / 8 + k);
    offset[a + 1] = offset[a] + __builtin_popcount(m);
  }
  PetscCheck(8.0 * (static_cast<double>(ccount) + static_cast<double>(gidx.size())) < 2147483647.0, comm,
             PETSC_ERR_SUP, "lattice multigrid: too many coarse unknowns on one rank for the interpolation shell");
  ip->node.resize(fine_nodes);
  ip->at.resize(packed.size());
  PetscCheck(which.size() == packed.size() && weights.size() <= 256, PETSC_COMM_SELF, PETSC_ERR_PLIB,
             "lattice multigrid: interpolation weights do not match the entries");
  ip->which = std::move(which);
  ip->weights = std::move(weights);
  for (int i = 0; i < fine_nodes; ++i) {
    const int n = start[i + 1] - start[i];
    PetscCheck(n <= 8, PETSC_COMM_SELF, PETSC_ERR_PLIB, "lattice multigrid: more than 8 coarse nodes a molecule");
    int h = 0;
    for (int k = 0; k < 3; ++k)
      if (held[3 * i + k]) h |= 1 << k;
    ip->node[i] = static_cast<std::uint8_t>(n | h << 4);
  }
  for (std::size_t e = 0; e < packed.size(); ++e) {
    const PetscInt b = packed[e] / 8, mask = packed[e] % 8;
    PetscInt at = b - cfirst;
    if (b < cfirst || b >= clast) at = ccount + offset[std::lower_bound(away.begin(), away.end(), packed[e]) - away.begin()];
    ip->at[e] = static_cast<std::int32_t>(8 * at + mask);
  }
  Vec layout;
  IS is;
  PetscCall(VecCreateMPIWithArray(comm, 1, ccount, PETSC_DETERMINE, nullptr, &layout));
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, static_cast<PetscInt>(gidx.size()), gidx.data(), PETSC_COPY_VALUES, &is));
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, static_cast<PetscInt>(gidx.size()), &ip->ghosts));
  PetscCall(VecScatterCreate(layout, is, ip->ghosts, nullptr, &ip->scatter));
  PetscCall(ISDestroy(&is));
  PetscCall(VecDestroy(&layout));
  PetscCall(MatCreateShell(comm, 3 * fine_nodes, ccount, PETSC_DETERMINE, PETSC_DETERMINE, ip.get(), P));
  ip.release();  // the shell's destroy deletes it
  PetscCall(MatShellSetOperation(*P, MATOP_DESTROY, reinterpret_cast<void (*)(void)>(destroy)));
  PetscCall(MatShellSetOperation(*P, MATOP_MULT, reinterpret_cast<void (*)(void)>(mult)));
  PetscCall(MatShellSetOperation(*P, MATOP_MULT_ADD, reinterpret_cast<void (*)(void)>(mult_add)));
  PetscCall(MatShellSetOperation(*P, MATOP_MULT_TRANSPOSE, reinterpret_cast<void (*)(void)>(mult_transpose)));
  PetscFunctionReturn(0);
}

PetscErrorCode interpolation_column_sums(Mat P, Vec c) {
  PetscFunctionBeginUser;
  // mult_transpose's sums with every fine value 1: no fine vector to make and fill.
  PetscCall(spread_transpose(context(P), [](std::size_t, int) { return 1.0; }, c));
  PetscFunctionReturn(0);
}

}  // namespace tissue
