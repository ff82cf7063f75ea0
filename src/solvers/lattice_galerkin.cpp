#include "src/solvers/lattice_galerkin.hpp"

#include <petsc/private/petscimpl.h>  // PetscObjectStateIncrease: a refill writes the arrays directly
#include <petscksp.h>

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <complex>
#include <map>
#include <cstdlib>
#include <cstring>
#include <type_traits>
#include <unordered_map>

#include <sys/mman.h>  // madvise: the halved level-1 rows' pages
#include <unistd.h>    // sysconf

#include <Eigen/Dense>

#include "partition/exchange.hpp"
#include "src/vector_clones.hpp"

namespace tissue {

namespace {

// Frees a container's storage: `c = {}` assigns an empty list and keeps the capacity (and a map's buckets).
template <class C>
void free_storage(C& c) {
  C().swap(c);
}

constexpr int kSlots = 27;  // a 27-point stencil: offsets -1, 0, 1 along each axis
constexpr int kBlock = 9;   // a 3x3 block, row-major

constexpr int slot_of(int dx, int dy, int dz) { return (dx + 1) + 3 * (dy + 1) + 9 * (dz + 1); }
// The diagonal slot, and the upper half of the stencil from it (slot 26 - s is the opposite neighbour of slot s).
constexpr int kHalf0 = slot_of(0, 0, 0), kHalf = kSlots - kHalf0;
constexpr std::size_t kMinPullRun = 8;  // level 1's shortest pulled run (pull_runs): one 8-lane vector

// Box index t = x + 4 y + 16 z (0..3 each) as a slot offset: x + 3 y + 9 z, so that slot = shift + kBoxToSlot[t].
constexpr std::array<int, 64> box_to_slot() {
  std::array<int, 64> s{};
  for (int t = 0; t < 64; ++t) s[t] = t % 4 + 3 * (t / 4 % 4) + 9 * (t / 16);
  return s;
}
constexpr std::array<int, 64> kBoxToSlot = box_to_slot();

// Each plane of level l among the planes of level l+1: the interpolation's own weights (lattice_mg.hpp).
using AxisWeights = PlaneWeights;

std::vector<AxisWeights> axis_weights(const std::vector<long>& fine, const std::vector<long>& coarse) {
  std::vector<AxisWeights> out(fine.size());
  for (std::size_t p = 0; p < fine.size(); ++p) out[p] = plane_weights(coarse, fine[p]);
  return out;
}

int position(const std::vector<long>& planes, long x) {
  return static_cast<int>(std::lower_bound(planes.begin(), planes.end(), x) - planes.begin());
}

PetscLogEvent galerkin_event() {
  static PetscLogEvent event = -1;
  if (event < 0) PetscCallAbort(PETSC_COMM_SELF, PetscLogEventRegister("LatticeGalerkin", PC_CLASSID, &event));
  return event;
}

// The stencil slots whose offset along axis a is d - 1.
constexpr std::array<std::array<std::uint32_t, 3>, 3> slots_at() {
  std::array<std::array<std::uint32_t, 3>, 3> m{};
  for (int s = 0; s < kSlots; ++s) {
    m[0][s % 3] |= 1u << s;
    m[1][s / 3 % 3] |= 1u << s;
    m[2][s / 9] |= 1u << s;
  }
  return m;
}
constexpr std::array<std::array<std::uint32_t, 3>, 3> kSlotsAt = slots_at();

// A fine row's neighbour plane along one axis (offset d - 1 from the row's) among the coarse planes of the row's
// 4x4x4 box: n coarse planes J (box index) with weights w.
struct AxisStep {
  int n = 0;
  std::array<int, 2> J{};
  std::array<double, 2> w{};
};
using AxisSteps = std::array<std::array<AxisStep, 3>, 3>;  // [axis][d]

// The coarsening's two inner loops, compiled for AVX-512, AVX2 and the baseline (picked at run time, as the
// spring kernel's; no fused multiply-adds in this build, so every clone rounds alike). A 3x3 block's 9 products
// are one vector operation and a remainder. (TISSUE_CLONES: src/vector_clones.hpp)

// Stage 1 of a fine row: T_J = sum_s w_J(s) A_s over the present slots s (ascending) and the coarse nodes J of
// each slot's neighbour, into the 4x4x4 box T; returns which J were touched (the others are not written).
TISSUE_CLONES std::uint64_t sum_blocks(std::uint32_t present, const double* src, const AxisSteps& steps, double* T) {
  std::uint64_t touched = 0;
  for (std::uint32_t rest = present; rest; rest &= rest - 1) {
    const int s = __builtin_ctz(rest);
    const AxisStep &sx = steps[0][s % 3], &sy = steps[1][s / 3 % 3], &sz = steps[2][s / 9];
    const double* blk = src + s * kBlock;
    for (int x = 0; x < sx.n; ++x)
      for (int y = 0; y < sy.n; ++y)
        for (int z = 0; z < sz.n; ++z) {
          const int t = sx.J[x] + 4 * sy.J[y] + 16 * sz.J[z];
          const double w = sx.w[x] * sy.w[y] * sz.w[z];
          double* to = T + t * kBlock;
          if (!(touched >> t & 1)) {
            touched |= std::uint64_t{1} << t;
            for (int e = 0; e < kBlock; ++e) to[e] = w * blk[e];
          } else {
            for (int e = 0; e < kBlock; ++e) to[e] += w * blk[e];
          }
        }
  }
  return touched;
}

// Stage 2: row_k += w_k T_J at slot shift_k + J for each of the row's coarse nodes k; bits_k: the slots written.
TISSUE_CLONES void spread_blocks(std::uint64_t touched, const double* T, int nrows, double* const* rows,
                                 const double* w, const int* shift, std::uint32_t* bits) {
  for (int k = 0; k < nrows; ++k) {
    std::uint32_t b = 0;
    for (std::uint64_t rest = touched; rest; rest &= rest - 1) {
      const int t = __builtin_ctzll(rest);
      const int s = shift[k] + kBoxToSlot[t];
      double* to = rows[k] + s * kBlock;
      const double* from = T + t * kBlock;
      for (int e = 0; e < kBlock; ++e) to[e] += w[k] * from[e];
      b |= 1u << s;
    }
    bits[k] = b;
  }
}

// Level 1's product, a block with a held component (either product: acc is 3 doubles or 4 lanes): A_ij v_j into
// acc, v_j the neighbour's free values at src by its mask jm (held: 0), and, off the diagonal (the diagonal block
// counts once), A_ij^T u_i into the neighbour's free values at back.
template <class Acc>
__attribute__((always_inline)) inline void masked_block(const double* blk, bool diagonal, int jm, const double* src,
                                                        const double* ui, Acc& acc, double* back) {
  double v[3];
  for (int m = 0, q = 0; m < 3; ++m) v[m] = jm >> m & 1 ? src[q++] : 0.0;
  for (int k = 0; k < 3; ++k) acc[k] += blk[3 * k] * v[0] + blk[3 * k + 1] * v[1] + blk[3 * k + 2] * v[2];
  if (diagonal) return;
  for (int k = 0, q = 0; k < 3; ++k)
    if (jm >> k & 1) back[q++] += blk[k] * ui[0] + blk[3 + k] * ui[1] + blk[6 + k] * ui[2];
}

// Level 1's product over its halved rows (LatticeGalerkin::stencil_mult). A block A_ij adds A_ij u_j to row i and
// A_ij^T u_i to row j; both take 4-lane vectors (the fourth lane is unused: it reads the next value and is never
// stored): A_ij^T u_i from the block's three rows, A_ij u_j from its three columns, read as the rows of the block's
// transpose at `columns`. When every block between two wholly free nodes is symmetric to the bit (springs only),
// columns is a itself; otherwise (a term's blocks) it is the kept rows' blocks transposed (halve_level_one) when
// they are few, or the lanes are gathered from the block's entries (null: no copy of many distinct rows). Lane k
// then computes exactly the scalar expressions sum_m A[k][m] v_m and sum_m A[m][k] u_m in the same order (no fused
// multiply-adds in this build), so the result does not depend on the layout. Blocks with a held component go the
// general way (masks).
using Lanes = double __attribute__((vector_size(32)));

enum class Columns { kRows, kCopy, kGathered };  // where A_ij u_j's columns come from (stencil_product)

// Level 1's pulled nodes (LatticeGalerkin::pull_runs): runs of consecutive wholly free nodes with one row, whose
// upper neighbours are wholly free and local at the usual node offsets (or absent), and whose lower neighbours
// (those whose blocks reach them) are at the usual offsets with one row each along the run (or absent): a box
// lattice's interior and faces at its reference state. Such a node's value is summed in registers, 8 nodes at a
// time, from the input by component: the transposed blocks its lower neighbours would add to it (by increasing
// neighbour, the order the push form adds them in; a held component reads +0, as the push form's), then its own
// blocks' sum, and stored. What the push form's nodes add to it before (all its lower neighbours come before it) is
// overwritten; nothing is added after. Every value is the push form's expression on the same operands in the same
// order, so the same bits.
struct PullRuns {
  struct Run {
    int c0, c1, row;
    int p0, p1;                // its pushes: pushes[p0 .. p1)
    int lower_row[kHalf - 1];  // by slot s - 1: the row of the lower neighbour c - delta[s] (-1: none reaches c)
    std::uint32_t absent;      // bit s: no block in upper slot s
  };
  const Run* runs = nullptr;
  std::size_t count = 0;
  const int* delta = nullptr;          // kHalf node offsets of the upper slots (delta[0] = 0)
  const int* lower = nullptr;          // slots 1 .. kHalf - 1 by decreasing offset (the lower neighbours by increasing node)
  // Pulled nodes' upper slots whose node is not pulled: 16 x the pulled node's first unknown + the slot, then
  // the other node's first unknown (so that the push reads neither the node's nor the columns' arrays).
  const std::uint32_t* pushes = nullptr;
  const double* soa[3] = {};           // the input by component, per node
};

using Lanes8 = double __attribute__((vector_size(64)));

template <class V>
inline void load(V& v, const double* p) {
  if constexpr (std::is_same_v<V, double>) v = *p;
  else std::memcpy(&v, p, sizeof v);
}

// W nodes from node c (V: double or Lanes8) into Y[k] (their row k values); kColumns as stencil_product's; lb[s]:
// the lower neighbour's block of slot s (null: none), absent: the upper slots without a block.
template <Columns kColumns, class V>
__attribute__((always_inline)) inline void pull_nodes(int c, const PullRuns& pr, const double* const* lb,
                                                     std::uint32_t absent, const double* blk, const double* tblk,
                                                     V Y[3]) {
  const double *X0 = pr.soa[0], *X1 = pr.soa[1], *X2 = pr.soa[2];
  V y0 = {}, y1 = {}, y2 = {};
  for (int q = 0; q < kHalf - 1; ++q) {  // A_ji^T u_j from each lower neighbour j, by increasing j
    const int s = pr.lower[q], j = c - pr.delta[s];
    const double* r = lb[s];
    if (!r) continue;
    V u0, u1, u2;
    load(u0, X0 + j), load(u1, X1 + j), load(u2, X2 + j);
    y0 += r[0] * u0 + r[3] * u1 + r[6] * u2;
    y1 += r[1] * u0 + r[4] * u1 + r[7] * u2;
    y2 += r[2] * u0 + r[5] * u1 + r[8] * u2;
  }
  V a0 = {}, a1 = {}, a2 = {};
  for (int s = 0; s < kHalf; ++s) {  // A_ij u_j over the node's own blocks, in slot order
    if (absent >> s & 1u) continue;
    const int j = c + pr.delta[s];
    const double* b = (kColumns == Columns::kCopy ? tblk : blk) + kBlock * s;
    V u0, u1, u2;
    load(u0, X0 + j), load(u1, X1 + j), load(u2, X2 + j);
    if (kColumns == Columns::kGathered) {  // column m of row k is b[3 k + m]
      a0 += b[0] * u0 + b[1] * u1 + b[2] * u2;
      a1 += b[3] * u0 + b[4] * u1 + b[5] * u2;
      a2 += b[6] * u0 + b[7] * u1 + b[8] * u2;
    } else {  // the lanes of row m are b[3 m ..]: lane k is b[3 m + k]
      a0 += b[0] * u0 + b[3] * u1 + b[6] * u2;
      a1 += b[1] * u0 + b[4] * u1 + b[7] * u2;
      a2 += b[2] * u0 + b[5] * u1 + b[8] * u2;
    }
  }
  Y[0] = y0 + a0, Y[1] = y1 + a1, Y[2] = y2 + a2;
}

// 8 nodes' three components interleaved into 24 consecutive values (two shuffles a vector).
__attribute__((always_inline)) inline void store_interleaved(double* to, Lanes8 y0, Lanes8 y1, Lanes8 y2) {
  const Lanes8 t0 = __builtin_shufflevector(y0, y1, 0, 8, 0, 1, 9, 0, 2, 10);
  const Lanes8 t1 = __builtin_shufflevector(y0, y1, 0, 3, 11, 0, 4, 12, 0, 5);
  const Lanes8 t2 = __builtin_shufflevector(y0, y1, 13, 0, 6, 14, 0, 7, 15, 0);
  const Lanes8 o0 = __builtin_shufflevector(t0, y2, 0, 1, 8, 3, 4, 9, 6, 7);
  const Lanes8 o1 = __builtin_shufflevector(t1, y2, 10, 1, 2, 11, 4, 5, 12, 7);
  const Lanes8 o2 = __builtin_shufflevector(t2, y2, 0, 13, 2, 3, 14, 5, 6, 15);
  std::memcpy(to, &o0, sizeof o0), std::memcpy(to + 8, &o1, sizeof o1), std::memcpy(to + 16, &o2, sizeof o2);
}
__attribute__((always_inline)) inline void store_nodes(double* to, const Lanes8 Y[3]) {
  store_interleaved(to, Y[0], Y[1], Y[2]);
}
__attribute__((always_inline)) inline void store_nodes(double* to, const double Y[3]) {
  to[0] = Y[0], to[1] = Y[1], to[2] = Y[2];
}

// The run's nodes W at a time from c to its end; the last W end at the run's end (nodes computed twice get the
// same values: a pulled node's value is only stored). Returns where it stopped (the run's end, or c when the run
// is shorter than W).
template <Columns kColumns, class V>
__attribute__((always_inline)) inline int pull_blocks(int c, const PullRuns::Run& run, const PullRuns& pr,
                                                      const PetscInt* first, const double* const* lb,
                                                      const double* blk, const double* tblk, double* y) {
  constexpr int W = sizeof(V) / sizeof(double);
  if (run.c1 - c < W) return c;
  for (; c < run.c1; c += W) {
    const int cw = std::min(c, run.c1 - W);
    V Y[3];
    pull_nodes<kColumns>(cw, pr, lb, run.absent, blk, tblk, Y);
    store_nodes(y + first[cw] / 8, Y);  // W wholly free nodes: 3 W consecutive values
  }
  return run.c1;
}

template <Columns kColumns>
__attribute__((always_inline)) inline void pull_run(const PullRuns::Run& run, const PullRuns& pr, const PetscInt* first,
                                                   const double* a, const double* columns, const double* u,
                                                   double* y) {
  const double* blk = a + kHalf * kBlock * static_cast<std::size_t>(run.row);
  const double* tblk = columns + kHalf * kBlock * static_cast<std::size_t>(run.row);
  const double* lb[kHalf] = {};
  for (int s = 1; s < kHalf; ++s)
    if (run.lower_row[s - 1] >= 0) lb[s] = a + kHalf * kBlock * static_cast<std::size_t>(run.lower_row[s - 1]) + kBlock * s;
  // (16 nodes at a time measured slower than 8: GCC spills the 16-lane sums.)
  const int c = pull_blocks<kColumns, Lanes8>(run.c0, run, pr, first, lb, blk, tblk, y);
  pull_blocks<kColumns, double>(c, run, pr, first, lb, blk, tblk, y);
  // Then its blocks to upper neighbours that are not pulled, A_ij^T u_i added there as the push form adds it: by
  // increasing i, as the push form's, and no other node writes to them while the run is summed.
  for (int p = run.p0; p < run.p1; ++p) {
    const std::uint32_t from = pr.pushes[2 * p], to = pr.pushes[2 * p + 1];
    const double* ui = u + (from >> 4);
    const double* r = blk + kBlock * (from & 15u);
    double* back = y + to;
    Lanes r0, r1, r2;
    std::memcpy(&r0, r, sizeof r0), std::memcpy(&r1, r + 3, sizeof r1), std::memcpy(&r2, r + 6, sizeof r2);
    const Lanes t = r0 * ui[0] + r1 * ui[1] + r2 * ui[2];
    back[0] += t[0], back[1] += t[1], back[2] += t[2];
  }
}

template <Columns kColumns>
__attribute__((always_inline)) inline void stencil_product(std::size_t nodes, const PetscInt* first, const int* row,
                                                           const double* a, const double* columns,
                                                           const PetscInt* cols, PetscInt n, const double* u,
                                                           const double* g, double* y, double* h,
                                                           const PullRuns& pr) {
  const PullRuns::Run* run = pr.runs;
  const PullRuns::Run* runs_end = pr.runs + pr.count;
  for (std::size_t c = 0; c < nodes; ++c) {
    if (run < runs_end && static_cast<int>(c) == run->c0) {  // a pulled run, then on after it
      pull_run<kColumns>(*run, pr, first, a, columns, u, y);
      c = static_cast<std::size_t>(run->c1) - 1;
      ++run;
      continue;
    }
    const int mask = static_cast<int>(first[c] % 8);
    if (!mask) continue;
    const double* blk = a + kHalf * kBlock * static_cast<std::size_t>(row[c]);
    const double* tblk = columns + kHalf * kBlock * static_cast<std::size_t>(row[c]);
    const PetscInt* col = cols + kHalf * c;
    double* to = y + first[c] / 8;
    double ui[3];
    for (int m = 0, q = 0; m < 3; ++m) ui[m] = mask >> m & 1 ? u[first[c] / 8 + q++] : 0.0;
    Lanes acc = {0.0, 0.0, 0.0, 0.0};
    for (int s = 0; s < kHalf; ++s, blk += kBlock, tblk += kBlock) {
      if (col[s] < 0) continue;
      const int jm = static_cast<int>(col[s] & 7);
      const PetscInt at = col[s] >> 3;
      const double* src = at < n ? u + at : g + (at - n);
      if ((mask & jm) == 7) {
        Lanes r0, r1, r2;
        std::memcpy(&r0, blk, sizeof r0), std::memcpy(&r1, blk + 3, sizeof r1), std::memcpy(&r2, blk + 6, sizeof r2);
        if (kColumns == Columns::kCopy) {
          Lanes c0, c1, c2;
          std::memcpy(&c0, tblk, sizeof c0), std::memcpy(&c1, tblk + 3, sizeof c1);
          std::memcpy(&c2, tblk + 6, sizeof c2);
          acc += c0 * src[0] + c1 * src[1] + c2 * src[2];
        } else if (kColumns == Columns::kGathered) {
          const Lanes c0 = {blk[0], blk[3], blk[6], 0.0}, c1 = {blk[1], blk[4], blk[7], 0.0},
                      c2 = {blk[2], blk[5], blk[8], 0.0};
          acc += c0 * src[0] + c1 * src[1] + c2 * src[2];
        } else {
          acc += r0 * src[0] + r1 * src[1] + r2 * src[2];
        }
        if (s == 0) continue;
        double* back = at < n ? y + at : h + (at - n);
        const Lanes t = r0 * ui[0] + r1 * ui[1] + r2 * ui[2];
        back[0] += t[0], back[1] += t[1], back[2] += t[2];
        continue;
      }
      masked_block(blk, s == 0, jm, src, ui, acc, at < n ? y + at : h + (at - n));
    }
    for (int k = 0, q = 0; k < 3; ++k)
      if (mask >> k & 1) to[q++] += acc[k];
  }
}

TISSUE_CLONES void symmetric_stencil_product(std::size_t nodes, const PetscInt* first, const int* row,
                                             const double* a, const PetscInt* cols, PetscInt n, const double* u,
                                             const double* g, double* y, double* h, const PullRuns& pr) {
  stencil_product<Columns::kRows>(nodes, first, row, a, a, cols, n, u, g, y, h, pr);
}

TISSUE_CLONES void general_stencil_product(std::size_t nodes, const PetscInt* first, const int* row,
                                           const double* a, const double* columns, const PetscInt* cols, PetscInt n,
                                           const double* u, const double* g, double* y, double* h,
                                           const PullRuns& pr) {
  if (columns)
    stencil_product<Columns::kCopy>(nodes, first, row, a, columns, cols, n, u, g, y, h, pr);
  else
    stencil_product<Columns::kGathered>(nodes, first, row, a, a, cols, n, u, g, y, h, pr);
}

// The largest eigenvalue of D^-1/2 A(theta) D^-1/2 over wave vectors theta, A(theta) = sum_s A_s e^(i theta.d_s)
// the symbol of a row of 27 blocks repeated over an infinite lattice (d_s: slot s's offset), D its diagonal
// block's diagonal. On a grid of pi/8 a component (theta and -theta give the same eigenvalues: the first component
// in [0, pi]); a row's symbol peaks at such points on the lattices here (checked against a grid of pi/32).
constexpr std::size_t kSymbolRows = 64;  // at most this many distinct interior rows are looked at
double jacobi_symbol_max(const double* blocks) {
  const double* diag = blocks + kBlock * slot_of(0, 0, 0);
  if (!(diag[0] > 0.0 && diag[4] > 0.0 && diag[8] > 0.0)) return 0.0;
  const double scale[3] = {1.0 / std::sqrt(diag[0]), 1.0 / std::sqrt(diag[4]), 1.0 / std::sqrt(diag[8])};
  constexpr int kSteps = 8;  // pi / kSteps
  double best = 0.0;
  for (int a = 0; a <= kSteps; ++a)
    for (int b = -kSteps + 1; b <= kSteps; ++b)
      for (int c = -kSteps + 1; c <= kSteps; ++c) {
        const double theta[3] = {M_PI * a / kSteps, M_PI * b / kSteps, M_PI * c / kSteps};
        Eigen::Matrix3cd H = Eigen::Matrix3cd::Zero();
        for (int s = 0; s < kSlots; ++s) {
          const double phase = theta[0] * (s % 3 - 1) + theta[1] * (s / 3 % 3 - 1) + theta[2] * (s / 9 - 1);
          const std::complex<double> e(std::cos(phase), std::sin(phase));
          for (int r = 0; r < 3; ++r)
            for (int k = 0; k < 3; ++k) H(r, k) += blocks[kBlock * s + 3 * r + k] * scale[r] * scale[k] * e;
        }
        const Eigen::Matrix3cd He = 0.5 * (H + H.adjoint());  // Hermitian to round-off
        best = std::max(best, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3cd>(He, Eigen::EigenvaluesOnly).eigenvalues().maxCoeff());
      }
  return best;
}

// Pages about to be written from scratch, faulted in by one call instead of one trap a 4 kB page at first touch:
// about half the cost a page on this project's VMs (docs/benchmarks.md, branch static18f). Whole pages inside
// [p, p + bytes) only, so nothing beyond what is written anyway becomes resident; best effort (a kernel before
// 5.14 answers EINVAL, and the pages fault as before).
void populate(const void* p, std::size_t bytes) {
#ifndef MADV_POPULATE_WRITE
  constexpr int MADV_POPULATE_WRITE = 23;
#endif
  const std::uintptr_t page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
  const auto from = (reinterpret_cast<std::uintptr_t>(p) + page - 1) / page * page;
  const auto to = (reinterpret_cast<std::uintptr_t>(p) + bytes) / page * page;
  if (to > from + (1u << 20)) (void)madvise(reinterpret_cast<void*>(from), to - from, MADV_POPULATE_WRITE);
}

// The fine operator's parts: diagonal block (SeqAIJ) and, on 2+ ranks, off-diagonal block and its global columns.
struct FineParts {
  Mat Ad = nullptr, Ao = nullptr;
  const PetscInt* garray = nullptr;
};

PetscErrorCode fine_parts(Mat A, FineParts* parts, bool* ok) {
  PetscFunctionBeginUser;
  PetscBool mpi = PETSC_FALSE, seq = PETSC_FALSE;
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(A), MATMPIAIJ, &mpi));
  PetscCall(PetscObjectTypeCompare(reinterpret_cast<PetscObject>(A), MATSEQAIJ, &seq));
  *ok = mpi || seq;
  if (mpi) PetscCall(MatMPIAIJGetSeqAIJ(A, &parts->Ad, &parts->Ao, &parts->garray));
  if (seq) parts->Ad = A;
  PetscFunctionReturn(0);
}

}  // namespace

// One level's stencil rows: per node its global molecule id, which of the 27 blocks are there, and the blocks.
// Rows equal to the bit share one copy of their blocks (at: a row's copy in a, refs: how many rows read it): a
// box lattice's coarse rows at its reference state are nearly all a few rows, and writing each (2 kB) was most of
// the coarse update's first touch. A row gets its blocks when first written (writable: zero, or a copy of the
// shared blocks when other rows still read them); until then it reads as zero.
struct LatticeGalerkin::Rows {
  static constexpr std::size_t kRow = kSlots * kBlock;
  std::vector<std::int64_t> id;
  std::vector<std::uint32_t> present;
  std::vector<int> at;    // per row: its blocks' copy in a, -1 for none yet
  std::vector<int> refs;  // per copy: the rows reading it
  std::vector<double> a;  // kRow per copy
  std::size_t populated = 0;  // copies of a's reserve faulted in ahead (populate)
  std::unordered_map<std::int64_t, int> index;
  std::vector<int> row;  // once complete: the row of each of this rank's nodes (owned order), -1 for none

  int find_or_add(std::int64_t g) {
    // try_emplace: no map node is made for a node already there (emplace made and freed one on each of the 1-8
    // calls a fine row makes, nearly all for rows seen before).
    const auto [it, added] = index.try_emplace(g, static_cast<int>(id.size()));
    if (added) {
      id.push_back(g);
      present.push_back(0);
      at.push_back(-1);
    }
    return it->second;
  }
  // Row r's blocks to write: its own copy (a new one may move a's storage: earlier pointers into a are void).
  double* writable(int r) {
    const int from = at[r];
    if (from >= 0 && refs[from] == 1) return a.data() + static_cast<std::size_t>(from) * kRow;
    const std::size_t copy = refs.size();
    // The copies about to be written, faulted in a batch at a time (one call instead of one trap a page) within
    // the reserve only: nothing beyond what the rows are about to use becomes resident.
    if (copy >= populated && a.capacity() >= (copy + 1) * kRow) {
      // Doubling from 1024 copies (2 MB) up to 1/16 of the reserve: a rank whose rows are nearly all shared (48
      // copies at 10^6) faults 2 MB, not 8.
      const std::size_t batch =
          std::min(std::max<std::size_t>(1024, populated), std::max<std::size_t>(1024, a.capacity() / kRow / 16));
      const std::size_t end = std::min(a.capacity() / kRow, copy + batch);
      populate(a.data() + copy * kRow, sizeof(double) * (end - copy) * kRow);
      populated = end;
    }
    a.resize(a.size() + kRow, 0.0);
    refs.push_back(1);
    at[r] = static_cast<int>(copy);
    double* to = a.data() + copy * kRow;
    if (from >= 0) {
      --refs[from];
      std::copy_n(a.data() + static_cast<std::size_t>(from) * kRow, kRow, to);
    }
    return to;
  }
  // Row r (no blocks yet) reads row s's.
  void share(int r, int s) {
    at[r] = at[s];
    ++refs[at[s]];
    present[r] = present[s];
  }
  const double* block(int r, int s) const {
    static const std::array<double, kRow> zero{};
    const double* base = at[r] < 0 ? zero.data() : a.data() + static_cast<std::size_t>(at[r]) * kRow;
    return base + s * kBlock;
  }
};

// Level l+1's numbers (coarsen, step 2): 8 * first unknown + free mask, of this rank's coarse nodes (from its
// own list, ascending ids) and of every other node the rank needs (through the directory).
struct LatticeGalerkin::Numbers {
  std::vector<std::int64_t> mine, asked;
  std::vector<PetscInt> packed, answers;
  std::vector<std::array<int, 3>> cplane;  // each of this rank's coarse nodes: its plane along each axis
  bool ascending = false;
  // Each coarse node's neighbour numbers by slot, looked up once (mask_held) and read by the later steps (each
  // lookup is two binary searches; the steps asked four times).
  mutable std::vector<PetscInt> slot_numbers;
  mutable std::vector<std::uint8_t> slot_order;  // and its present slots by column then (kSlots a node, the count)
  mutable std::vector<std::uint8_t> slot_count;
  mutable bool numbered = false;

  // This rank's coarse nodes on a dense box of their planes, per body (own_at: no search), when the box is not
  // much larger than the nodes (a box partition's slab); empty otherwise.
  struct Dense {
    std::array<int, 3> lo{}, n{};
    std::vector<int> c;  // the node's index in mine, -1 for none
  };
  std::vector<Dense> dense;
  // own(id of the node on planes q of body b) without the id: -2 when the dense box does not say.
  std::ptrdiff_t own_at(int b, const int q[3]) const {
    if (!ascending || b >= static_cast<int>(dense.size()) || dense[b].c.empty()) return -2;
    const Dense& d = dense[b];
    for (int a = 0; a < 3; ++a)
      if (q[a] < d.lo[a] || q[a] >= d.lo[a] + d.n[a]) return -1;
    return d.c[(static_cast<std::size_t>(q[0] - d.lo[0]) * d.n[1] + (q[1] - d.lo[1])) * d.n[2] + (q[2] - d.lo[2])];
  }
  std::ptrdiff_t own(std::int64_t g) const {
    const auto it = std::lower_bound(mine.begin(), mine.end(), g);
    return ascending && it != mine.end() && *it == g ? static_cast<std::ptrdiff_t>(it - mine.begin()) : -1;
  }
  PetscInt number(std::int64_t g) const {
    const std::ptrdiff_t c = own(g);
    return c >= 0 ? packed[c] : answers[std::lower_bound(asked.begin(), asked.end(), g) - asked.begin()];
  }
};

// Level 1 behind a shell (keep_level_one_as_stencil): its masked rows as coarsen leaves them (27 blocks a node by
// stencil slot, while level 2 is summed from them), then only their upper half (halve_level_one: the operator is
// symmetric, A_ji = A_ij^T), and per owned coarse node where its unknowns and each present slot's neighbour's
// are in the input: 8 * offset + free mask, offsets into [owned unknowns | the ghost values the scatter brings].
struct LatticeGalerkin::StencilOperator {
  Rows rows;                    // the whole rows; once halved (halve_level_one) row r's blocks of slots kHalf0 ..
                                // kSlots - 1 (the diagonal's first) are rows.a's blocks r * kHalf ...
  std::vector<PetscInt> first;  // per owned coarse node: 8 * its first unknown (local) + its free mask
  std::vector<PetscInt> col;    // per owned coarse node and slot (upper slots once halved): 8 * offset + mask of
                                // the neighbour; -1: no block
  PetscInt n = 0;               // owned unknowns
  bool symmetric = false;       // every block between two wholly free nodes symmetric to the bit (halve_level_one)
  std::vector<double> columns;  // when not, and few distinct rows: their blocks transposed (A_ij u_j's columns)
  Vec ghosts = nullptr;         // the neighbours' values owned elsewhere
  Vec shares = nullptr;         // what the transposed blocks add to them (a product's reverse scatter)
  VecScatter scatter = nullptr;
  // The pulled runs (pull_runs; stencil_product): none when -static_level_one_pull false or no node qualifies.
  std::vector<PullRuns::Run> runs;
  std::array<int, kHalf> delta{};
  std::array<int, kHalf - 1> lower{};
  std::vector<std::uint32_t> pushes;
  std::vector<double> soa;           // 3 x nodes: a product's input by component
  std::size_t pulled_nodes = 0;
  void release() {
    (void)VecDestroy(&ghosts);
    (void)VecDestroy(&shares);
    (void)VecScatterDestroy(&scatter);
  }
  ~StencilOperator() { release(); }
};

// A coarse node's present stencil slots (coarsen, step 4): each slot's column number, and the slots by column.
struct LatticeGalerkin::Neighbours {
  std::array<PetscInt, kSlots> jnum{};
  std::array<int, kSlots> order{};  // the present slots by column
  int norder = 0;
};


LatticeGalerkin::LatticeGalerkin(const LocalModel& model, const std::vector<std::uint8_t>& held, LatticeLevels levels)
    : model_(model), held_(held), levels_(std::move(levels)), csr_(levels_.planes.size()),
      coarse_(levels_.planes.size(), nullptr) {
  // Level 0's nodes are all owned molecules in order, and its numbering is the tangent's: not kept (memory).
  free_storage(levels_.owned_nodes[0]);
  free_storage(levels_.base[0]);
}

void LatticeGalerkin::index_molecules() const {
  ijk_.resize(model_.local);
  for (int i = 0; i < model_.local; ++i) {
    const auto ijk = model_.shape.body(model_.body[i]).index(model_.id[i]);
    ijk_[i] = {static_cast<int>(ijk[0]), static_cast<int>(ijk[1]), static_cast<int>(ijk[2])};
  }
}

LatticeGalerkin::~LatticeGalerkin() {
  for (Mat& m : coarse_)  // before level_one_: a shell refers to it
    if (m) (void)MatDestroy(&m);
}

PetscErrorCode LatticeGalerkin::applies(Mat fine, bool* ok) const {
  PetscFunctionBeginUser;
  FineParts parts;
  bool good = false;
  PetscCall(fine_parts(fine, &parts, &good));
  PetscInt bs = 1;
  PetscCall(MatGetBlockSize(fine, &bs));
  good = good && bs == 3;
  std::unordered_map<PetscInt, int> ghost;
  for (int j = model_.owned; j < model_.local; ++j) ghost.emplace(model_.block[j], j);
  index_molecules();
  auto near = [&](int i, int j) {
    if (j < 0 || model_.body[i] != model_.body[j]) return false;
    for (int d = 0; d < 3; ++d)
      if (std::abs(ijk_[i][d] - ijk_[j][d]) > 1) return false;
    return true;
  };
  for (Mat part : {parts.Ad, parts.Ao}) {
    if (!good || !part) continue;
    const PetscInt *ia, *ja;
    PetscInt rows;
    PetscBool done;
    PetscCall(MatGetRowIJ(part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &ia, &ja, &done));
    good = done && rows == 3 * model_.owned;
    // Whole 3x3 blocks (three consecutive columns from a multiple of 3), each within one plane step; the three
    // rows of a molecule have the same columns, so only the first is checked block by block.
    for (PetscInt r = 0; good && r < rows; ++r) {
      const PetscInt len = ia[r + 1] - ia[r];
      good = len % 3 == 0;
      if (r % 3) {
        const PetscInt f = ia[r - r % 3];
        good = good && len == ia[r - r % 3 + 1] - f && std::equal(ja + ia[r], ja + ia[r + 1], ja + f);
        continue;
      }
      for (PetscInt e = ia[r]; good && e < ia[r + 1]; e += 3) {
        const PetscInt c = part == parts.Ad ? ja[e] : parts.garray[ja[e]];
        const PetscInt c2 = part == parts.Ad ? ja[e + 2] : parts.garray[ja[e + 2]];
        good = c % 3 == 0 && c2 == c + 2;
        int j = -1;
        if (part == parts.Ad) {
          j = static_cast<int>(c / 3);
        } else {
          const auto it = ghost.find(c / 3);
          if (it != ghost.end()) j = it->second;
        }
        good = good && near(static_cast<int>(r / 3), j);
      }
    }
    PetscCall(MatRestoreRowIJ(part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &ia, &ja, &done));
  }
  free_storage(ijk_);
  int mine = good ? 1 : 0, all = 0;
  PetscCallMPI(MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, model_.comm));
  *ok = all == 1;
  PetscFunctionReturn(0);
}

// Level l+1's operator from level l's: from the fine matrix (l = 0) or from level l's stencil rows. next receives
// level l+1's rows (this rank's nodes, owned order, held components zeroed), and coarse_[l + 1] its matrix.
PetscErrorCode LatticeGalerkin::coarsen(int l, Mat fine, const Stream* stream, const Rows* stencil, Rows& next) {
  PetscFunctionBeginUser;
  Rows acc;
  PetscCall(accumulate_rows(l, fine, stream, stencil, acc));
  Numbers num;
  PetscCall(number_coarse_nodes(l, acc, num));
  PetscCall(send_rows_to_owners(l, num, acc));
  std::vector<PetscInt> dnnz(levels_.count[l + 1], 0), onnz(levels_.count[l + 1], 0);
  PetscCall(mask_held(l, num, acc, dnnz, onnz));
  if (l == 0 && level_one_)
    PetscCall(stencil_operator(num, acc));
  else
    PetscCall(fill_coarse_matrix(l, num, acc, dnnz, onnz));
  free_storage(acc.index);
  next = std::move(acc);
  PetscFunctionReturn(0);
}

// 1. Every fine node's row, a block at a time: T = sum_j A_ij w_jJ over a 4x4x4 box of coarse nodes J, then
//    row I += w_iI T for the coarse nodes I that i interpolates from. Rows of coarse nodes owned elsewhere are
//    collected too and sent in step 3.
PetscErrorCode LatticeGalerkin::accumulate_rows(int l, Mat fine, const Stream* stream, const Rows* stencil,
                                                Rows& acc) const {
  PetscFunctionBeginUser;
  const Body& shape = model_.shape;
  const auto& planes = levels_.planes;
  const int nb = shape.bodies();
  // weights[b][a][p]: where plane p of level l sits among level l+1's planes.
  std::vector<std::array<std::vector<AxisWeights>, 3>> weights(nb);
  for (int b = 0; b < nb; ++b)
    for (int a = 0; a < 3; ++a) weights[b][a] = axis_weights(planes[l][b][a], planes[l + 1][b][a]);

  // The fine matrix's arrays (level 0).
  FineParts parts;
  const PetscInt *dia = nullptr, *dja = nullptr, *oia = nullptr, *oja = nullptr;
  const PetscScalar *dv = nullptr, *ov = nullptr;
  std::vector<int> off_local;  // local molecule of each off-diagonal column
  if (l == 0 && !stream) {
    bool ok = false;
    PetscCall(fine_parts(fine, &parts, &ok));
    PetscCheck(ok, model_.comm, PETSC_ERR_SUP, "lattice Galerkin product: the tangent is not AIJ");
    PetscInt rows;
    PetscBool done;
    PetscCall(MatGetRowIJ(parts.Ad, 0, PETSC_FALSE, PETSC_FALSE, &rows, &dia, &dja, &done));
    PetscCall(MatSeqAIJGetArrayRead(parts.Ad, &dv));
    if (parts.Ao) {
      PetscInt cols;
      PetscCall(MatGetRowIJ(parts.Ao, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oia, &oja, &done));
      PetscCall(MatSeqAIJGetArrayRead(parts.Ao, &ov));
      PetscCall(MatGetSize(parts.Ao, nullptr, &cols));
      std::unordered_map<PetscInt, int> ghost;
      for (int j = model_.owned; j < model_.local; ++j) ghost.emplace(model_.block[j], j);
      off_local.resize(cols);
      for (PetscInt c = 0; c < cols; ++c) {
        const auto it = ghost.find(parts.garray[c] / 3);
        off_local[c] = it == ghost.end() ? -1 : it->second;  // -1: not a molecule of this rank's stencils
      }
    }
  }
  const auto& nodes = levels_.owned_nodes[l];  // level 0: all owned molecules, 0 .. owned - 1
  const std::size_t nnodes = l == 0 ? static_cast<std::size_t>(model_.owned) : nodes.size();
  {
    // About this rank's coarse nodes and a layer more: no regrowth (a copy and fresh pages) while filling.
    const std::size_t named = l + 1 < static_cast<int>(levels_.named.size()) ? levels_.named[l + 1] : 0;
    const std::size_t expect = std::max(levels_.owned_nodes[l + 1].size() * 5 / 4 + 64, named);
    acc.id.reserve(expect), acc.present.reserve(expect), acc.at.reserve(expect), acc.refs.reserve(expect);
    acc.a.reserve(std::min(named, expect) * kSlots * kBlock);  // address space: only written copies are touched
    acc.index.reserve(expect);
  }
  std::array<double, kSlots * kBlock> blocks{};
  std::array<double, 64 * kBlock> T{};
  // A row's neighbour planes along one axis (AxisStep triple, relative to its 4x4x4 box) depend only on its plane
  // and take a few distinct values (interior planes on and between coarse planes, the planes near the ends):
  // each plane's class, found once here instead of once a row.
  struct AxisClass {
    std::array<AxisStep, 3> st{};
    std::uint32_t outside = 0, beyond = 0;
  };
  auto same_step = [](const AxisStep& x, const AxisStep& y) {
    if (x.n != y.n) return false;
    for (int k = 0; k < x.n; ++k)
      if (x.J[k] != y.J[k] || std::memcmp(&x.w[k], &y.w[k], sizeof(double)) != 0) return false;
    return true;
  };
  std::vector<std::array<std::vector<AxisClass>, 3>> axis_classes(nb);
  std::vector<std::array<std::vector<int>, 3>> axis_class_of(nb);  // [b][a][p]
  for (int b = 0; b < nb; ++b)
    for (int a = 0; a < 3; ++a) {
      const auto& wa = weights[b][a];
      auto& classes = axis_classes[b][a];
      axis_class_of[b][a].resize(wa.size());
      for (std::size_t p = 0; p < wa.size(); ++p) {
        AxisClass ac;
        const int c0 = wa[p].at[0] - 1;
        for (int d = 0; d < 3; ++d) {
          const long q = static_cast<long>(p) + d - 1;
          if (q < 0 || q >= static_cast<long>(wa.size())) {
            ac.outside |= kSlotsAt[a][d];
            continue;
          }
          AxisStep& st = ac.st[d];
          st.n = wa[q].n;
          for (int k = 0; k < wa[q].n; ++k) {
            st.J[k] = wa[q].at[k] - c0, st.w[k] = wa[q].w[k];
            if (st.J[k] < 0 || st.J[k] >= 4) ac.beyond |= kSlotsAt[a][d];
          }
        }
        std::size_t c = 0;
        for (; c < classes.size(); ++c)
          if (classes[c].outside == ac.outside && classes[c].beyond == ac.beyond &&
              same_step(classes[c].st[0], ac.st[0]) && same_step(classes[c].st[1], ac.st[1]) &&
              same_step(classes[c].st[2], ac.st[2]))
            break;
        if (c == classes.size()) classes.push_back(ac);
        axis_class_of[b][a][p] = static_cast<int>(c);
      }
    }
  // Row classes: rows of one class (the same axis classes) whose blocks are equal to the bit have the same box T
  // (sum_blocks: the same operations on the same numbers), which is then summed once for the class. On a box
  // lattice at its reference state (the first tangent of a solve) nearly every row equals one of a few rows of
  // its class: a class keeps up to kVariants distinct rows (variants, chained by next), because its first row
  // may be an exception (a row next to a held face has masked blocks; the class of the planes between coarse
  // planes then starts on the plane next to it, and with one row a class every other row of that class, half the
  // lattice, was streamed and summed again).
  struct RowClass {
    std::uint32_t present = 0;
    std::vector<double> src;  // the class's first row's blocks (kSlots of them, absent ones zero)
    std::vector<double> T;    // the box sums
    std::uint64_t touched = 0;
    std::array<double, 8> w{};
    std::array<int, 8> shift{};
    // The first row's inputs (ForceModel::tangent_blocks_unless) when it and its neighbours are wholly free
    // and within the stencil: a row of the class with the same inputs has the same blocks, not streamed at all.
    bool has_inputs = false;
    std::vector<int> slots;  // each end's slot (the connections' neighbours, then the terms' columns)
    std::vector<double> inputs;
    int next = -1;  // the class's next variant
  };
  constexpr int kVariants = 4;  // a deformed state's rows are all distinct: a few tries a row, then the general way
  int created = -1;  // the variant the last scatter made or used, if it has no inputs yet
  constexpr std::size_t kMaxClasses = 8192;  // a pending contribution is 8 class + k in 16 bits
  std::vector<RowClass> row_classes;
  std::vector<std::vector<int>> class_at(nb);  // [b][(x class * ny + y class) * nz + z class] -> row_classes
  for (int b = 0; b < nb; ++b)
    class_at[b].assign(axis_classes[b][0].size() * axis_classes[b][1].size() * axis_classes[b][2].size(), -1);
  // Each coarse node's row by its planes on a dense box per body (the planes this rank's nodes interpolate
  // from), so that a row seen before is a table read, not its id and a hash lookup (1-8 a fine row); a box much
  // larger than the rows (a scattered part) keeps the lookups. Rows are numbered in the same order either way.
  struct RowBox {
    std::array<int, 3> lo{}, n{};
    std::vector<int> r;  // the row, -1 for none yet
  };
  std::vector<RowBox> row_box(nb);
  {
    std::vector<std::array<int, 6>> span(nb, {INT_MAX, INT_MAX, INT_MAX, INT_MIN, INT_MIN, INT_MIN});
    std::vector<std::size_t> count(nb, 0);
    for (std::size_t n = 0; n < nnodes; ++n) {
      const int i = l == 0 ? static_cast<int>(n) : nodes[n];
      const int b = model_.body[i];
      ++count[b];
      for (int a = 0; a < 3; ++a) {
        const int p = l == 0 ? ijk_[i][a] : position(planes[l][b][a], ijk_[i][a]);
        span[b][a] = std::min(span[b][a], p), span[b][3 + a] = std::max(span[b][3 + a], p);
      }
    }
    for (int b = 0; b < nb; ++b) {
      if (!count[b]) continue;
      RowBox& box = row_box[b];
      std::size_t volume = 1;
      for (int a = 0; a < 3; ++a) {
        const AxisWeights &first = weights[b][a][span[b][a]], &last = weights[b][a][span[b][3 + a]];
        box.lo[a] = first.at[0], box.n[a] = last.at[last.n - 1] - first.at[0] + 1;
        volume *= static_cast<std::size_t>(box.n[a]);
      }
      if (volume <= count[b] + 4096) box.r.assign(volume, -1);
    }
  }
  // A coarse row's contributions of class sums are kept as a list (class, k) until the row takes another (then
  // the list is summed first, in order) or the rows are complete; rows with equal lists are then equal to the
  // bit (the same operations in the same order from zero), so one is summed and the others copied.
  constexpr int kPending = 27;                // a coarse node takes at most 3 fine planes an axis
  constexpr std::uint8_t kSummed = 0x80;      // the list was summed into the row; the low bits keep its length
  std::vector<std::uint16_t> pending;         // kPending a coarse row
  std::vector<std::uint8_t> npending;         // its length, | kSummed
  auto sum_pending = [&](int r) {
    if (npending[r] & kSummed) return;
    double* to = acc.writable(r);
    for (int q = 0; q < npending[r]; ++q) {
      const int code = pending[static_cast<std::size_t>(r) * kPending + q];
      const RowClass& rc = row_classes[code >> 3];
      std::uint32_t bits;
      spread_blocks(rc.touched, rc.T.data(), 1, &to, &rc.w[code & 7], &rc.shift[code & 7], &bits);
      acc.present[r] |= bits;
    }
    npending[r] |= kSummed;
  };
  // Every touched J within one coarse plane of every I (the row's own plane's step: J of its coarse nodes), so
  // the slot arithmetic of spread_blocks cannot wrap.
  auto check_touched = [](std::uint64_t touched, const AxisSteps& steps) -> PetscErrorCode {
    std::array<int, 3> lo{4, 4, 4}, hi{-1, -1, -1};
    for (std::uint64_t rest = touched; rest; rest &= rest - 1) {
      const int t = __builtin_ctzll(rest), tc[3] = {t % 4, t / 4 % 4, t / 16};
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], tc[a]), hi[a] = std::max(hi[a], tc[a]);
    }
    for (int a = 0; a < 3; ++a)
      PetscCheck(lo[a] >= steps[a][1].J[steps[a][1].n - 1] - 1 && hi[a] <= steps[a][1].J[0] + 1, PETSC_COMM_SELF,
                 PETSC_ERR_PLIB, "lattice Galerkin product: a coarse block beyond the 27-point stencil");
    return PetscErrorCode(0);
  };
  // Row i (level l, planes p) of level l's operator, its blocks src by stencil slot (present: which), into the
  // rows of the coarse nodes I that i interpolates from.
  // known >= 0: the row's blocks are that variant's first row's (equal inputs), so its sums are taken unseen.
  auto scatter = [&](int b, const std::array<int, 3>& p, std::uint32_t present, const double* src,
                     int known = -1) -> PetscErrorCode {
    const BoxGeometry& box = shape.body(b);
    const std::array<const AxisWeights*, 3> wi{&weights[b][0][p[0]], &weights[b][1][p[1]], &weights[b][2][p[2]]};
    std::array<int, 3> c0, cls;
    for (int a = 0; a < 3; ++a) c0[a] = wi[a]->at[0] - 1, cls[a] = axis_class_of[b][a][p[a]];
    // Each axis's three neighbour planes among the coarse planes from c0 (sum_blocks reads them for every slot);
    // a plane outside the lattice or a coarse node outside the 4x4x4 box is an error only for a present slot.
    const std::array<const AxisClass*, 3> ac{&axis_classes[b][0][cls[0]], &axis_classes[b][1][cls[1]],
                                             &axis_classes[b][2][cls[2]]};
    const AxisSteps steps{ac[0]->st, ac[1]->st, ac[2]->st};
    const std::uint32_t outside = ac[0]->outside | ac[1]->outside | ac[2]->outside;
    const std::uint32_t beyond = ac[0]->beyond | ac[1]->beyond | ac[2]->beyond;
    PetscCheck(!(present & outside), PETSC_COMM_SELF, PETSC_ERR_PLIB, "lattice Galerkin product: a block outside the lattice");
    PetscCheck(!(present & beyond), PETSC_COMM_SELF, PETSC_ERR_PLIB,
               "lattice Galerkin product: a coarse node outside the box");
    // The coarse rows first (find_or_add may move the rows' storage), then their blocks.
    RowBox& rb = row_box[b];
    std::array<int, 8> rows, shift;
    std::array<double, 8> w;
    int nrows = 0;
    for (int x = 0; x < wi[0]->n; ++x)
      for (int y = 0; y < wi[1]->n; ++y)
        for (int z = 0; z < wi[2]->n; ++z, ++nrows) {
          const int I[3] = {wi[0]->at[x], wi[1]->at[y], wi[2]->at[z]};
          w[nrows] = wi[0]->w[x] * wi[1]->w[y] * wi[2]->w[z];
          int* seen = nullptr;
          if (!rb.r.empty())
            seen = &rb.r[(static_cast<std::size_t>(I[0] - rb.lo[0]) * rb.n[1] + (I[1] - rb.lo[1])) * rb.n[2] +
                         (I[2] - rb.lo[2])];
          if (seen && *seen >= 0) {
            rows[nrows] = *seen;
          } else {
            rows[nrows] = acc.find_or_add(box.id(planes[l + 1][b][0][I[0]], planes[l + 1][b][1][I[1]],
                                                 planes[l + 1][b][2][I[2]]));
            if (seen) *seen = rows[nrows];
          }
          // J - I along each axis is -1, 0 or 1 (a fine neighbour's enclosing planes are at most one coarse
          // plane from the node's own), so slot = the box index shifted by the node's place in the box.
          shift[nrows] = slot_of(c0[0] - I[0], c0[1] - I[1], c0[2] - I[2]);
        }
    if (npending.size() < acc.id.size()) {
      npending.resize(acc.id.size(), 0);
      pending.resize(acc.id.size() * kPending);
    }
    // The row's class: its box sums reused when its blocks are the class's to the bit.
    int& at = class_at[b][(static_cast<std::size_t>(cls[0]) * axis_classes[b][1].size() + cls[1]) *
                              axis_classes[b][2].size() +
                          cls[2]];
    int e = known;
    int variants = 0, tail = -1;
    for (int v = at; e < 0 && v >= 0; v = row_classes[v].next, ++variants) {
      // The whole rows at once (one call instead of one a slot): their absent slots are zero on every path, and
      // a difference there would only send the row the general way.
      const RowClass& rc = row_classes[v];
      if (rc.present == present && std::memcmp(rc.src.data(), src, sizeof(double) * kSlots * kBlock) == 0) e = v;
      tail = v;
    }
    if (e < 0 && variants < kVariants && row_classes.size() < kMaxClasses) {
      const int made = static_cast<int>(row_classes.size());
      (tail >= 0 ? row_classes[tail].next : at) = made;
      RowClass& rc = row_classes.emplace_back();
      rc.present = present;
      rc.src.assign(src, src + kSlots * kBlock);
      rc.T.resize(64 * kBlock);
      rc.touched = sum_blocks(present, src, steps, rc.T.data());
      PetscCall(check_touched(rc.touched, steps));
      rc.w = w, rc.shift = shift;
      e = made;
    }
    // A variant with no inputs yet takes this row's, when they were kept (flush): equal inputs, equal blocks.
    if (e >= 0 && known < 0 && !row_classes[e].has_inputs) created = e;
    if (e >= 0) {
      for (int k = 0; k < nrows; ++k) {
        const int r = rows[k];
        std::uint8_t& n = npending[r];
        if (!(n & kSummed) && n < kPending) {
          pending[static_cast<std::size_t>(r) * kPending + n++] = static_cast<std::uint16_t>(8 * e + k);
          continue;
        }
        sum_pending(r);
        double* to = acc.writable(r);
        std::uint32_t bits;
        const RowClass& rc = row_classes[e];
        spread_blocks(rc.touched, rc.T.data(), 1, &to, &w[k], &shift[k], &bits);
        acc.present[r] |= bits;
      }
      return PetscErrorCode(0);
    }
    const std::uint64_t touched = sum_blocks(present, src, steps, T.data());
    PetscCall(check_touched(touched, steps));
    std::array<double*, 8> to;
    std::array<std::uint32_t, 8> bits;
    for (int k = 0; k < nrows; ++k) sum_pending(rows[k]), acc.writable(rows[k]);
    for (int k = 0; k < nrows; ++k) to[k] = acc.a.data() + static_cast<std::size_t>(acc.at[rows[k]]) * Rows::kRow;
    spread_blocks(touched, T.data(), nrows, to.data(), w.data(), shift.data(), bits.data());
    for (int k = 0; k < nrows; ++k) acc.present[rows[k]] |= bits[k];
    return PetscErrorCode(0);
  };
  if (l == 0 && stream) {
    // The fine blocks straight from the force model (matrix-free: no fine matrix), collected while they belong
    // to one row and scattered as a matrix row is. Held components as in the assembled tangent: their rows
    // dropped, their columns zero. A row may come in several runs (a term's blocks): the sum is the same.
    int row = -1;
    std::uint32_t present = 0;
    bool off_stencil = false;
    // Gershgorin's bound on the Jacobi-scaled operator, row by row as ForceModel::jacobi_gershgorin sums it (the
    // diagonal and the off-diagonal magnitudes of each free component, in the stream's order; a held row's is 1).
    double diag[3] = {}, off[3] = {}, bound = 1.0;
    // The last row's inputs (springs only, below), while it may start a class.
    struct Inputs {
      int row = -1;  // the row they are of, when it could start a class (free, within the stencil)
      std::vector<int> slots;
      std::vector<double> inputs;
    } last;
    auto flush = [&]() -> PetscErrorCode {
      for (int r = 0; r < 3 && row >= 0; ++r)
        if (!held_[3 * row + r]) bound = std::max(bound, 1.0 + off[r] / diag[r]);
      for (int r = 0; r < 3; ++r) diag[r] = off[r] = 0.0;
      if (row >= 0 && present) {
        created = -1;
        PetscCall(scatter(model_.body[row], ijk_[row], present, blocks.data()));
        if (created >= 0 && row == last.row) {  // a class made from a row whose inputs were kept takes them
          RowClass& rc = row_classes[created];
          rc.has_inputs = true;
          rc.slots = std::move(last.slots);
          rc.inputs = std::move(last.inputs);
        }
      }
      for (std::uint32_t rest = present; rest; rest &= rest - 1)
        std::fill_n(blocks.data() + __builtin_ctz(rest) * kBlock, kBlock, 0.0);
      present = 0, row = -1;
      return PetscErrorCode(0);
    };
    // The row's own values are read once a row, and the stencil check skips the body lookup for one body: the
    // same operations on the blocks in the same order.
    const std::uint8_t* held = held_.data();
    const std::array<int, 3>* ijk = ijk_.data();
    const bool one_body = shape.bodies() == 1;
    // One body: each local molecule's lattice index packed in 21 bits an axis, bit 63 when a component is held, so
    // that known's test of a row's ends (wholly free, within one plane) is one load and one subtraction an end:
    // key[j] - key[i] + (1, 1, 1) has every field in 0..2 exactly when j is free and a stencil neighbour of the free
    // i (an offset beyond the stencil leaves its field, borrowed from or not, outside 0..2; a held j puts bit 63 in
    // the z field). With cells a row shows 45 ends (18 springs', 27 cells' columns). Empty: the general test.
    constexpr int kBits = 21;
    constexpr std::uint64_t kField = (1u << kBits) - 1, kHeldBit = std::uint64_t{1} << 63;
    constexpr std::uint64_t kOnes = 1 | std::uint64_t{1} << kBits | std::uint64_t{1} << 2 * kBits;
    std::vector<std::uint64_t> key;
    if (one_body) {
      const auto& n = shape.body(0).n;
      if (n[0] < static_cast<long>(kField) - 2 && n[1] < static_cast<long>(kField) - 2 &&
          n[2] < static_cast<long>(kField) - 2) {
        key.resize(model_.local);
        for (int j = 0; j < model_.local; ++j)
          key[j] = static_cast<std::uint64_t>(ijk[j][0]) | static_cast<std::uint64_t>(ijk[j][1]) << kBits |
                   static_cast<std::uint64_t>(ijk[j][2]) << 2 * kBits |
                   ((held[3 * j] | held[3 * j + 1] | held[3 * j + 2]) ? kHeldBit : 0);
      }
    }
    bool row_free = false;
    std::array<int, 3> row_ijk{};
    auto put = [&](int i, int j, const double K[9]) -> PetscErrorCode {
      if (i != row) {
        PetscCall(flush());
        row = i;
        row_free = !(held[3 * i] | held[3 * i + 1] | held[3 * i + 2]);
        row_ijk = ijk[i];
      }
      // Both molecules free, two of them, one plane apart at most (nearly every block): the general path's
      // operations on the block read once, with no masks.
      if (row_free && i != j) {
        const std::uint8_t* hj = held + 3 * j;
        const unsigned e0 = static_cast<unsigned>(ijk[j][0] - row_ijk[0] + 1),
                       e1 = static_cast<unsigned>(ijk[j][1] - row_ijk[1] + 1),
                       e2 = static_cast<unsigned>(ijk[j][2] - row_ijk[2] + 1);
        if (!(hj[0] | hj[1] | hj[2]) && e0 <= 2 && e1 <= 2 && e2 <= 2 && (one_body || model_.body[j] == model_.body[i])) {
          double k[kBlock];
          std::memcpy(k, K, sizeof k);
          double o0 = off[0], o1 = off[1], o2 = off[2];
          o0 += std::abs(k[0]), o0 += std::abs(k[1]), o0 += std::abs(k[2]);
          o1 += std::abs(k[3]), o1 += std::abs(k[4]), o1 += std::abs(k[5]);
          o2 += std::abs(k[6]), o2 += std::abs(k[7]), o2 += std::abs(k[8]);
          off[0] = o0, off[1] = o1, off[2] = o2;
          const int s = static_cast<int>(e0 + 3 * e1 + 9 * e2);
          double* to = blocks.data() + s * kBlock;
          for (int e = 0; e < kBlock; ++e) to[e] += k[e];
          present |= 1u << s;
          return PetscErrorCode(0);
        }
      }
      const bool free = row_free && !(held[3 * j] | held[3 * j + 1] | held[3 * j + 2]);
      if (free && i != j) {
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) off[r] += std::abs(K[3 * r + c]);
      } else {
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) {
            if (held[3 * i + r] || held[3 * j + c]) continue;
            if (i == j && r == c)
              diag[r] += K[4 * r];
            else
              off[r] += std::abs(K[3 * r + c]);
          }
      }
      const int d0 = ijk[j][0] - row_ijk[0], d1 = ijk[j][1] - row_ijk[1], d2 = ijk[j][2] - row_ijk[2];
      if (std::abs(d0) > 1 || std::abs(d1) > 1 || std::abs(d2) > 1 ||
          (!one_body && model_.body[j] != model_.body[i])) {
        off_stencil = true;
        return PetscErrorCode(0);
      }
      const int s = slot_of(d0, d1, d2);
      double* to = blocks.data() + s * kBlock;
      if (free) {
        for (int e = 0; e < kBlock; ++e) to[e] += K[e];
        present |= 1u << s;
        return PetscErrorCode(0);
      }
      bool any = false;
      for (int r = 0; r < 3; ++r) {
        if (held[3 * i + r]) continue;
        any = true;
        for (int c = 0; c < 3; ++c)
          if (!held[3 * j + c]) to[3 * r + c] += K[3 * r + c];
      }
      if (any) present |= 1u << s;
      return PetscErrorCode(0);
    };
    using Put = decltype(put);
    auto add = [](void* ctx, int i, int j, const double K[9]) -> PetscErrorCode {
      return (*static_cast<Put*>(ctx))(i, j, K);
    };
    // Each row's inputs first (springs only, or at rest with terms that have rest rows); a row whose inputs are its
    // class's first row's (to the bit, and every molecule of both wholly free and within the stencil) is not
    // streamed: its blocks, Gershgorin sums and so its contributions are the first row's. The rows come in the
    // same order either way, so the coarse rows sum the same numbers in the same order.
    PetscErrorCode known_error = 0;
    auto known = [&](int i, const int* ends, int n, const double* inputs, int m) -> bool {
      if (known_error) return true;  // reported after the stream
      // The row before it first (its contributions come first; it may make the class this row's inputs meet).
      known_error = flush();
      last.row = -1;
      if (known_error) return true;
      if (held[3 * i] | held[3 * i + 1] | held[3 * i + 2]) return false;
      const int b = model_.body[i];
      std::array<int, 64> slots;  // the springs' ends and the terms' columns (a cell row's 27)
      if (n > 64) return false;
      if (!key.empty()) {
        const std::uint64_t from = kOnes - key[i];
        unsigned bad = 0;
        for (int q = 0; q < n; ++q) {
          const std::uint64_t d = key[ends[q]] + from;
          const unsigned e0 = static_cast<unsigned>(d & kField), e1 = static_cast<unsigned>(d >> kBits & kField);
          const std::uint64_t e2 = d >> 2 * kBits;
          bad |= (e0 > 2) | (e1 > 2) | (e2 > 2);
          slots[q] = static_cast<int>(e0 + 3 * e1 + 9 * static_cast<unsigned>(e2));
        }
        if (bad) return false;
      } else {
        for (int q = 0; q < n; ++q) {
          const int j = ends[q];
          const unsigned e0 = static_cast<unsigned>(ijk[j][0] - ijk[i][0] + 1),
                         e1 = static_cast<unsigned>(ijk[j][1] - ijk[i][1] + 1),
                         e2 = static_cast<unsigned>(ijk[j][2] - ijk[i][2] + 1);
          if ((held[3 * j] | held[3 * j + 1] | held[3 * j + 2]) || e0 > 2 || e1 > 2 || e2 > 2 ||
              model_.body[j] != b)
            return false;
          slots[q] = static_cast<int>(e0 + 3 * e1 + 9 * e2);
        }
      }
      const std::array<int, 3>& p = ijk[i];
      const int at = class_at[b][(static_cast<std::size_t>(axis_class_of[b][0][p[0]]) * axis_classes[b][1].size() +
                                  axis_class_of[b][1][p[1]]) *
                                     axis_classes[b][2].size() +
                                 axis_class_of[b][2][p[2]]];
      int variants = 0;
      for (int v = at; v >= 0; v = row_classes[v].next, ++variants) {
        const RowClass& rc = row_classes[v];
        if (!rc.has_inputs || static_cast<int>(rc.slots.size()) != n || static_cast<int>(rc.inputs.size()) != m ||
            !std::equal(rc.slots.begin(), rc.slots.end(), slots.begin()) ||
            std::memcmp(rc.inputs.data(), inputs, sizeof(double) * m) != 0)
          continue;
        known_error = scatter(b, p, rc.present, rc.src.data(), v);
        return true;
      }
      if (variants < kVariants) {  // this row may start the class or a variant of it
        last.row = i;
        last.slots.assign(slots.begin(), slots.begin() + n);
        last.inputs.assign(inputs, inputs + m);
      }
      return false;
    };
    using Known = decltype(known);
    auto ask = [](void* ctx, int i, const int* ends, int n, const double* inputs, int m) -> bool {
      return (*static_cast<Known*>(ctx))(i, ends, n, inputs, m);
    };
    PetscCall(stream->forces->tangent_blocks_unless(stream->x, add, &put, ask, &known, ijk_.data()));
    PetscCall(known_error);
    PetscCall(flush());
    jacobi_bound_ = bound;
    // The symbol of the interior rows (symbol_bound): the classes' first rows whose blocks all join wholly free
    // molecules and fill the stencil's whole pattern (every slot any such row has), a few dozen at a box's
    // reference state, thousands at a deformed one (then none is looked at).
    std::uint32_t pattern = 0;
    for (const RowClass& rc : row_classes)
      if (rc.has_inputs) pattern |= rc.present;
    std::size_t interior = 0;
    for (const RowClass& rc : row_classes) interior += rc.has_inputs && rc.present == pattern;
    symbol_bound_ = interior > kSymbolRows ? -1.0 : 0.0;
    if (interior <= kSymbolRows) {
      std::vector<const RowClass*> distinct;  // classes of other axis positions often have the same blocks
      for (const RowClass& rc : row_classes) {
        if (!rc.has_inputs || rc.present != pattern) continue;
        if (std::any_of(distinct.begin(), distinct.end(), [&](const RowClass* d) { return d->src == rc.src; }))
          continue;
        distinct.push_back(&rc);
        symbol_bound_ = std::max(symbol_bound_, jacobi_symbol_max(rc.src.data()));
      }
      (void)PetscInfo(nullptr, "lattice Galerkin: the symbol of %zu distinct interior rows\n", distinct.size());
    }
    PetscCheck(!off_stencil, PETSC_COMM_SELF, PETSC_ERR_SUP,
               "lattice Galerkin product: the tangent has a block beyond the lattice stencil");
  }
  for (std::size_t n = 0; n < (l == 0 && stream ? 0 : nnodes); ++n) {
    const int i = l == 0 ? static_cast<int>(n) : nodes[n];
    const int b = model_.body[i];
    std::array<int, 3> p;
    for (int a = 0; a < 3; ++a) p[a] = l == 0 ? ijk_[i][a] : position(planes[l][b][a], ijk_[i][a]);
    // The node's blocks by stencil slot.
    std::uint32_t present = 0;
    const double* src = nullptr;
    bool off_stencil = false;
    if (l == 0) {
      blocks.fill(0.0);
      // Rows come in whole 3x3 blocks (applies() checked): three values a block column.
      auto put = [&](int r, int j, const PetscScalar* v) {
        if (j < 0) {
          off_stencil = true;
          return;
        }
        const int d0 = ijk_[j][0] - ijk_[i][0], d1 = ijk_[j][1] - ijk_[i][1], d2 = ijk_[j][2] - ijk_[i][2];
        // The pattern was checked once (applies()); a block added since (a new contact pair) is not a stencil's.
        if (std::abs(d0) > 1 || std::abs(d1) > 1 || std::abs(d2) > 1 || model_.body[j] != b) {
          off_stencil = true;
          return;
        }
        const int s = slot_of(d0, d1, d2);
        double* to = blocks.data() + s * kBlock + 3 * r;
        to[0] = v[0], to[1] = v[1], to[2] = v[2];
        present |= 1u << s;
      };
      for (int r = 0; r < 3; ++r) {
        if (held_[3 * i + r]) continue;  // the identity row of a held component: not in the masked product
        const PetscInt row = 3 * i + r;
        for (PetscInt e = dia[row]; e < dia[row + 1]; e += 3) put(r, static_cast<int>(dja[e] / 3), dv + e);
        if (oia)
          for (PetscInt e = oia[row]; e < oia[row + 1]; e += 3) put(r, off_local[oja[e]], ov + e);
      }
      PetscCheck(!off_stencil, PETSC_COMM_SELF, PETSC_ERR_SUP,
                 "lattice Galerkin product: the tangent has a block beyond the lattice stencil");
      src = blocks.data();
    } else {
      const int r = stencil->row[n];
      if (r < 0) continue;  // every component held
      present = stencil->present[r];
      src = stencil->block(r, 0);
    }
    if (!present) continue;
    PetscCall(scatter(b, p, present, src));
  }
  // The rows still holding only their lists: one summed for each distinct list, the others copied from it.
  {
    auto list = [&](std::size_t r) { return pending.data() + r * kPending; };
    std::unordered_map<std::uint64_t, int> summed;  // a list's hash -> the row summed for it
    for (std::size_t r = 0; r < npending.size(); ++r) {
      const int n = npending[r];
      if (n & kSummed) continue;
      std::uint64_t h = 1469598103934665603ull ^ static_cast<std::uint64_t>(n);
      for (int q = 0; q < n; ++q) h = (h ^ list(r)[q]) * 1099511628211ull;
      const auto [it, added] = summed.try_emplace(h, static_cast<int>(r));
      const std::size_t s = static_cast<std::size_t>(it->second);
      if (!added && (npending[s] & ~kSummed) == n && std::equal(list(r), list(r) + n, list(s))) {
        acc.share(static_cast<int>(r), static_cast<int>(s));
        npending[r] |= kSummed;
        continue;
      }
      sum_pending(static_cast<int>(r));
    }
  }
  if (l == 0 && !stream) {
    PetscInt rows;
    PetscBool done;
    PetscCall(MatSeqAIJRestoreArrayRead(parts.Ad, &dv));
    PetscCall(MatRestoreRowIJ(parts.Ad, 0, PETSC_FALSE, PETSC_FALSE, &rows, &dia, &dja, &done));
    if (parts.Ao) {
      PetscCall(MatSeqAIJRestoreArrayRead(parts.Ao, &ov));
      PetscCall(MatRestoreRowIJ(parts.Ao, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oia, &oja, &done));
    }
  }
  PetscFunctionReturn(0);
}

// 2. The level l+1 numbers (8 first unknown + free mask) of every row collected and of every stencil
//    neighbour of this rank's coarse nodes: this rank's own from its list (ascending ids), the others through
//    the directory (asking for every neighbour was, at 10^6 molecules, the run's peak memory).
PetscErrorCode LatticeGalerkin::number_coarse_nodes(int l, const Rows& acc, Numbers& num) const {
  PetscFunctionBeginUser;
  const Body& shape = model_.shape;
  const auto& planes = levels_.planes;
  auto free_mask = [&](int i) {
    int m = 0;
    for (int k = 0; k < 3; ++k)
      if (!held_[3 * i + k]) m |= 1 << k;
    return m;
  };
  const auto& cnodes = levels_.owned_nodes[l + 1];
  const auto& cbase = levels_.base[l + 1];
  auto& mine = num.mine;
  auto& asked = num.asked;
  auto& packed = num.packed;
  auto& cplane = num.cplane;
  mine.resize(cnodes.size()), packed.resize(cnodes.size()), cplane.resize(cnodes.size());
  for (std::size_t c = 0; c < cnodes.size(); ++c) {
    const int i = cnodes[c];
    mine[c] = model_.id[i], packed[c] = 8 * cbase[c] + free_mask(i);
    const int b = model_.body[i];
    for (int a = 0; a < 3; ++a) cplane[c][a] = position(planes[l + 1][b][a], ijk_[i][a]);
  }
  num.ascending = std::is_sorted(mine.begin(), mine.end());
  {
    const int nb = shape.bodies();
    std::vector<std::array<int, 6>> box(nb, {INT_MAX, INT_MAX, INT_MAX, INT_MIN, INT_MIN, INT_MIN});
    std::vector<std::size_t> count(nb, 0);
    for (std::size_t c = 0; c < cnodes.size(); ++c) {
      const int b = model_.body[cnodes[c]];
      ++count[b];
      for (int a = 0; a < 3; ++a)
        box[b][a] = std::min(box[b][a], cplane[c][a]), box[b][3 + a] = std::max(box[b][3 + a], cplane[c][a]);
    }
    num.dense.resize(nb);
    for (int b = 0; b < nb; ++b) {
      if (!count[b]) continue;
      auto& d = num.dense[b];
      std::size_t volume = 1;
      for (int a = 0; a < 3; ++a) d.lo[a] = box[b][a], d.n[a] = box[b][3 + a] - box[b][a] + 1, volume *= d.n[a];
      if (volume > 4 * count[b] + 4096) continue;  // a scattered part: the searches stay
      d.c.assign(volume, -1);
    }
    for (std::size_t c = 0; c < cnodes.size(); ++c) {
      auto& d = num.dense[model_.body[cnodes[c]]];
      if (d.c.empty()) continue;
      const auto& q = cplane[c];
      d.c[(static_cast<std::size_t>(q[0] - d.lo[0]) * d.n[1] + (q[1] - d.lo[1])) * d.n[2] + (q[2] - d.lo[2])] =
          static_cast<int>(c);
    }
  }
  auto own = [&](std::int64_t g) { return num.own(g); };
  for (std::int64_t g : acc.id)
    if (own(g) < 0) asked.push_back(g);
  for (std::size_t c = 0; c < cnodes.size(); ++c) {
    const int b = model_.body[cnodes[c]];
    const BoxGeometry& box = shape.body(b);
    for (int s = 0; s < kSlots; ++s) {
      const int q[3] = {cplane[c][0] + s % 3 - 1, cplane[c][1] + s / 3 % 3 - 1, cplane[c][2] + s / 9 - 1};
      bool inside = true;
      for (int a = 0; a < 3; ++a) inside = inside && q[a] >= 0 && q[a] < static_cast<int>(planes[l + 1][b][a].size());
      if (!inside || num.own_at(b, q) >= 0) continue;
      const std::int64_t g = box.id(planes[l + 1][b][0][q[0]], planes[l + 1][b][1][q[1]], planes[l + 1][b][2][q[2]]);
      if (own(g) < 0) asked.push_back(g);
    }
  }
  std::sort(asked.begin(), asked.end());
  asked.erase(std::unique(asked.begin(), asked.end()), asked.end());
  PetscCall(lattice_lookup(model_.comm, shape.molecules(), mine, packed, asked, num.answers));
  PetscFunctionReturn(0);
}

// 3. Rows of coarse nodes owned elsewhere go to their owners (the rank whose unknowns hold the node's first);
//    a node with every component held has no row at all.
PetscErrorCode LatticeGalerkin::send_rows_to_owners(int l, const Numbers& numbers, Rows& acc) const {
  PetscFunctionBeginUser;
  auto number = [&](std::int64_t g) { return numbers.number(g); };
  const int size = model_.size;
  std::vector<PetscInt> firsts(size), counts(size);
  PetscCallMPI(MPI_Allgather(&levels_.first[l + 1], 1, MPIU_INT, firsts.data(), 1, MPIU_INT, model_.comm));
  PetscCallMPI(MPI_Allgather(&levels_.count[l + 1], 1, MPIU_INT, counts.data(), 1, MPIU_INT, model_.comm));
  auto owner = [&](PetscInt num) {
    const PetscInt base = num / 8;
    for (int r = 0; r < size; ++r)
      if (base >= firsts[r] && base < firsts[r] + counts[r]) return r;
    return -1;
  };
  constexpr int kRecord = 2 + kSlots * kBlock;  // id, presence bits, blocks
  std::vector<std::vector<double>> out(size);
  for (std::size_t r = 0; r < acc.id.size(); ++r) {
    const PetscInt num = number(acc.id[r]);
    if (num % 8 == 0) continue;
    const int to = owner(num);
    PetscCheck(to >= 0, model_.comm, PETSC_ERR_PLIB, "lattice Galerkin product: a coarse node has no owner");
    if (to == model_.rank) continue;
    auto& o = out[to];
    o.push_back(static_cast<double>(acc.id[r]));
    o.push_back(static_cast<double>(acc.present[r]));
    o.insert(o.end(), acc.block(static_cast<int>(r), 0), acc.block(static_cast<int>(r), 0) + kSlots * kBlock);
  }
  const std::vector<double> recvbuf = exchange(model_.comm, std::move(out));
  for (std::size_t q = 0; q < recvbuf.size(); q += kRecord) {
    const int r = acc.find_or_add(static_cast<std::int64_t>(recvbuf[q]));
    acc.present[r] |= static_cast<std::uint32_t>(recvbuf[q + 1]);
    double* to = acc.writable(r);
    for (int e = 0; e < kSlots * kBlock; ++e) to[e] += recvbuf[q + 2 + e];
  }
  PetscFunctionReturn(0);
}

// The present slots of coarse node c's row (acc.row[c] set) with their column numbers, by column.
void LatticeGalerkin::neighbours(int l, const Numbers& num, const Rows& acc, std::size_t c, Neighbours& nb) const {
  const Body& shape = model_.shape;
  const auto& planes = levels_.planes;
  const auto& cnodes = levels_.owned_nodes[l + 1];
  const auto& cplane = num.cplane;
  auto& jnum = nb.jnum;
  auto& order = nb.order;
  int& norder = nb.norder;
  const int b = model_.body[cnodes[c]];
  const BoxGeometry& box = shape.body(b);
  norder = 0;
  const std::uint32_t bits = acc.present[acc.row[c]];
  if (num.slot_numbers.size() != kSlots * cnodes.size()) {
    num.slot_numbers.assign(kSlots * cnodes.size(), -1);
    num.slot_order.assign(kSlots * cnodes.size(), 0);
    num.slot_count.assign(cnodes.size(), 0);
  }
  PetscInt* cached = num.slot_numbers.data() + kSlots * c;
  std::uint8_t* cached_order = num.slot_order.data() + kSlots * c;
  if (num.numbered) {
    // Present now, so present (and looked up, and sorted) in mask_held's call; the slots it dropped since are
    // skipped, which keeps the others' order (their columns are distinct).
    for (int q = 0; q < num.slot_count[c]; ++q) {
      const int s = cached_order[q];
      if (!(bits >> s & 1)) continue;
      jnum[s] = cached[s];
      order[norder++] = s;
    }
    return;
  }
  for (int s = 0; s < kSlots; ++s) {
    if (!(bits >> s & 1)) continue;
    const int q[3] = {cplane[c][0] + s % 3 - 1, cplane[c][1] + s / 3 % 3 - 1, cplane[c][2] + s / 9 - 1};
    const std::ptrdiff_t at = num.own_at(b, q);
    jnum[s] = cached[s] =
        at >= 0 ? num.packed[at]
                : num.number(box.id(planes[l + 1][b][0][q[0]], planes[l + 1][b][1][q[1]], planes[l + 1][b][2][q[2]]));
    order[norder++] = s;
  }
  // Columns in increasing order, as AIJ keeps them.
  std::sort(order.begin(), order.begin() + norder, [&](int x, int y) { return jnum[x] < jnum[y]; });
  std::copy_n(order.begin(), norder, cached_order);
  num.slot_count[c] = static_cast<std::uint8_t>(norder);
}

// 4. This rank's coarse rows, held components (row's and column's) zeroed in place (row[c]: where node c's
//    row is; a copy in owned order would double the largest temporary), and their counts of nonzeros.
PetscErrorCode LatticeGalerkin::mask_held(int l, const Numbers& num, Rows& acc, std::vector<PetscInt>& dnnz,
                                          std::vector<PetscInt>& onnz) const {
  PetscFunctionBeginUser;
  const auto& cnodes = levels_.owned_nodes[l + 1];
  const auto& cbase = levels_.base[l + 1];
  const auto& mine = num.mine;
  const auto& packed = num.packed;
  acc.row.assign(cnodes.size(), -1);
  const PetscInt cfirst = levels_.first[l + 1], clast = cfirst + levels_.count[l + 1];
  Neighbours nb;
  const auto& jnum = nb.jnum;
  for (std::size_t c = 0; c < cnodes.size(); ++c) {
    const int mask = packed[c] % 8;
    if (!mask) continue;
    const auto it = acc.index.find(mine[c]);
    PetscCheck(it != acc.index.end(), PETSC_COMM_SELF, PETSC_ERR_PLIB, "lattice Galerkin product: an empty coarse row");
    const int r = acc.row[c] = it->second;
    neighbours(l, num, acc, c, nb);
    // A row with a held component here or in a neighbour is written, so it takes its own copy (rows that share
    // blocks need not share masks).
    bool masked = mask != 7;
    for (int s = 0; s < kSlots && !masked; ++s) masked = (acc.present[r] >> s & 1) && jnum[s] % 8 != 7;
    double* const own = masked ? acc.writable(r) : nullptr;
    for (int s = 0; s < kSlots; ++s) {
      if (!(acc.present[r] >> s & 1)) continue;
      const int jmask = static_cast<int>(jnum[s] % 8);
      if (masked) {
        double* blk = own + s * kBlock;
        for (int k = 0; k < 3; ++k)
          for (int m = 0; m < 3; ++m)
            if (!(mask >> k & 1) || !(jmask >> m & 1)) blk[3 * k + m] = 0.0;
      }
      if (!jmask) {
        acc.present[r] &= ~(1u << s);
        continue;
      }
      const PetscInt jb = jnum[s] / 8;
      const bool local = jb >= cfirst && jb < clast;
      for (int k = 0, row = static_cast<int>(cbase[c] - cfirst); k < 3; ++k)
        if (mask >> k & 1) (local ? dnnz : onnz)[row++] += __builtin_popcount(jmask);
    }
  }
  num.numbered = true;  // every later step's present slots were looked up above
  PetscFunctionReturn(0);
}

// The coarse matrix from the masked rows: its CSR arrays, diagonal and off-diagonal parts (off-diagonal columns
// global), written here and handed to PETSc without a copy: the pattern is the lattice's, the same on every
// call, so a refill writes the values in the same places.
PetscErrorCode LatticeGalerkin::fill_coarse_matrix(int l, const Numbers& num, const Rows& acc,
                                                   const std::vector<PetscInt>& dnnz,
                                                   const std::vector<PetscInt>& onnz) {
  PetscFunctionBeginUser;
  const auto& cnodes = levels_.owned_nodes[l + 1];
  const auto& cbase = levels_.base[l + 1];
  const auto& packed = num.packed;
  const PetscInt cfirst = levels_.first[l + 1], clast = cfirst + levels_.count[l + 1];
  Neighbours nb;
  const auto& jnum = nb.jnum;
  const auto& order = nb.order;
  const int& norder = nb.norder;
  Csr& m = csr_[l + 1];
  Mat& C = coarse_[l + 1];
  const PetscInt nrows = levels_.count[l + 1];
  if (!C) {
    m.di.assign(nrows + 1, 0), m.oi.assign(nrows + 1, 0);
    for (PetscInt r = 0; r < nrows; ++r) m.di[r + 1] = m.di[r] + dnnz[r], m.oi[r + 1] = m.oi[r] + onnz[r];
    m.dj.resize(m.di[nrows]), m.dv.resize(m.di[nrows]);
    m.oj.resize(m.oi[nrows]), m.ov.resize(m.oi[nrows]);
  }
  const bool fresh = !C;
  for (std::size_t c = 0; c < cnodes.size(); ++c) {
    const int mask = packed[c] % 8;
    if (!mask) continue;
    neighbours(l, num, acc, c, nb);
    for (int k = 0, row = static_cast<int>(cbase[c] - cfirst); k < 3; ++k) {
      if (!(mask >> k & 1)) continue;
      PetscInt d = m.di[row], o = m.oi[row];
      for (int q = 0; q < norder; ++q) {
        const int s = order[q];
        const int jmask = static_cast<int>(jnum[s] % 8);
        const double* blk = acc.block(acc.row[c], s);
        const PetscInt jb = jnum[s] / 8;
        const bool local = jb >= cfirst && jb < clast;
        for (int mm = 0, col = static_cast<int>(jb); mm < 3; ++mm) {
          if (!(jmask >> mm & 1)) continue;
          if (local) {
            if (fresh) m.dj[d] = col - cfirst;
            m.dv[d++] = blk[3 * k + mm];
          } else {
            if (fresh) m.oj[o] = col;
            m.ov[o++] = blk[3 * k + mm];
          }
          ++col;
        }
      }
      PetscCheck(d == m.di[row + 1] && o == m.oi[row + 1], PETSC_COMM_SELF, PETSC_ERR_PLIB,
                 "lattice Galerkin product: the coarse pattern changed");
      ++row;
    }
  }
  if (fresh) {
    if (model_.size == 1)
      PetscCall(MatCreateSeqAIJWithArrays(model_.comm, nrows, nrows, m.di.data(), m.dj.data(), m.dv.data(), &C));
    else
      PetscCall(MatCreateMPIAIJWithSplitArrays(model_.comm, nrows, nrows, PETSC_DETERMINE, PETSC_DETERMINE, m.di.data(),
                                               m.dj.data(), m.dv.data(), m.oi.data(), m.oj.data(), m.ov.data(), &C));
    PetscCall(MatSetOption(C, MAT_SYMMETRIC, PETSC_TRUE));
    PetscCall(MatSetOption(C, MAT_SYMMETRY_ETERNAL, PETSC_TRUE));
  } else {
    PetscCall(PetscObjectStateIncrease(reinterpret_cast<PetscObject>(C)));  // new values in the same arrays
  }
  PetscFunctionReturn(0);
}


PetscErrorCode LatticeGalerkin::update(Mat fine, PC pc) { return update(fine, nullptr, pc); }

PetscErrorCode LatticeGalerkin::update(const ForceModel& forces, const double* x, PC pc) {
  const Stream stream{&forces, x};
  return update(nullptr, &stream, pc);
}

PetscErrorCode LatticeGalerkin::applies(const ForceModel& forces, const double* x, bool* ok) const {
  PetscFunctionBeginUser;
  index_molecules();
  bool good = true;
  // One body: no body to compare (a molecule's body is a search among runs of the molecules).
  const bool one_body = model_.shape.bodies() == 1;
  auto put = [&](int i, int j, const double*) -> PetscErrorCode {
    for (int d = 0; d < 3; ++d) good = good && std::abs(ijk_[i][d] - ijk_[j][d]) <= 1;
    good = good && (one_body || model_.body[i] == model_.body[j]);
    return PetscErrorCode(0);
  };
  using Put = decltype(put);
  auto add = [](void* ctx, int i, int j, const double K[9]) -> PetscErrorCode {
    return (*static_cast<Put*>(ctx))(i, j, K);
  };
  if (forces.has_terms() && !forces.terms_within_cells()) {
    PetscCall(forces.tangent_blocks(x, add, &put));
  } else {
    // Springs only: the blocks join exactly the ends of the connections of owned molecules, so their ends say
    // it without computing a block (the stream cost 2.5 % of a 64,000-molecule solve's instructions); a term's
    // blocks within lattice cells are inside the stencil by construction (the cell term's dual numbers cost 6 %).
    // Both ends by runs (for_each_pair), not a division a read; put cannot fail.
    model_.end_a.for_each_pair(model_.end_b, [&](int, int i, int j) {
      if (i < model_.owned || j < model_.owned) (void)put(i, j, nullptr);
    });
  }
  free_storage(ijk_);
  int mine = good ? 1 : 0, all = 0;
  PetscCallMPI(MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, model_.comm));
  *ok = all == 1;
  PetscFunctionReturn(0);
}

PetscErrorCode LatticeGalerkin::update(Mat fine, const Stream* stream, PC pc) {
  PetscFunctionBeginUser;
  PetscCall(PetscLogEventBegin(galerkin_event(), pc, fine, 0, 0));
  index_molecules();
  const int L = static_cast<int>(levels_.planes.size());
  // Level 1 as a shell over its rows only without a fine matrix (the assembled path keeps its CSR, unchanged) and
  // where it is not the coarsest level (PCMG factors that one).
  if (stencil_level_one_ && stream && L >= 3 && !level_one_) level_one_ = std::make_unique<StencilOperator>();
  if (level_one_) level_one_->rows = Rows();  // the last rows go before the new ones are summed
  Rows stencil, next;
  const Rows* prev = nullptr;
  for (int l = 0; l + 1 < L; ++l) {
    PetscCall(coarsen(l, fine, stream, prev, next));
    if (l == 0 && level_one_) {
      level_one_->rows = std::move(next);
      prev = &level_one_->rows;
    } else {
      std::swap(stencil, next);
      prev = &stencil;
    }
    KSP level;
    PetscCall(PCMGGetSmoother(pc, L - 2 - l, &level));  // PCMG counts levels from the coarsest
    PetscCall(KSPSetOperators(level, coarse_[l + 1], coarse_[l + 1]));
  }
  if (level_one_) halve_level_one();  // level 2 has been summed from the whole rows
  if (stream) {
    const double mine[3] = {jacobi_bound_, symbol_bound_, -symbol_bound_};
    double all[3];
    PetscCallMPI(MPI_Allreduce(mine, all, 3, MPI_DOUBLE, MPI_MAX, model_.comm));
    jacobi_bound_ = all[0];
    symbol_bound_ = all[2] > 0.0 ? 0.0 : all[1];  // a rank with too many rows: none
    (void)PetscInfo(nullptr, "lattice Galerkin: the Jacobi-scaled symbol's largest eigenvalue %g\n", symbol_bound_);
  }
  free_storage(ijk_);
  PetscCall(PetscLogEventEnd(galerkin_event(), pc, fine, 0, 0));
  PetscFunctionReturn(0);
}

}  // namespace tissue

namespace tissue {

// Level 1's shell (keep_level_one_as_stencil), from coarsen's masked rows: the column of every present block and
// the scatter of the neighbours' unknowns owned elsewhere, made again at every update (a rebuild is rare, and its
// rows are new).
PetscErrorCode LatticeGalerkin::stencil_operator(const Numbers& num, const Rows& acc) {
  PetscFunctionBeginUser;
  StencilOperator& op = *level_one_;
  op.release();
  const auto& cnodes = levels_.owned_nodes[1];
  const auto& cbase = levels_.base[1];
  const PetscInt cfirst = levels_.first[1], n = levels_.count[1], clast = cfirst + n;
  op.n = n;
  op.first.assign(cnodes.size(), 0);
  op.col.assign(kSlots * cnodes.size(), -1);
  Neighbours nb;
  // Pass 1: the neighbours owned elsewhere (8 * first unknown + mask), sorted.
  std::vector<PetscInt> away;
  for (std::size_t c = 0; c < cnodes.size(); ++c) {
    const int mask = static_cast<int>(num.packed[c] % 8);
    op.first[c] = 8 * (cbase[c] - cfirst) + mask;
    if (!mask) continue;
    neighbours(0, num, acc, c, nb);
    for (int q = 0; q < nb.norder; ++q) {
      const PetscInt jb = nb.jnum[nb.order[q]] / 8;
      if (jb < cfirst || jb >= clast) away.push_back(nb.jnum[nb.order[q]]);
    }
  }
  std::sort(away.begin(), away.end());
  away.erase(std::unique(away.begin(), away.end()), away.end());
  std::vector<PetscInt> offset(away.size() + 1, 0), gidx;  // each one's first value among the ghosts
  for (std::size_t a = 0; a < away.size(); ++a) {
    const int m = static_cast<int>(away[a] % 8);
    for (int k = 0; k < __builtin_popcount(m); ++k) gidx.push_back(away[a] / 8 + k);
    offset[a + 1] = offset[a] + __builtin_popcount(m);
  }
  // Pass 2: every present block's column.
  for (std::size_t c = 0; c < cnodes.size(); ++c) {
    if (!(op.first[c] % 8)) continue;
    neighbours(0, num, acc, c, nb);
    for (int q = 0; q < nb.norder; ++q) {
      const int s = nb.order[q];
      const PetscInt jnum = nb.jnum[s], jb = jnum / 8;
      PetscInt at = jb - cfirst;
      if (jb < cfirst || jb >= clast)
        at = n + offset[std::lower_bound(away.begin(), away.end(), jnum) - away.begin()];
      op.col[kSlots * c + s] = 8 * at + jnum % 8;
    }
  }
  Vec layout;
  IS is;
  PetscCall(VecCreateMPIWithArray(model_.comm, 1, n, PETSC_DETERMINE, nullptr, &layout));
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, static_cast<PetscInt>(gidx.size()), gidx.data(), PETSC_COPY_VALUES, &is));
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, static_cast<PetscInt>(gidx.size()), &op.ghosts));
  PetscCall(VecDuplicate(op.ghosts, &op.shares));
  PetscCall(VecScatterCreate(layout, is, op.ghosts, nullptr, &op.scatter));
  PetscCall(ISDestroy(&is));
  PetscCall(VecDestroy(&layout));
  Mat& C = coarse_[1];
  if (!C) {
    PetscCall(MatCreateShell(model_.comm, n, n, PETSC_DETERMINE, PETSC_DETERMINE, &op, &C));
    PetscCall(MatShellSetOperation(C, MATOP_MULT, reinterpret_cast<void (*)(void)>(stencil_mult)));
    PetscCall(MatShellSetOperation(C, MATOP_MULT_TRANSPOSE, reinterpret_cast<void (*)(void)>(stencil_mult)));
    PetscCall(MatShellSetOperation(C, MATOP_GET_DIAGONAL, reinterpret_cast<void (*)(void)>(stencil_diagonal)));
    PetscCall(MatSetOption(C, MAT_SYMMETRIC, PETSC_TRUE));
    PetscCall(MatSetOption(C, MAT_SYMMETRY_ETERNAL, PETSC_TRUE));
  } else {
    PetscCall(PetscObjectStateIncrease(reinterpret_cast<PetscObject>(C)));  // new rows behind the same shell
  }
  PetscFunctionReturn(0);
}

// Level 1's rows halved: the upper slots' blocks (the diagonal's first) of every row kept (243 -> 126 B a fine
// molecule). Each coupling between two nodes is then kept once, by the owner of the node it is an upper slot of;
// stencil_mult applies it and its transpose.
void LatticeGalerkin::halve_level_one() {
  StencilOperator& op = *level_one_;
  const std::size_t nodes = op.first.size();
  std::vector<PetscInt> col(kHalf * nodes, -1);
  for (std::size_t c = 0; c < nodes; ++c)
    if (op.first[c] % 8) std::copy_n(op.col.begin() + kSlots * c + kHalf0, kHalf, col.begin() + kHalf * c);
  op.col = std::move(col);
  // In place, row by row in order (row r's upper half moves to at most r * kHalf blocks, never past a row not yet
  // moved), so that no second copy of the rows exists even for a moment (with one, this was the solve's peak), and
  // the pages past the kept rows go back to the system (the vector keeps its size and never reads them again).
  // Rows equal to the bit are kept once (a box lattice's interior rows at its reference state are nearly all one
  // row): the product then reads the few distinct rows from the cache, not 126 B a fine molecule from memory.
  double* a = op.rows.a.data();
  const std::size_t rows = op.rows.id.size(), copies = op.rows.refs.size();
  constexpr std::size_t kRow = kHalf * kBlock;
  std::vector<int> kept_as(copies, -1);  // by copy of the blocks (rows.at), not by row: shared rows hash once
  for (std::size_t c = 0; c < nodes; ++c)
    if (op.first[c] % 8) kept_as[op.rows.at[op.rows.row[c]]] = 0;  // the copies some node of this rank reads
  std::unordered_map<std::uint64_t, int> distinct;  // a copy's hash -> the first kept copy with it
  std::size_t kept = 0;
  for (std::size_t r = 0; r < copies; ++r) {
    if (kept_as[r] < 0) continue;
    const double* from = a + (r * kSlots + kHalf0) * kBlock;
    // Four independent hashes of interleaved values (one chain of multiplies was the pass's time), then combined.
    std::uint64_t lane[4] = {1469598103934665603ull, 1, 2, 3};
    for (std::size_t e = 0; e < kRow; ++e) {
      std::uint64_t bits;
      std::memcpy(&bits, from + e, sizeof bits);
      lane[e % 4] = (lane[e % 4] ^ bits) * 1099511628211ull;
    }
    const std::uint64_t h = ((lane[0] * 31 + lane[1]) * 31 + lane[2]) * 31 + lane[3];
    const auto [it, added] = distinct.try_emplace(h, static_cast<int>(kept));
    if (!added && std::memcmp(a + it->second * kRow, from, sizeof(double) * kRow) == 0) {
      kept_as[r] = it->second;
      continue;
    }
    std::memmove(a + kept * kRow, from, sizeof(double) * kRow);
    kept_as[r] = static_cast<int>(kept++);
  }
  for (std::size_t c = 0; c < nodes; ++c)
    if (op.first[c] % 8) op.rows.row[c] = kept_as[op.rows.at[op.rows.row[c]]];
  (void)PetscInfo(nullptr, "lattice Galerkin: level 1 keeps %zu distinct rows of %zu (%zu copies)\n", kept, rows,
                  copies);
  const std::uintptr_t page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
  const auto from = (reinterpret_cast<std::uintptr_t>(a + kept * kRow) + page - 1) / page * page;
  // Up to the last copy populate faulted in ahead (writable's batch: 1/16 of the reserve, 8 MB a rank at 10^6),
  // not only the copies written: on a rank with few copies that batch was most of the rows' resident pages.
  const std::size_t faulted = std::max(op.rows.a.size(), op.rows.populated * Rows::kRow);
  const auto to = reinterpret_cast<std::uintptr_t>(a + faulted) / page * page;
  if (to > from + (1u << 20)) (void)madvise(reinterpret_cast<void*>(from), to - from, MADV_DONTNEED);
  op.rows.populated = 0;  // (nothing is written to them again; were it, writable would fault them in anew)
  free_storage(op.rows.index);
  free_storage(op.rows.present);
  free_storage(op.rows.at);
  free_storage(op.rows.refs);
  // A spring's block is symmetric to the bit and so is every weighted sum of them; a term's blocks need not be.
  op.symmetric = true;
  for (std::size_t c = 0; c < nodes && op.symmetric; ++c) {
    const int mask = static_cast<int>(op.first[c] % 8);
    if (mask != 7) continue;
    const double* blk = a + kHalf * kBlock * static_cast<std::size_t>(op.rows.row[c]);
    for (int q = 0; q < kHalf; ++q, blk += kBlock) {
      const PetscInt cq = op.col[kHalf * c + q];
      if (cq < 0 || (cq & 7) != 7) continue;
      for (int r = 0; r < 3; ++r)
        for (int k = r + 1; k < 3; ++k)
          op.symmetric = op.symmetric && std::memcmp(blk + 3 * r + k, blk + 3 * k + r, sizeof(double)) == 0;
    }
  }
  // The tangent is symmetric, but a cell's block A_ab need not be (only A_ba = A_ab^T): the product then reads the
  // columns from a transposed copy of the kept rows, 3 padding values for the last block's unused lane, when they
  // are at most a quarter of the rows (a box lattice at rest: its few distinct rows); otherwise (a deformed
  // state, nearly every row distinct) no copy, and the product gathers the columns from the rows.
  free_storage(op.columns);
  if (!op.symmetric && 4 * kept <= rows) {
    op.columns.assign(kept * kRow + 3, 0.0);
    for (std::size_t b = 0; b < kept * kHalf; ++b)
      for (int r = 0; r < 3; ++r)
        for (int k = 0; k < 3; ++k) op.columns[b * kBlock + 3 * k + r] = a[b * kBlock + 3 * r + k];
  }
  pull_runs();
}

// Level 1's pulled runs (PullRuns; stencil_product): a node is pulled when it is wholly free, its 14 upper slots'
// nodes are wholly free, owned here and at the same node offsets as everywhere else (`delta`, from the first such
// node), and its 13 lower neighbours are such nodes with the same row of blocks. A box lattice's interior at its
// reference state, where the rows are a few shared ones, is nearly all pulled; a deformed state (every row
// distinct) or another numbering pulls nothing, and the push form runs as before.
void LatticeGalerkin::pull_runs() {
  StencilOperator& op = *level_one_;
  op.runs.clear();
  free_storage(op.pushes);
  free_storage(op.soa);
  op.pulled_nodes = 0;
  PetscBool on = PETSC_TRUE;
  (void)PetscOptionsGetBool(nullptr, nullptr, "-static_level_one_pull", &on, nullptr);
  const std::size_t nodes = op.first.size();
  const PetscInt n = op.n;
  if (!on || nodes == 0 || n >= (PetscInt{1} << 27)) return;  // (pushes keep 16 x a position in 32 bits)
  std::vector<int> node_at(static_cast<std::size_t>(n), -1);  // the node whose first unknown is there
  for (std::size_t c = 0; c < nodes; ++c)
    if (op.first[c] % 8) node_at[op.first[c] / 8] = static_cast<int>(c);
  auto upper = [&](std::size_t c, int s) {  // slot s's node if wholly free and owned here, else -1
    const PetscInt cq = op.col[kHalf * c + s];
    return cq < 0 || (cq & 7) != 7 || (cq >> 3) >= n ? -1 : node_at[cq >> 3];
  };
  auto full = [&](std::size_t c) {
    if (op.first[c] % 8 != 7) return false;
    for (int s = 0; s < kHalf; ++s)
      if (upper(c, s) < 0) return false;
    return true;
  };
  // The offsets most wholly free nodes have (a rank's nodes need not all be numbered alike: the first one's can be
  // a cut's).
  std::map<std::array<int, kHalf>, std::size_t> seen;
  for (std::size_t c = 0; c < nodes; ++c) {
    if (!full(c)) continue;
    std::array<int, kHalf> d;
    for (int s = 0; s < kHalf; ++s) d[s] = upper(c, s) - static_cast<int>(c);
    ++seen[d];
  }
  if (seen.empty()) return;
  op.delta = std::max_element(seen.begin(), seen.end(), [](const auto& p, const auto& q) {
               return p.second < q.second;
             })->first;
  for (int s = 1; s < kHalf; ++s) op.lower[s - 1] = s;
  std::sort(op.lower.begin(), op.lower.end(), [&](int p, int q) { return op.delta[p] > op.delta[q]; });
  if (op.delta[0] != 0 || op.delta[op.lower.back()] <= 0) return;
  for (int q = 1; q < kHalf - 1; ++q)
    if (op.delta[op.lower[q]] == op.delta[op.lower[q - 1]]) return;
  // A node is pulled when it is wholly free, each upper slot has no block or a wholly free local node at its usual
  // offset, and every block that reaches it from a node before it comes from a lower slot's usual offset: the
  // lower neighbour c - delta[s] with unknowns and a block of slot s at it (any mask: its held components read +0).
  const int* row = op.rows.row.data();
  const PetscInt* col = op.col.data();
  auto reaches = [&](long j, int s, std::size_t c) {  // node j's slot s is a block that adds to node c
    if (j < 0 || op.first[j] % 8 == 0) return false;
    const PetscInt cq = col[kHalf * j + s];
    return cq >= 0 && (cq & 7) != 0 && (cq >> 3) == op.first[c] / 8;
  };
  std::vector<std::uint8_t> incoming(nodes, 0);  // the blocks reaching each node from nodes before it
  for (std::size_t j = 0; j < nodes; ++j) {
    if (op.first[j] % 8 == 0) continue;
    for (int s = 1; s < kHalf; ++s) {
      const PetscInt cq = col[kHalf * j + s];
      if (cq < 0 || (cq & 7) == 0 || (cq >> 3) >= n) continue;
      const int t = node_at[cq >> 3];
      if (t > static_cast<int>(j) && incoming[t] < 255) ++incoming[t];
    }
  }
  std::vector<std::uint8_t> pure(nodes, 0);
  std::vector<PullRuns::Run> key(nodes);  // each pulled node's rows and absent slots (c0, c1, p0, p1 unused)
  for (std::size_t c = 0; c < nodes; ++c) {
    if (op.first[c] % 8 != 7) continue;
    PullRuns::Run& k = key[c];
    k.row = row[c], k.absent = 0;
    bool ok = true;
    for (int s = 0; s < kHalf && ok; ++s) {
      if (col[kHalf * c + s] < 0) k.absent |= 1u << s;
      else ok = upper(c, s) == static_cast<int>(c) + op.delta[s];
    }
    int reached = 0;
    for (int s = 1; s < kHalf && ok; ++s) {
      const long j = static_cast<long>(c) - op.delta[s];
      const bool from = reaches(j, s, c);
      k.lower_row[s - 1] = from ? row[j] : -1;
      reached += from;
    }
    pure[c] = ok && reached == incoming[c];
  }
  // Runs: consecutive such nodes with the same rows and absent slots; those shorter than 8 nodes (one vector) stay
  // in the push form, whose 4-lane blocks beat the scalar pull (a face's ends, every row of a deformed state).
  auto same = [&](std::size_t p, std::size_t q) {
    return key[p].row == key[q].row && key[p].absent == key[q].absent &&
           std::equal(key[p].lower_row, key[p].lower_row + kHalf - 1, key[q].lower_row);
  };
  std::vector<std::pair<std::size_t, std::size_t>> spans;
  for (std::size_t c = 0; c < nodes;) {
    std::size_t e = c + 1;
    if (pure[c])
      while (e < nodes && pure[e] && same(e, c)) ++e;
    if (pure[c] && e - c >= kMinPullRun) spans.emplace_back(c, e), op.pulled_nodes += e - c;
    else std::fill(pure.begin() + c, pure.begin() + e, 0);
    c = e;
  }
  (void)PetscInfo(nullptr, "lattice Galerkin: level 1 pulls %zu of %zu nodes in %zu runs\n", op.pulled_nodes, nodes,
                  spans.size());
  if (!op.pulled_nodes) return;
  for (auto [c, e] : spans) {
    const int p0 = static_cast<int>(op.pushes.size());
    for (std::size_t i = c; i < e; ++i)
      for (int s = 1; s < kHalf; ++s)
        if (!(key[c].absent >> s & 1u) && !pure[i + op.delta[s]]) {
          op.pushes.push_back(static_cast<std::uint32_t>(16 * (op.first[i] / 8) + s));
          op.pushes.push_back(static_cast<std::uint32_t>(op.col[kHalf * i + s] >> 3));
        }
    PullRuns::Run run = key[c];
    run.c0 = static_cast<int>(c), run.c1 = static_cast<int>(e);
    run.p0 = p0 / 2, run.p1 = static_cast<int>(op.pushes.size() / 2);
    op.runs.push_back(run);
  }
  op.soa.assign(3 * nodes, 0.0);
}

std::size_t LatticeGalerkin::level_one_pulled() const { return level_one_ ? level_one_->pulled_nodes : 0; }

// y = A u over the halved rows: each kept block A_ij adds A_ij u_j to row i and A_ij^T u_i to row j, whose
// shares for nodes owned elsewhere go back to their owners through the reverse scatter.
PetscErrorCode LatticeGalerkin::stencil_mult(Mat A, Vec in, Vec out) {
  PetscFunctionBeginUser;
  StencilOperator* op;
  PetscCall(MatShellGetContext(A, &op));
  PetscCall(VecScatterBegin(op->scatter, in, op->ghosts, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(op->scatter, in, op->ghosts, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecZeroEntries(out));
  PetscCall(VecZeroEntries(op->shares));
  const PetscScalar *u, *g;
  PetscScalar *y, *h;
  PetscCall(VecGetArrayRead(in, &u));
  PetscCall(VecGetArrayRead(op->ghosts, &g));
  PetscCall(VecGetArray(out, &y));
  PetscCall(VecGetArray(op->shares, &h));
  const PetscInt n = op->n;
  const std::size_t nodes = op->first.size();
  PullRuns pr;
  if (!op->runs.empty()) {
    double* soa = op->soa.data();
    for (std::size_t c = 0; c < nodes; ++c) {  // the nodes' values by component (the pulled nodes read), held +0
      const int mask = static_cast<int>(op->first[c] % 8);
      const double* from = u + op->first[c] / 8;
      if (mask == 7) {
        soa[c] = from[0], soa[nodes + c] = from[1], soa[2 * nodes + c] = from[2];
      } else if (mask) {
        for (int m = 0, q = 0; m < 3; ++m) soa[m * nodes + c] = mask >> m & 1 ? from[q++] : 0.0;
      }
    }
    pr = PullRuns{op->runs.data(), op->runs.size(), op->delta.data(), op->lower.data(), op->pushes.data(), {soa, soa + nodes, soa + 2 * nodes}};
  }
  if (op->symmetric)
    symmetric_stencil_product(nodes, op->first.data(), op->rows.row.data(), op->rows.a.data(), op->col.data(), n,
                              u, g, y, h, pr);
  else
    general_stencil_product(nodes, op->first.data(), op->rows.row.data(), op->rows.a.data(),
                            op->columns.empty() ? nullptr : op->columns.data(), op->col.data(), n, u, g, y, h, pr);
  PetscCall(VecRestoreArray(op->shares, &h));
  PetscCall(VecRestoreArray(out, &y));
  PetscCall(VecRestoreArrayRead(op->ghosts, &g));
  PetscCall(VecRestoreArrayRead(in, &u));
  PetscCall(VecScatterBegin(op->scatter, op->shares, out, ADD_VALUES, SCATTER_REVERSE));
  PetscCall(VecScatterEnd(op->scatter, op->shares, out, ADD_VALUES, SCATTER_REVERSE));
  PetscFunctionReturn(0);
}

PetscErrorCode LatticeGalerkin::stencil_diagonal(Mat A, Vec d) {
  PetscFunctionBeginUser;
  StencilOperator* op;
  PetscCall(MatShellGetContext(A, &op));
  PetscScalar* y;
  PetscCall(VecGetArray(d, &y));
  for (std::size_t c = 0; c < op->first.size(); ++c) {
    const int mask = static_cast<int>(op->first[c] % 8);
    if (!mask) continue;
    const double* blk = op->rows.a.data() + kHalf * kBlock * op->rows.row[c];  // the diagonal block leads
    PetscScalar* to = y + op->first[c] / 8;
    for (int k = 0, q = 0; k < 3; ++k)
      if (mask >> k & 1) to[q++] = blk[4 * k];
  }
  PetscCall(VecRestoreArray(d, &y));
  PetscFunctionReturn(0);
}

}  // namespace tissue

