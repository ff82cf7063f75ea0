#include "src/solvers/lattice_mg.hpp"

#include <petscksp.h>

#include <algorithm>
#include <array>
#include <climits>
#include <numeric>

#include "partition/exchange.hpp"
#include "src/solvers/lattice_interpolation.hpp"

namespace tissue {

namespace {

// The free components in a 3-bit mask (a table: __builtin_popcount is a library call without -mpopcnt).
constexpr int kFreeCount[8] = {0, 1, 1, 2, 1, 2, 2, 3};

// The planes a coarser level keeps along one axis: every other plane of the level below, and the last.
std::vector<long> coarser(const std::vector<long>& s) {
  if (s.size() <= 2) return s;
  std::vector<long> c;
  for (std::size_t p = 0; p < s.size(); p += 2) c.push_back(s[p]);
  if (c.back() != s.back()) c.push_back(s.back());
  return c;
}

// The directory's exchanges (partition/exchange.hpp): the int64 items grouped by destination rank (counts per
// rank), what arrives and the counts received. Collective.
void exchange(MPI_Comm comm, const std::vector<std::int64_t>& out, const std::vector<int>& out_counts,
              std::vector<std::int64_t>& in, std::vector<int>& in_counts) {
  const ExchangePlan plan(comm, out_counts);
  in = plan.forward(out);
  in_counts = plan.recv_counts();
}

}  // namespace

PetscErrorCode lattice_lookup(MPI_Comm comm, std::int64_t total, const std::vector<std::int64_t>& mine,
                              const std::vector<PetscInt>& nums, const std::vector<std::int64_t>& asked,
                              std::vector<PetscInt>& answers) {
  PetscFunctionBeginUser;
  int size, rank;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const std::int64_t chunk = (total + size - 1) / size;
  auto home = [&](std::int64_t g) { return static_cast<int>(g / chunk); };
  // 1. Owners publish (id, number) pairs to the directory.
  std::vector<int> counts(size, 0), in_counts;
  std::vector<std::size_t> order(mine.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t p, std::size_t q) { return home(mine[p]) < home(mine[q]); });
  std::vector<std::int64_t> out, in;
  out.reserve(2 * mine.size());
  for (std::size_t p : order) {
    out.push_back(mine[p]), out.push_back(nums[p]);
    counts[home(mine[p])] += 2;
  }
  exchange(comm, out, counts, in, in_counts);
  std::vector<PetscInt> table(static_cast<std::size_t>(chunk), -1);
  for (std::size_t p = 0; p < in.size(); p += 2) table[in[p] - rank * chunk] = static_cast<PetscInt>(in[p + 1]);
  // 2. Askers ask, the directory answers in the same order.
  order.resize(asked.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t p, std::size_t q) { return home(asked[p]) < home(asked[q]); });
  out.clear();
  std::fill(counts.begin(), counts.end(), 0);
  for (std::size_t p : order) out.push_back(asked[p]), counts[home(asked[p])]++;
  exchange(comm, out, counts, in, in_counts);
  for (auto& g : in) g = table[g - rank * chunk];
  std::vector<std::int64_t> back;
  std::vector<int> back_counts;
  exchange(comm, in, in_counts, back, back_counts);
  answers.assign(asked.size(), -1);
  for (std::size_t p = 0; p < order.size(); ++p) answers[order[p]] = static_cast<PetscInt>(back[p]);
  for (PetscInt a : answers) PetscCheck(a >= 0, comm, PETSC_ERR_PLIB, "lattice multigrid: a coarse node has no owner");
  PetscFunctionReturn(0);
}

PetscErrorCode estimate_chebyshev_interval(KSP smoother) {
  PetscFunctionBeginUser;
  PetscCall(KSPChebyshevEstEigSet(smoother, kChebyshevEstimate[0], kChebyshevEstimate[1], kChebyshevEstimate[2],
                                  kChebyshevEstimate[3]));
  // Galerkin operators of an SPD tangent are SPD: CG estimates the eigenvalues with 4 work vectors where the
  // default GMRES keeps ~15 per level (340 B per molecule at 64,000). -mg_levels_esteig_ksp_type overrides.
  // 6 CG iterations instead of PETSc's 10: the same Krylov iterations (3 + 9) on the peer problem at 8,000,
  // 64,000 and 262,144 molecules (5 gave 3 + 11 at 64,000); -mg_levels_esteig_ksp_max_it overrides.
  KSP estimator;
  PetscCall(KSPChebyshevEstEigGetKSP(smoother, &estimator));
  if (estimator) {
    PetscCall(KSPSetType(estimator, KSPCG));
    PetscCall(KSPSetTolerances(estimator, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, kChebyshevEstimateSteps));
  }
  PetscFunctionReturn(0);
}

PlaneWeights plane_weights(const std::vector<long>& coarse, long x) {
  PlaneWeights pw;
  const auto c = static_cast<int>(std::lower_bound(coarse.begin(), coarse.end(), x) - coarse.begin());
  if (coarse[c] == x) {
    pw.n = 1, pw.at[0] = c, pw.w[0] = 1.0;
  } else {
    const long lo = coarse[c - 1], hi = coarse[c];
    pw.n = 2;
    pw.at = {c - 1, c};
    pw.w = {double(hi - x) / double(hi - lo), double(x - lo) / double(hi - lo)};
  }
  return pw;
}

PetscErrorCode setup_lattice_mg(const LocalModel& model, const std::vector<std::uint8_t>& held, PC pc,
                                long coarse_nodes, PetscInt* levels, LatticeLevels* hierarchy, bool finest_as_shell) {
  PetscFunctionBeginUser;
  const Body& shape = model.shape;
  const int nb = shape.bodies();
  // Meshes and random clouds have no lattice planes to coarsen: their ids are no (i, j, k), so the caller falls
  // back to GAMG.
  *levels = 1;
  for (int b = 0; b < nb; ++b)
    if (shape.body(b).unstructured()) PetscFunctionReturn(0);
  // planes[l][b][a]: the lattice planes level l keeps along axis a of body b; level 0 keeps all.
  using Planes = LatticeLevels::Planes;
  std::vector<Planes> planes(1, Planes(nb));
  auto nodes = [&](const Planes& p) {
    std::int64_t total = 0;
    for (const auto& b : p) total += static_cast<std::int64_t>(b[0].size()) * b[1].size() * b[2].size();
    return total;
  };
  for (int b = 0; b < nb; ++b)
    for (int a = 0; a < 3; ++a) {
      planes[0][b][a].resize(shape.body(b).n[a]);
      std::iota(planes[0][b][a].begin(), planes[0][b][a].end(), 0L);
    }
  while (nodes(planes.back()) > coarse_nodes && planes.size() < 12) {
    Planes next(nb);
    for (int b = 0; b < nb; ++b)
      for (int a = 0; a < 3; ++a) next[b][a] = coarser(planes.back()[b][a]);
    if (nodes(next) == nodes(planes.back())) break;  // nothing left to coarsen
    planes.push_back(std::move(next));
  }
  const int L = static_cast<int>(planes.size());
  *levels = L;
  if (L == 1) PetscFunctionReturn(0);

  // Each owned molecule's body and lattice indices, found once for every level (an index is divisions).
  std::vector<int> body_of(model.owned);
  std::vector<std::array<int, 3>> index_of(model.owned);
  for (int i = 0; i < model.owned; ++i) {
    const std::int64_t g = model.id[i];
    body_of[i] = shape.body_of(g);
    const auto ijk = shape.body(body_of[i]).index(g);
    for (int a = 0; a < 3; ++a) index_of[i][a] = static_cast<int>(ijk[a]);
  }
  // kept[b][a][x]: whether lattice plane x along axis a of body b is one of a level's planes.
  auto kept_planes = [&](const Planes& p) {
    std::vector<std::array<std::vector<char>, 3>> kept(nb);
    for (int b = 0; b < nb; ++b)
      for (int a = 0; a < 3; ++a) {
        kept[b][a].assign(shape.body(b).n[a], 0);
        for (long x : p[b][a]) kept[b][a][x] = 1;
      }
    return kept;
  };
  // Unknowns: level 0 is the tangent's layout (3 per molecule, held ones included as identity rows); on coarser
  // levels a held component is no unknown at all (the Dirichlet condition of the coarse problem), so a node
  // has 0-3 unknowns. Each level's nodes this rank owns (local molecule indices, owned order), the global
  // number of each node's first unknown, and the mask of its free components.
  auto free_mask = [&](int i) {
    int m = 0;
    for (int k = 0; k < 3; ++k)
      if (!held[3 * i + k]) m |= 1 << k;
    return m;
  };
  std::vector<std::vector<int>> owned_nodes(L);
  std::vector<std::vector<PetscInt>> base(L);
  std::vector<PetscInt> first(L, 0), count(L, 0);
  for (int l = 0; l < L; ++l) {
    PetscInt n = 0;
    const auto kept = kept_planes(planes[l]);
    for (int i = 0; i < model.owned; ++i) {
      const int b = body_of[i];
      const auto& ijk = index_of[i];
      if (!(kept[b][0][ijk[0]] && kept[b][1][ijk[1]] && kept[b][2][ijk[2]])) continue;
      owned_nodes[l].push_back(i);
      base[l].push_back(n);
      n += l == 0 ? 3 : kFreeCount[free_mask(i)];
    }
    count[l] = n;
    PetscInt before = 0;
    PetscCallMPI(MPI_Exscan(&n, &before, 1, MPIU_INT, MPI_SUM, model.comm));
    first[l] = model.rank == 0 ? 0 : before;
    for (auto& v : base[l]) v += first[l];
  }

  const std::int64_t total = shape.molecules();
  std::vector<Mat> interp(L - 1, nullptr);
  std::vector<std::size_t> named(L, 0);
  PetscBool empty_column = PETSC_FALSE;
  for (int l = 0; l + 1 < L; ++l) {
    const auto& rows = owned_nodes[l];
    const auto& cols = owned_nodes[l + 1];
    // Trilinear weights: per axis the enclosing planes of level l+1 and their weights, then all products. Per
    // entry its coarse node (the index among the distinct ones, asked; then, in place, the directory's answer) and
    // its weight: as the index of one of the few distinct weights (in order of first use) for the finest shell,
    // which keeps them so (4 + 1 bytes an entry, not 16 + 8 + 4 written and dropped), else as the number.
    const bool shell = l == 0 && finest_as_shell;
    std::vector<int> start(rows.size() + 1, 0);
    std::vector<PetscInt> node;
    std::vector<double> weight, distinct_weights;
    std::vector<std::uint8_t> which;
    bool too_many_weights = false;
    node.reserve(8 * rows.size());
    // Each coarse node is asked of the directory once: a fine row's coarse nodes are also its neighbours' (at
    // level 0 each is named by about 27 rows). Distinct ones are found on a dense box, per body, of the coarse
    // planes this rank's rows name (a compact block of the lattice: from the rows' lowest and highest planes).
    std::vector<std::array<long, 6>> extent(nb, {LONG_MAX, LONG_MAX, LONG_MAX, -1, -1, -1});
    for (int i : rows) {
      const int b = body_of[i];
      const auto& ijk = index_of[i];
      for (int a = 0; a < 3; ++a)
        extent[b][a] = std::min<long>(extent[b][a], ijk[a]),
        extent[b][3 + a] = std::max<long>(extent[b][3 + a], ijk[a]);
    }
    std::vector<std::array<int, 6>> span(nb);  // per body the coarse planes named: lowest, highest per axis
    std::vector<std::vector<int>> distinct(nb);
    for (int b = 0; b < nb; ++b) {
      if (extent[b][3] < 0) continue;
      for (int a = 0; a < 3; ++a) {
        span[b][a] = plane_weights(planes[l + 1][b][a], extent[b][a]).at[0];
        const PlaneWeights hi = plane_weights(planes[l + 1][b][a], extent[b][3 + a]);
        span[b][3 + a] = hi.at[hi.n - 1];
      }
      distinct[b].assign(static_cast<std::size_t>(span[b][3] - span[b][0] + 1) * (span[b][4] - span[b][1] + 1) *
                             (span[b][5] - span[b][2] + 1),
                         -1);
    }
    // weights_at[b][a][x]: lattice plane x among level l+1's planes (the same for every row on it).
    std::vector<std::array<std::vector<PlaneWeights>, 3>> weights_at(nb);
    for (int b = 0; b < nb; ++b)
      for (int a = 0; a < 3; ++a) {
        if (extent[b][3] < 0) continue;
        weights_at[b][a].resize(shape.body(b).n[a]);
        for (long x = extent[b][a]; x <= extent[b][3 + a]; ++x)
          weights_at[b][a][x] = plane_weights(planes[l + 1][b][a], x);
      }
    std::vector<std::int64_t> asked;  // asked[u]: the u-th distinct node's id
    std::vector<char> by_free;        // whether a row with a free component names it (a held row sums nothing)
    for (std::size_t r = 0; r < rows.size(); ++r) {
      const bool free_row = free_mask(rows[r]) != 0;
      const int b = body_of[rows[r]];
      const BoxGeometry& box = shape.body(b);
      const auto& ijk = index_of[rows[r]];
      std::array<PlaneWeights, 3> w;
      for (int a = 0; a < 3; ++a) w[a] = weights_at[b][a][ijk[a]];
      const auto& sp = span[b];
      const long ny = sp[4] - sp[1] + 1, nz = sp[5] - sp[2] + 1;
      for (int x = 0; x < w[0].n; ++x)
        for (int y = 0; y < w[1].n; ++y)
          for (int z = 0; z < w[2].n; ++z) {
            const int I[3] = {w[0].at[x], w[1].at[y], w[2].at[z]};
            int& u = distinct[b][((I[0] - sp[0]) * ny + (I[1] - sp[1])) * nz + (I[2] - sp[2])];
            if (u < 0) {
              u = static_cast<int>(asked.size());
              asked.push_back(box.id(planes[l + 1][b][0][I[0]], planes[l + 1][b][1][I[1]], planes[l + 1][b][2][I[2]]));
              by_free.push_back(0);
            }
            if (free_row && !by_free[u]) by_free[u] = 1, named[l + 1]++;
            const double product = w[0].w[x] * w[1].w[y] * w[2].w[z];
            node.push_back(u);
            if (!shell) {
              weight.push_back(product);
              continue;
            }
            auto found = std::find(distinct_weights.begin(), distinct_weights.end(), product);
            if (found == distinct_weights.end()) {
              too_many_weights = too_many_weights || distinct_weights.size() == 256;  // refused below, as before
              if (!too_many_weights) distinct_weights.push_back(product);
              found = distinct_weights.end() - 1;
            }
            which.push_back(static_cast<std::uint8_t>(found - distinct_weights.begin()));
          }
      start[r + 1] = static_cast<int>(node.size());
    }
    std::vector<std::vector<int>>().swap(distinct);
    // The directory carries each coarse node's first unknown and free-component mask, packed as 8 base + mask.
    std::vector<std::int64_t> mine(cols.size());
    std::vector<PetscInt> packed(cols.size()), distinct_answers;
    for (std::size_t c = 0; c < cols.size(); ++c) mine[c] = model.id[cols[c]], packed[c] = 8 * base[l + 1][c] + free_mask(cols[c]);
    PetscCall(lattice_lookup(model.comm, total, mine, packed, asked, distinct_answers));
    std::vector<PetscInt>& answers = node;  // each entry's coarse node, now as its packed answer
    for (PetscInt& a : answers) a = distinct_answers[a];
    // Column of component k of a coarse node, or -1 when that component is held.
    auto column = [](PetscInt packed, int k) -> PetscInt {
      const int mask = static_cast<int>(packed % 8);
      if (!(mask >> k & 1)) return -1;
      return packed / 8 + kFreeCount[mask & ((1 << k) - 1)];
    };

    const PetscInt cfirst = first[l + 1], clast = first[l + 1] + count[l + 1];
    Mat P;
    if (shell) {
      std::vector<std::int64_t>().swap(asked);
      PetscCheck(!too_many_weights, PETSC_COMM_SELF, PETSC_ERR_SUP,
                 "lattice multigrid: more than 256 distinct interpolation weights");
      PetscCall(interpolation_shell(model.comm, held, static_cast<int>(rows.size()), start, std::move(distinct_weights),
                                    std::move(which), answers, cfirst, count[l + 1], &P));
    } else {
      std::vector<PetscInt> dnnz(count[l], 0), onnz(count[l], 0);
      auto row_of = [&](std::size_t r, int k) -> PetscInt {
        const int i = rows[r];
        if (held[3 * i + k]) return -1;  // a held component takes no coarse correction
        if (l == 0) return base[l][r] + k;
        const int mask = free_mask(i);
        return base[l][r] + kFreeCount[mask & ((1 << k) - 1)];
      };
      for (std::size_t r = 0; r < rows.size(); ++r)
        for (int k = 0; k < 3; ++k) {
          const PetscInt row = row_of(r, k);
          if (row < 0) continue;
          for (int e = start[r]; e < start[r + 1]; ++e) {
            const PetscInt c = column(answers[e], k);
            if (c >= 0) (c >= cfirst && c < clast ? dnnz : onnz)[row - first[l]]++;
          }
        }
      PetscCall(MatCreate(model.comm, &P));
      PetscCall(MatSetSizes(P, count[l], count[l + 1], PETSC_DETERMINE, PETSC_DETERMINE));
      PetscCall(MatSetType(P, MATAIJ));
      PetscCall(MatSeqAIJSetPreallocation(P, 0, dnnz.data()));
      PetscCall(MatMPIAIJSetPreallocation(P, 0, dnnz.data(), 0, onnz.data()));
      PetscCall(MatSetOption(P, MAT_NO_OFF_PROC_ENTRIES, PETSC_TRUE));
      std::vector<PetscInt> cs;
      std::vector<double> v;
      for (std::size_t r = 0; r < rows.size(); ++r)
        for (int k = 0; k < 3; ++k) {
          const PetscInt row = row_of(r, k);
          if (row < 0) continue;
          cs.clear(), v.clear();
          for (int e = start[r]; e < start[r + 1]; ++e) {
            const PetscInt c = column(answers[e], k);
            if (c >= 0) cs.push_back(c), v.push_back(weight[e]);
          }
          if (!cs.empty())
            PetscCall(MatSetValues(P, 1, &row, static_cast<PetscInt>(cs.size()), cs.data(), v.data(), INSERT_VALUES));
        }
      PetscCall(MatAssemblyBegin(P, MAT_FINAL_ASSEMBLY));
      PetscCall(MatAssemblyEnd(P, MAT_FINAL_ASSEMBLY));
    }
    interp[l] = P;
    // A coarse unknown that no fine one interpolates from would make the coarse operator singular.
    // (The shell sums its columns without a fine vector of ones: 24 B a molecule made, filled and dropped.)
    Vec ones = nullptr, sums;
    if (shell) {
      PetscCall(MatCreateVecs(P, &sums, nullptr));
      PetscCall(interpolation_column_sums(P, sums));
    } else {
      PetscCall(MatCreateVecs(P, &sums, &ones));
      PetscCall(VecSet(ones, 1.0));
      PetscCall(MatMultTranspose(P, ones, sums));
    }
    PetscReal least = 1.0;
    PetscCall(VecMin(sums, nullptr, &least));
    if (least <= 0) empty_column = PETSC_TRUE;
    PetscCall(VecDestroy(&ones));
    PetscCall(VecDestroy(&sums));
    if (empty_column) break;
  }
  if (empty_column) {
    for (Mat& P : interp) PetscCall(MatDestroy(&P));
    *levels = 1;
    PetscFunctionReturn(0);
  }

  if (hierarchy) *hierarchy = LatticeLevels{std::move(planes), std::move(owned_nodes), std::move(base), first, count,
                                            std::move(named)};
  PetscCall(PCSetType(pc, PCMG));
  PetscCall(PCMGSetLevels(pc, L, nullptr));
  PetscCall(PCMGSetType(pc, PC_MG_MULTIPLICATIVE));
  PetscCall(PCMGSetGalerkin(pc, PC_MG_GALERKIN_BOTH));
  for (int l = 0; l + 1 < L; ++l) {
    PetscCall(PCMGSetInterpolation(pc, L - 1 - l, interp[l]));  // PCMG counts levels from the coarsest
    PetscCall(MatDestroy(&interp[l]));
  }
  // Smoothers as GAMG's: Chebyshev on Jacobi, two steps, eigenvalue bounds estimated on each level.
  for (PetscInt k = 1; k < L; ++k) {
    KSP smoother;
    PC spc;
    PetscCall(PCMGGetSmoother(pc, k, &smoother));
    PetscCall(KSPSetType(smoother, KSPCHEBYSHEV));
    PetscCall(estimate_chebyshev_interval(smoother));
    PetscCall(KSPSetTolerances(smoother, PETSC_DEFAULT, PETSC_DEFAULT, PETSC_DEFAULT, 2));
    PetscCall(KSPGetPC(smoother, &spc));
    PetscCall(PCSetType(spc, PCJACOBI));
  }
  PetscFunctionReturn(0);
}

}  // namespace tissue
