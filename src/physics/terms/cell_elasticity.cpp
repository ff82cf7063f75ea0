// The cell term: one energy per lattice cell (its 8 corner molecules) of the cell-centre deformation gradient,
// which carries what central springs cannot (src/model/cell_law.hpp, docs/poisson.md): a Poisson ratio other
// than 1/4, and the shear of cells too far from cubic. Built only for bodies calibrated by homogenized that need
// it (body_has_cells); everything else pays nothing.
//
// F = sum_a x_a (x) g_a with g_a = (s_x / 4h_x, s_y / 4h_y, s_z / 4h_z), s in {-1, 1}^3 the corner's signs (the
// trilinear cell's gradient at its centre; F = I at rest). Per unit reference volume V0 = h_x h_y h_z:
//   W = mu_c/2 (J^(-2/3) tr C - 3) + kappa_c/4 (J^2 - 1 - 2 ln J) + sum_w alpha_w sum_(n = (e_a +- e_b)/sqrt 2) (|F n|^2 - 1)^2 / 4
// (isochoric neo-Hookean, a volumetric part that is convex and infinite as J -> 0, and the virtual 45-degree
// diagonals of each face plane w = (a, b)): objective (a function of C = F^T F), >= 0, zero at rest. Its
// small-strain tensor adds lambda_c + 2 mu_c to C11, lambda_c to C12, mu_c to C44 (lambda_c = kappa_c - 2 mu_c/3)
// and alpha_w to C_aaaa, C_bbbb, C_aabb and C_abab. Forces f_a = -V0 P g_a with P = dW/dF; the tangent is P's
// exact derivative, taken by forward-mode dual numbers through the same code (no second hand-written formula
// to drift from the force).
//
// Ranks: each rank evaluates every cell that has an owned corner (the lattice's ghost layer holds all 8 corners,
// partition/lattice_model.cpp) in increasing cell id and adds to its owned corners only, so each molecule sums its
// cells in the same order on any partition: results are bit for bit those of one rank. A cell's energy is
// counted by the rank owning its lowest corner.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <stdexcept>
#include <unordered_map>

#include <petscsys.h>

#include "src/model/cell_law.hpp"
#include "src/physics/continuum_law.hpp"
#include "src/physics/term.hpp"
#include "src/vector_clones.hpp"

namespace tissue {

namespace {

using namespace continuum;

// The cell's second Piola-Kirchhoff stress S = F^-1 P (every part: isotropic, non-cubic remainder, fibres;
// objective: the quantity the Prony history of quasi-linear viscoelasticity follows, so the whole tensor relaxes
// by one G(t) and nu stays constant in time); false when J <= 0.
template <class T>
bool cell_pk2(const T F[9], const Moduli& m, const Fibre* fibres, int nfibres, T S[9]) {
  T P[9];
  if (!stress(F, m, fibres, nfibres, P)) return false;
  const T cof[9] = {F[4] * F[8] - F[5] * F[7], F[5] * F[6] - F[3] * F[8], F[3] * F[7] - F[4] * F[6],
                    F[2] * F[7] - F[1] * F[8], F[0] * F[8] - F[2] * F[6], F[1] * F[6] - F[0] * F[7],
                    F[1] * F[5] - F[2] * F[4], F[2] * F[3] - F[0] * F[5], F[0] * F[4] - F[1] * F[3]};
  const T J = F[0] * cof[0] + F[1] * cof[1] + F[2] * cof[2];
  // F^-1_im = cof_mi / J
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) S[3 * i + j] = (cof[i] * P[j] + cof[3 + i] * P[3 + j] + cof[6 + i] * P[6 + j]) / J;
  return true;
}

// The kernels below (TISSUE_CLONES) are compiled for AVX-512, AVX2 and the baseline, the loader picking the best the
// CPU has; every clone rounds as the baseline does (src/vector_clones.hpp).
constexpr int kCellBlock = 64;

// One cell's one-point gradient row along component d from its eight corners' values u[c] (corner c's offsets
// along x, y, z are bits 0, 1, 2 of c): the three entries F[3d + 0..2] = the axis differences x g. Inlined into
// every clone of the kernels below, so each keeps its own vector width.
__attribute__((always_inline)) inline void corner_gradient(double u0, double u1, double u2, double u3, double u4,
                                                           double u5, double u6, double u7, double gx, double gy,
                                                           double gz, double& a, double& b, double& c) {
  a = ((u1 - u0) + (u3 - u2) + (u5 - u4) + (u7 - u6)) * gx;
  b = ((u2 - u0) + (u3 - u1) + (u6 - u4) + (u7 - u5)) * gy;
  c = ((u4 - u0) + (u5 - u1) + (u6 - u2) + (u7 - u3)) * gz;
}

// The gradients of n cells in a row from their four corner rows' values (row r: corners 2r and 2r + 1 of cell i
// at molecules i and i + 1, interleaved as x): F[3d + 0..2][i] for each component d.
__attribute__((always_inline)) inline void row_gradient(const double* r0, const double* r1, const double* r2,
                                                        const double* r3, int n, double gx, double gy, double gz,
                                                        double (&F)[9][kCellBlock]) {
  for (int d = 0; d < 3; ++d)
    for (int i = 0; i < n; ++i) {
      const int a = 3 * i + d, b = 3 * (i + 1) + d;
      corner_gradient(r0[a], r0[b], r1[a], r1[b], r2[a], r2[b], r3[a], r3[b], gx, gy, gz, F[3 * d][i], F[3 * d + 1][i],
                      F[3 * d + 2][i]);
    }
}

// Cell i's corner sums of q (per component r, q[3r + 0..2]: the x, y, z columns of V0 P g, with the caller's
// sign), added to its owned corners c (corner c's offsets along x, y, z are bits 0, 1, 2 of c), in order.
__attribute__((always_inline)) inline void add_cell_corners(const double (&q)[9][kCellBlock], int i,
                                                            const int* __restrict base, const int* __restrict offset,
                                                            int owned, double* __restrict f) {
  for (int r = 0; r < 3; ++r) {
    const double q0 = q[3 * r][i], q1 = q[3 * r + 1][i], q2 = q[3 * r + 2][i];
    const double lo = q0 + q1, hi = q1 - q0;
    const double add[8] = {lo + q2, hi + q2, -hi + q2, -lo + q2, lo - q2, hi - q2, -hi - q2, -lo - q2};
    for (int c = 0; c < 8; ++c)
      if (base[i] + offset[c] < owned) f[3 * (base[i] + offset[c]) + r] += add[c];
  }
}

// The same for n cells in a row (the kernels' row layout: row r holds the cells' corners 2r (cell i's at molecule
// i) and 2r + 1 (at molecule i + 1)): their forces interleaved as f, one row at a time, corner 2r + 1 first, so each
// molecule sums its cells in increasing order (the same sums as add_cell_corners; a - b is a + (-b)).
__attribute__((always_inline)) inline void add_row_corners(const double (&q)[9][kCellBlock], int n,
                                                           const int* __restrict base, const int* __restrict offset,
                                                           int owned, double* __restrict f) {
  alignas(64) double at[3 * kCellBlock], next[3 * kCellBlock];
  for (int r = 0; r < 4; ++r) {
    const bool odd = r & 1;
    const double z = (r >> 1) ? -1.0 : 1.0;
    for (int i = 0; i < n; ++i)
      for (int d = 0; d < 3; ++d) {
        const double q0 = q[3 * d][i], q1 = q[3 * d + 1][i], q2 = z * q[3 * d + 2][i];
        const double lo = q0 + q1, hi = q1 - q0;
        at[3 * i + d] = (odd ? -hi : lo) + q2;
        next[3 * i + d] = (odd ? -lo : hi) + q2;
      }
    const int s = base[0] + offset[2 * r];
    const int touched = std::min(n + 1, owned - s);  // the row's owned molecules: s .. s + touched - 1
    double* __restrict fr = f + 3 * s;
    if (touched == n + 1) {
      // The whole row owned: one pass, each molecule's (f + its cell before) + its cell after, the same sums.
      for (int j = 0; j < 3; ++j) fr[j] += at[j];
      for (int j = 3; j < 3 * n; ++j) fr[j] = (fr[j] + next[j - 3]) + at[j];
      for (int j = 3 * n; j < 3 * n + 3; ++j) fr[j] += next[j - 3];
      continue;
    }
    for (int j = 3; j < 3 * touched; ++j) fr[j] += next[j - 3];
    for (int j = 0; j < 3 * std::min(n, touched); ++j) fr[j] += at[j];
  }
}

// The F = I form's corner signs for add_row_corners' rows (bit 0 of r: the y+ rows, bit 1: the z+ rows): Q = V0 dP g
// with dP = dvol I has one nonzero column per component, so a cell's corner at molecule i ("at", e = 0) adds
// (q_x, s_y q_y, s_z q_z) and its corner at molecule i + 1 ("next", e = 1) adds (-q_x, s_y q_y, s_z q_z):
// add_row_corners' sums with the zero columns' terms dropped (x + (-0) is x; their +0 could only change the sign of
// an exact zero). Repeated over the x, y, z entries of a row's molecules.
struct RestCornerSigns {
  double s[4][2][3 * (kCellBlock + 1)];  // a row block's n + 1 molecules
};
constexpr RestCornerSigns rest_corner_signs() {
  RestCornerSigns t{};
  for (int r = 0; r < 4; ++r)
    for (int e = 0; e < 2; ++e)
      for (int k = 0; k < 3 * (kCellBlock + 1); ++k) {
        const int d = k % 3;
        t.s[r][e][k] = d == 0 ? (e ? -1.0 : 1.0) : d == 1 ? ((r & 1) ? -1.0 : 1.0) : ((r >> 1) ? -1.0 : 1.0);
      }
  return t;
}
inline constexpr RestCornerSigns kRestCornerSigns = rest_corner_signs();

// add_row_corners for the F = I form, Q interleaved as the molecules (Q[3i + d] = cell i's q_d): each owned
// molecule of a row takes its cell before (next) and then its cell after (at), in one pass.
__attribute__((always_inline)) inline void add_row_corners_at_rest(const double* __restrict Q, int n,
                                                                   const int* __restrict base,
                                                                   const int* __restrict offset, int owned,
                                                                   double* __restrict f) {
  for (int r = 0; r < 4; ++r) {
    const double* __restrict at = kRestCornerSigns.s[r][0];
    const double* __restrict next = kRestCornerSigns.s[r][1];
    const int s = base[0] + offset[2 * r];
    const int touched = std::min(n + 1, owned - s);  // the row's owned molecules: s .. s + touched - 1
    const int m = 3 * std::min(n, touched), t = 3 * touched;
    double* __restrict fr = f + 3 * s;
    if (touched == n + 1) {
      // The whole row owned (n > 0: a row block): its first molecule's cell after and its last's cell before
      // written out, without the general bounds' loops around the vectorized one.
      fr[0] += at[0] * Q[0], fr[1] += at[1] * Q[1], fr[2] += at[2] * Q[2];
#pragma GCC unroll 8
      for (int k = 3; k < m; ++k) fr[k] = (fr[k] + next[k] * Q[k - 3]) + at[k] * Q[k];
      fr[m] += next[m] * Q[m - 3], fr[m + 1] += next[m + 1] * Q[m - 2], fr[m + 2] += next[m + 2] * Q[m - 1];
      continue;
    }
    for (int k = 0; k < std::min(3, m); ++k) fr[k] += at[k] * Q[k];
    for (int k = 3; k < m; ++k) fr[k] = (fr[k] + next[k] * Q[k - 3]) + at[k] * Q[k];
    for (int k = std::max(3, m); k < t; ++k) fr[k] += next[k] * Q[k - 3];
  }
}

// A tangent product's last step, for n cells' dP (overwritten): Q = V0 dP g per column (in dP's place); corner c's
// row s_x q0 + s_y q1 + s_z q2, cell_block_forces's sums with the opposite sign, added to the owned corners of out.
__attribute__((always_inline)) inline void add_cell_products(double (&dP)[9][kCellBlock], int n, double volume,
                                                             double gx, double gy, double gz, bool rows,
                                                             const int* __restrict base,
                                                             const int* __restrict offset, int owned,
                                                             double* __restrict out) {
  for (int r = 0; r < 3; ++r)
    for (int i = 0; i < n; ++i) {
      dP[3 * r][i] = -volume * dP[3 * r][i] * gx;
      dP[3 * r + 1][i] = -volume * dP[3 * r + 1][i] * gy;
      dP[3 * r + 2][i] = -volume * dP[3 * r + 2][i] * gz;
    }
  const double(&q)[9][kCellBlock] = dP;
  if (rows) {
    add_row_corners(q, n, base, offset, owned, out);
    return;
  }
  for (int i = 0; i < n; ++i) add_cell_corners(q, i, base, offset, owned, out);
}

// The forces of n <= kCellBlock cells of one moduli (no fibres, no history) and one corner pattern (cell i's
// corner c is base[i] + offset[c]), added to their owned corners: CellElasticity::cell_forces's arithmetic,
// operation for operation (stress() for plain moduli, with the same order of sums), with the cells as the
// vector lanes of structure-of-arrays steps; the forces are added cell by cell in order, so every molecule sums
// its cells in the same order as there. g: the gradient weights' magnitudes 1/(4h) per axis.
//
// rows: the cells are consecutive along x (base[i] = base[0] + i) and corner 2r + 1 follows corner 2r (r = 0..3:
// the four lattice rows of the block's corners, more than n molecules apart). Then each row's molecules are read
// once (not twice, as corners 2r and 2r + 1 of neighbouring cells), and each row's forces are added in two
// passes, first the cells' corner 2r + 1 (the cell before a molecule), then corner 2r (the cell after it): each
// molecule still sums its cells in increasing order.
//
// rest (rows only, may be null): the lattice that gives the rows' rest positions (offset + index * h, the doubles
// the model's rest positions hold: checked when the term is built), so that X is not read: a quarter of the
// bytes the row blocks stream at 10^6 molecules (docs/benchmarks.md).
struct RowRest {
  double offset[3], h[3];
  long ijk[3];  // the lattice index of the block's corner 0
};
// The four corner rows' displacements x - X of a row block, interleaved as x; with rest, X is the lattice's
// (BoxGeometry::rest_position's arithmetic: offset + (double) index * h, per axis), not read.
__attribute__((always_inline)) inline void row_displacements(int n, const int* __restrict base,
                                                             const int* __restrict offset, const RowRest* rest,
                                                             const double* __restrict x, const double* __restrict X,
                                                             double (*__restrict out)[3 * (kCellBlock + 1)]) {
  if (rest) {
    alignas(64) double Xx[kCellBlock + 1];
    for (int j = 0; j < n + 1; ++j) Xx[j] = rest->offset[0] + static_cast<double>(rest->ijk[0] + j) * rest->h[0];
    for (int r = 0; r < 4; ++r) {
      const double Xy = rest->offset[1] + static_cast<double>(rest->ijk[1] + (r & 1)) * rest->h[1];
      const double Xz = rest->offset[2] + static_cast<double>(rest->ijk[2] + (r >> 1)) * rest->h[2];
      const double* __restrict xr = x + 3 * (base[0] + offset[2 * r]);
      double* __restrict u = out[r];
      for (int j = 0; j < n + 1; ++j)
        u[3 * j] = xr[3 * j] - Xx[j], u[3 * j + 1] = xr[3 * j + 1] - Xy, u[3 * j + 2] = xr[3 * j + 2] - Xz;
    }
  } else {
    for (int r = 0; r < 4; ++r) {
      const int s = 3 * (base[0] + offset[2 * r]);
      for (int j = 0; j < 3 * (n + 1); ++j) out[r][j] = x[s + j] - X[s + j];
    }
  }
}
TISSUE_CLONES
void cell_block_forces(int n, const int* __restrict base, const int* __restrict offset, bool rows,
                       const RowRest* rest, const double* __restrict x, const double* __restrict X,
                       const Moduli& m, double volume, const double g[3], int owned, double* __restrict f) {
  alignas(64) double F[9][kCellBlock], P[9][kCellBlock], J[kCellBlock];
  const double gx = g[0], gy = g[1], gz = g[2];
  if (rows) {
    alignas(64) double ur[4][3 * (kCellBlock + 1)];  // the rows' displacements, interleaved as x
    // The next block's leading rows (1 and 3; rows 0 and 2 are the cell row before's 1 and 3, in cache) in x and
    // f, requested now so that they arrive while this block computes: 10 % off the kernel at 10^6 molecules
    // (docs/benchmarks.md).
    for (int r = 1; r < 4; r += 2) {
      const std::size_t s = 3 * static_cast<std::size_t>(base[0] + offset[2 * r] + n + 1);
      const char* xp = reinterpret_cast<const char*>(x + s);
      const char* fp = reinterpret_cast<const char*>(f + s);
      for (int o = 0; o < 3 * static_cast<int>(sizeof(double)) * kCellBlock; o += 64)
        __builtin_prefetch(xp + o, 0), __builtin_prefetch(fp + o, 1);
    }
    row_displacements(n, base, offset, rest, x, X, ur);
    row_gradient(ur[0], ur[1], ur[2], ur[3], n, gx, gy, gz, F);
  } else {
    for (int d = 0; d < 3; ++d)
      for (int i = 0; i < n; ++i) {
        double u[8];
        for (int c = 0; c < 8; ++c) {
          const int j = 3 * (base[i] + offset[c]) + d;
          u[c] = x[j] - X[j];
        }
        corner_gradient(u[0], u[1], u[2], u[3], u[4], u[5], u[6], u[7], gx, gy, gz, F[3 * d][i], F[3 * d + 1][i],
                        F[3 * d + 2][i]);
      }
  }
  for (int i = 0; i < n; ++i) F[0][i] += 1.0, F[4][i] += 1.0, F[8][i] += 1.0;
  // stress(): J, cof = J F^-T, then each part added to P = 0.
  alignas(64) double cof[9][kCellBlock];
  for (int i = 0; i < n; ++i) {
    const double F0 = F[0][i], F1 = F[1][i], F2 = F[2][i], F3 = F[3][i], F4 = F[4][i], F5 = F[5][i], F6 = F[6][i],
                 F7 = F[7][i], F8 = F[8][i];
    J[i] = F0 * (F4 * F8 - F5 * F7) - F1 * (F3 * F8 - F5 * F6) + F2 * (F3 * F7 - F4 * F6);
    cof[0][i] = F4 * F8 - F5 * F7, cof[1][i] = F5 * F6 - F3 * F8, cof[2][i] = F3 * F7 - F4 * F6;
    cof[3][i] = F2 * F7 - F1 * F8, cof[4][i] = F0 * F8 - F2 * F6, cof[5][i] = F1 * F6 - F0 * F7;
    cof[6][i] = F1 * F5 - F2 * F4, cof[7][i] = F2 * F3 - F0 * F5, cof[8][i] = F0 * F4 - F1 * F3;
    for (int q = 0; q < 9; ++q) P[q][i] = 0.0;
  }
  if (m.mu != 0) {
    alignas(64) double scale[kCellBlock];
    for (int i = 0; i < n; ++i) scale[i] = J[i] > 0 ? std::pow(J[i], -2.0 / 3.0) : 0.0;  // pow is not vectorized
    for (int i = 0; i < n; ++i) {
      double I1 = 0.0;
      for (int q = 0; q < 9; ++q) I1 = I1 + F[q][i] * F[q][i];
      const double s = m.mu * scale[i], third = I1 / (3.0 * J[i]);
      for (int q = 0; q < 9; ++q) P[q][i] = P[q][i] + s * (F[q][i] - third * cof[q][i]);
    }
  }
  if (m.kappa != 0) {
    const double half = 0.5 * m.kappa;
    for (int i = 0; i < n; ++i) {
      const double vol = half * (J[i] * J[i] - 1.0) / J[i];
      for (int q = 0; q < 9; ++q) P[q][i] = P[q][i] + vol * cof[q][i];
    }
  }
  for (int w = 0; w < 3; ++w) {
    if (m.alpha[w] == 0) continue;
    const int a = (w + 1) % 3, b = (w + 2) % 3;
    for (const double sign : {1.0, -1.0})
      for (int i = 0; i < n; ++i) {
        double Fn[3];
        for (int r = 0; r < 3; ++r) Fn[r] = (F[3 * r + a][i] + sign * F[3 * r + b][i]) * M_SQRT1_2;
        const double stretch = Fn[0] * Fn[0] + Fn[1] * Fn[1] + Fn[2] * Fn[2] - 1.0;
        const double c = m.alpha[w] * stretch * M_SQRT1_2;
        for (int r = 0; r < 3; ++r) {
          P[3 * r + a][i] = P[3 * r + a][i] + c * Fn[r];
          P[3 * r + b][i] = P[3 * r + b][i] + c * sign * Fn[r];
        }
      }
  }
  // Q = V0 P g per column (in P's place), then the signed sums per corner, added cell by cell.
  double(&q)[9][kCellBlock] = P;
  for (int r = 0; r < 3; ++r)
    for (int i = 0; i < n; ++i) {
      q[3 * r][i] = volume * P[3 * r][i] * gx;
      q[3 * r + 1][i] = volume * P[3 * r + 1][i] * gy;
      q[3 * r + 2][i] = volume * P[3 * r + 2][i] * gz;
    }
  bool inverted = false;
  for (int i = 0; i < n; ++i) inverted |= !(J[i] > 0);
  if (rows && !inverted) {
    add_row_corners(q, n, base, offset, owned, f);
    return;
  }
  alignas(64) int along[kCellBlock];  // a row block's cells' bases (it is given base[0] only: Block::base0)
  if (rows) {
    for (int i = 0; i < n; ++i) along[i] = base[0] + i;
    base = along;
  }
  for (int i = 0; i < n; ++i) {
    if (!(J[i] > 0)) {
      // An inverted cell: its energy is infinite; NaN forces make every solver's guard stop or cut back.
      for (int c = 0; c < 8; ++c)
        if (base[i] + offset[c] < owned)
          for (int r = 0; r < 3; ++r) f[3 * (base[i] + offset[c]) + r] = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    add_cell_corners(q, i, base, offset, owned, f);
  }
}

// The derivative of cof F along d (d cof F [d]): the products' and the volumetric kernel's one expression.
__attribute__((always_inline)) inline void dcof_of(const double F[9], const double d[9], double dcof[9]) {
  dcof[0] = (d[4] * F[8] + F[4] * d[8]) - (d[5] * F[7] + F[5] * d[7]);
  dcof[1] = (d[5] * F[6] + F[5] * d[6]) - (d[3] * F[8] + F[3] * d[8]);
  dcof[2] = (d[3] * F[7] + F[3] * d[7]) - (d[4] * F[6] + F[4] * d[6]);
  dcof[3] = (d[2] * F[7] + F[2] * d[7]) - (d[1] * F[8] + F[1] * d[8]);
  dcof[4] = (d[0] * F[8] + F[0] * d[8]) - (d[2] * F[6] + F[2] * d[6]);
  dcof[5] = (d[1] * F[6] + F[1] * d[6]) - (d[0] * F[7] + F[0] * d[7]);
  dcof[6] = (d[1] * F[5] + F[1] * d[5]) - (d[2] * F[4] + F[2] * d[4]);
  dcof[7] = (d[2] * F[3] + F[2] * d[3]) - (d[0] * F[5] + F[0] * d[5]);
  dcof[8] = (d[0] * F[4] + F[0] * d[4]) - (d[1] * F[3] + F[1] * d[3]);
}

// stress()'s derivative along d for plain moduli (no fibres, no history) at F, with s = mu J^(-2/3) given, one
// cell (a vector lane of cell_block_tangent, or one cell of the diagonal): d(cof) is bilinear in F and d;
// dJ = cof : d; s moves by -2/3 s dJ / J, I1 / (3J) by (2/3 F : d - I1 / (3J) dJ) / J; the volumetric factor
// kappa/2 (J - 1/J) by kappa/2 (1 + 1/J^2) dJ (half = kappa/2). P is set; then each face diagonal's part is
// added (below).
__attribute__((always_inline)) inline void isotropic_stress_direction(const double F[9], double s, double half,
                                                                      const double d[9], double P[9]) {
  const double cof[9] = {F[4] * F[8] - F[5] * F[7], F[5] * F[6] - F[3] * F[8], F[3] * F[7] - F[4] * F[6],
                         F[2] * F[7] - F[1] * F[8], F[0] * F[8] - F[2] * F[6], F[1] * F[6] - F[0] * F[7],
                         F[1] * F[5] - F[2] * F[4], F[2] * F[3] - F[0] * F[5], F[0] * F[4] - F[1] * F[3]};
  double dcof[9];
  dcof_of(F, d, dcof);
  const double J = F[0] * cof[0] + F[1] * cof[1] + F[2] * cof[2];
  double dJ = 0, I1 = 0, dI1 = 0;
  for (int q = 0; q < 9; ++q) dJ += cof[q] * d[q], I1 += F[q] * F[q], dI1 += F[q] * d[q];
  const double rJ = 1.0 / J, third = I1 * rJ / 3.0;
  const double ds = -2.0 / 3.0 * s * dJ * rJ, dthird = (2.0 * dI1 / 3.0 - third * dJ) * rJ;
  const double vol = half * (J - rJ), dvol = half * (1.0 + rJ * rJ) * dJ;
  for (int q = 0; q < 9; ++q)
    P[q] = ds * (F[q] - third * cof[q]) + s * (d[q] - dthird * cof[q] - third * dcof[q]) + dvol * cof[q] +
           vol * dcof[q];
}

// The derivative of one face diagonal's stress (face plane (a, b), n = (e_a + sign e_b) / sqrt 2) along d, from
// F's and d's columns a and b (Fa[r] = F[3r + a], ...): c Fn's derivative t = dc Fn + c dFn with c = alpha
// stretch scale (alpha = the plane's alpha_w, scale = 1/sqrt 2; the blocks pass alpha_w / sqrt 2 and 1, the
// rounding each path always had), which adds t to P's column a and sign t to its column b.
__attribute__((always_inline)) inline void face_diagonal_stress_direction(const double Fa[3], const double Fb[3],
                                                                          const double da[3], const double db[3],
                                                                          double sign, double alpha, double scale,
                                                                          double t[3]) {
  double Fn[3], dFn[3];
  for (int r = 0; r < 3; ++r) Fn[r] = (Fa[r] + sign * Fb[r]) * M_SQRT1_2, dFn[r] = (da[r] + sign * db[r]) * M_SQRT1_2;
  const double stretch = Fn[0] * Fn[0] + Fn[1] * Fn[1] + Fn[2] * Fn[2] - 1.0;
  const double dstretch = 2.0 * (Fn[0] * dFn[0] + Fn[1] * dFn[1] + Fn[2] * dFn[2]);
  const double c = alpha * stretch * scale, dc = alpha * dstretch * scale;
  for (int r = 0; r < 3; ++r) t[r] = dc * Fn[r] + c * dFn[r];
}

// The tangent's product on the same blocks as cell_block_forces (the same corner patterns and row layout): per
// cell dF = sum_a u_a (x) g_a from the corners' u, dP = dP/dF [dF], and K u = V0 dP g_a added to the owned
// corners, each molecule summing its cells in increasing order. The block's cells are the vector lanes of its
// state: with moduli m (plain cells: no fibres, no history), F and scale = mu J^(-2/3) per cell
// (state[q n + i], q = 0..8 F's, 9 the scale: 80 B a cell) and dP is stress()'s derivative along dF in closed
// form (below); without, D = dP/dF (state[(9 p + q) n + i] = dP_q / dF_p: 648 B a cell). An inverted cell's
// state is F = I, scale 0 (adds a finite value; the residual is NaN already) or D = 0.
TISSUE_CLONES
void cell_block_tangent(int n, const int* __restrict base, const int* __restrict offset, bool rows,
                        const double* __restrict u, const double* __restrict D, const Moduli* m, double volume,
                        const double g[3], int owned, double* __restrict out) {
  alignas(64) double dF[9][kCellBlock], dP[9][kCellBlock];
  const double gx = g[0], gy = g[1], gz = g[2];
  if (rows) {
    const double* ur[4];
    for (int r = 0; r < 4; ++r) ur[r] = u + 3 * (base[0] + offset[2 * r]);
    row_gradient(ur[0], ur[1], ur[2], ur[3], n, gx, gy, gz, dF);
  } else {
    for (int d = 0; d < 3; ++d)
      for (int i = 0; i < n; ++i) {
        double v[8];
        for (int c = 0; c < 8; ++c) v[c] = u[3 * (base[i] + offset[c]) + d];
        corner_gradient(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], gx, gy, gz, dF[3 * d][i], dF[3 * d + 1][i],
                        dF[3 * d + 2][i]);
      }
  }
  if (m) {
    // stress()'s derivative along dF with the cells as vector lanes: the isotropic parts, then each face diagonal
    // in its own loop (as cell_block_forces).
    const std::size_t sn = static_cast<std::size_t>(n);
    const double* __restrict Fs = D;
    const double half = 0.5 * m->kappa;
    for (int i = 0; i < n; ++i) {
      double F[9], d[9], P[9];
      for (int q = 0; q < 9; ++q) F[q] = Fs[q * sn + i], d[q] = dF[q][i];
      isotropic_stress_direction(F, Fs[9 * sn + i], half, d, P);
      for (int q = 0; q < 9; ++q) dP[q][i] = P[q];
    }
    for (int w = 0; w < 3; ++w) {
      if (m->alpha[w] == 0) continue;
      const int a = (w + 1) % 3, b = (w + 2) % 3;
      const double alpha = m->alpha[w] * M_SQRT1_2;
      for (int k = 0; k < 2; ++k) {
        const double sign = k == 0 ? 1.0 : -1.0;
        for (int i = 0; i < n; ++i) {
          double Fa[3], Fb[3], da[3], db[3], t[3];
          for (int r = 0; r < 3; ++r)
            Fa[r] = Fs[(3 * r + a) * sn + i], Fb[r] = Fs[(3 * r + b) * sn + i], da[r] = dF[3 * r + a][i],
            db[r] = dF[3 * r + b][i];
          face_diagonal_stress_direction(Fa, Fb, da, db, sign, alpha, 1.0, t);
          for (int r = 0; r < 3; ++r) dP[3 * r + a][i] += t[r], dP[3 * r + b][i] += sign * t[r];
        }
      }
    }
  } else {
    for (int q = 0; q < 9; ++q) {
      for (int i = 0; i < n; ++i) dP[q][i] = 0.0;
      for (int p = 0; p < 9; ++p) {
        const double* __restrict Dpq = D + static_cast<std::size_t>(9 * p + q) * n;
        for (int i = 0; i < n; ++i) dP[q][i] = dP[q][i] + Dpq[i] * dF[p][i];
      }
    }
  }
  add_cell_products(dP, n, volume, gx, gy, gz, rows, base, offset, owned, out);
}

__attribute__((always_inline)) inline void cof_of(const double F[9], double cof[9]) {
  cof[0] = F[4] * F[8] - F[5] * F[7], cof[1] = F[5] * F[6] - F[3] * F[8], cof[2] = F[3] * F[7] - F[4] * F[6];
  cof[3] = F[2] * F[7] - F[1] * F[8], cof[4] = F[0] * F[8] - F[2] * F[6], cof[5] = F[1] * F[6] - F[0] * F[7];
  cof[6] = F[1] * F[5] - F[2] * F[4], cof[7] = F[2] * F[3] - F[0] * F[5], cof[8] = F[0] * F[4] - F[1] * F[3];
}

// cell_block_tangent for volumetric-only cells (mu = 0, no virtual diagonals: cubic cells at nu > 1/4, W =
// kappa/4 (J^2 - 1 - 2 ln J)), from the Newton iterate's positions x instead of a state per cell: F = I + the same
// axis differences of the displacements d = x - X as dF's of u (row layout or gathered), then dP = W'' dJ cof F +
// W' dcof with W' = kappa/2 (J - 1/J), W'' = kappa/2 (1 + 1/J^2) (isotropic_stress_direction's terms with s = 0).
// Row blocks on a lattice (rest given) compute X as cell_block_forces does (the same doubles as the model's rest
// positions), so the kernel reads x, which the springs' product has just read (the fused pass: MatrixFreeTangent),
// where a state of 80 B a cell, or of d, would be streamed on every application. An inverted cell takes F = I.
// at_rest (x is the rest positions: the finest level's rest tangent, src/solvers/rest_tangent.hpp): F = I exactly,
// so cof F = I, J = 1, W' = 0 and dP = kappa tr(dF) I, the same numbers without x, G, cof or dcof.
// The rest form's rows de-interleaved (x, y, z of each molecule) by the last row blocks of one product: rows 1 and 3
// of the cell row (j, k) are rows 0 and 2 of (j + 1, k), the next block of the same x range. An entry is found by
// its rows' addresses in u and its length; reset() before every product (u's values change between products).
struct RestRows {
  static constexpr int kEntries = 4;  // a lattice row in up to 4 blocks
  struct Entry {
    const double* row[2] = {nullptr, nullptr};  // the block's rows 1 and 3 in u
    int n = -1;
    alignas(64) double x[2][kCellBlock + 1], y[2][kCellBlock + 1], z[2][kCellBlock + 1];
  };
  Entry entry[kEntries];
  int next = 0;
  void reset() {
    for (Entry& e : entry) e.n = -1;
  }
};
// One row's n + 1 molecules into x, y, z.
__attribute__((always_inline)) inline void split_row(const double* __restrict r, int n, double* __restrict x,
                                                     double* __restrict y, double* __restrict z) {
  for (int j = 0; j <= n; ++j) x[j] = r[3 * j], y[j] = r[3 * j + 1], z[j] = r[3 * j + 2];
}
// The F = I form's Q from the four corner rows' molecules split into x, y, z (xs[r][j]: row r's molecule j): tr dF
// with corner_gradient's differences in its order, then Q = -V0 kappa tr dF g.
__attribute__((always_inline)) inline void rest_split_q(int n, const double* const* xs, const double* const* ys,
                                                        const double* const* zs, double kappa, double volume,
                                                        double gx, double gy, double gz, double* __restrict Q) {
  const double *__restrict y0 = ys[0], *__restrict y1 = ys[1], *__restrict y2 = ys[2], *__restrict y3 = ys[3];
  const double *__restrict z0 = zs[0], *__restrict z1 = zs[1], *__restrict z2 = zs[2], *__restrict z3 = zs[3];
  alignas(64) double dy[2][kCellBlock + 1], dz[2][kCellBlock + 1];
  for (int j = 0; j <= n; ++j) {
    dy[0][j] = y1[j] - y0[j], dy[1][j] = y3[j] - y2[j];
    dz[0][j] = z2[j] - z0[j], dz[1][j] = z3[j] - z1[j];
  }
  const double* const* ux = xs;
  alignas(64) double tr[kCellBlock];
  for (int i = 0; i < n; ++i) {
    const double tx = ((ux[0][i + 1] - ux[0][i]) + (ux[1][i + 1] - ux[1][i]) + (ux[2][i + 1] - ux[2][i]) +
                       (ux[3][i + 1] - ux[3][i])) * gx;
    const double ty = (dy[0][i] + dy[0][i + 1] + dy[1][i] + dy[1][i + 1]) * gy;
    const double tz = (dz[0][i] + dz[0][i + 1] + dz[1][i] + dz[1][i + 1]) * gz;
    tr[i] = tx + ty + tz;
  }
  const double stiff = 0.5 * kappa * 2.0;  // half (1 + 1 / J^2) at J = 1, as volumetric_block_tangent's
  for (int i = 0; i < n; ++i) {
    const double sv = -volume * (stiff * tr[i]);  // add_cell_products' -volume dP g, dP = dvol I
    Q[3 * i] = sv * gx, Q[3 * i + 1] = sv * gy, Q[3 * i + 2] = sv * gz;
  }
}

// The F = I form's Q of a row block's n cells (Q[3i + d] = cell i's -V0 dP g, d's entry; dP = kappa tr(dF) I),
// interleaved as the molecules: volumetric_block_tangent's rest rows, and the pull form's cell rows (below).
__attribute__((always_inline)) inline void rest_rows_q(int n, const int* __restrict base,
                                                       const int* __restrict offset, const double* __restrict u,
                                                       double kappa, double volume, double gx, double gy, double gz,
                                                       RestRows* cache, double* __restrict Q) {
  const double* r0 = u + 3 * (base[0] + offset[0]);
  const double* r1 = u + 3 * (base[0] + offset[2]);
  const double* r2 = u + 3 * (base[0] + offset[4]);
  const double* r3 = u + 3 * (base[0] + offset[6]);
  // corner_gradient's entries a of x, b of y, c of z, with the same differences in the same order: each row's
  // molecules read once, not twice (as corner a of cell i and corner b of cell i - 1), rows 0 and 2 from the
  // cache when the block before in the same x range split them, and the cells' sums from contiguous arrays
  // instead of the rows' interleaved components.
  RestRows::Entry local[2];
  const RestRows::Entry* hit = nullptr;
  if (cache)
    for (const RestRows::Entry& e : cache->entry)
      if (e.n == n && e.row[0] == r0 && e.row[1] == r2) hit = &e;
  const double *x0, *y0, *z0, *x2, *y2, *z2;
  if (hit) {
    x0 = hit->x[0], y0 = hit->y[0], z0 = hit->z[0], x2 = hit->x[1], y2 = hit->y[1], z2 = hit->z[1];
  } else {
    split_row(r0, n, local[0].x[0], local[0].y[0], local[0].z[0]);
    split_row(r2, n, local[0].x[1], local[0].y[1], local[0].z[1]);
    x0 = local[0].x[0], y0 = local[0].y[0], z0 = local[0].z[0];
    x2 = local[0].x[1], y2 = local[0].y[1], z2 = local[0].z[1];
  }
  RestRows::Entry* keep = &local[1];
  if (cache) {
    if (&cache->entry[cache->next] == hit) cache->next = (cache->next + 1) % RestRows::kEntries;
    keep = &cache->entry[cache->next];
    cache->next = (cache->next + 1) % RestRows::kEntries;
  }
  split_row(r1, n, keep->x[0], keep->y[0], keep->z[0]);
  split_row(r3, n, keep->x[1], keep->y[1], keep->z[1]);
  keep->row[0] = r1, keep->row[1] = r3, keep->n = n;
  const double* const xs[4] = {x0, keep->x[0], x2, keep->x[1]};
  const double* const ys[4] = {y0, keep->y[0], y2, keep->y[1]};
  const double* const zs[4] = {z0, keep->z[0], z2, keep->z[1]};
  rest_split_q(n, xs, ys, zs, kappa, volume, gx, gy, gz, Q);
}
TISSUE_CLONES
void volumetric_block_tangent(int n, const int* __restrict base, const int* __restrict offset, bool rows,
                              const RowRest* rest, const double* __restrict u, const double* __restrict x,
                              const double* __restrict X, double kappa, double volume, const double g[3], int owned,
                              double* __restrict out, bool at_rest, RestRows* cache) {
  alignas(64) double dF[9][kCellBlock], G[9][kCellBlock], dP[9][kCellBlock];
  const double gx = g[0], gy = g[1], gz = g[2];
  if (at_rest) {
    if (rows) {
      // Only tr dF is read (dF's diagonal), then the diagonal Q's corner sums.
      alignas(64) double Q[3 * kCellBlock];
      rest_rows_q(n, base, offset, u, kappa, volume, gx, gy, gz, cache, Q);
      add_row_corners_at_rest(Q, n, base, offset, owned, out);
      return;
    } else {
      for (int d = 0; d < 3; ++d)
        for (int i = 0; i < n; ++i) {
          double v[8];
          for (int c = 0; c < 8; ++c) v[c] = u[3 * (base[i] + offset[c]) + d];
          corner_gradient(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], gx, gy, gz, dF[3 * d][i],
                          dF[3 * d + 1][i], dF[3 * d + 2][i]);
        }
    }
    const double stiff = 0.5 * kappa * 2.0;  // half (1 + 1 / J^2) at J = 1, as below
    for (int i = 0; i < n; ++i) {
      const double dvol = stiff * (dF[0][i] + dF[4][i] + dF[8][i]);
      for (int q = 0; q < 9; ++q) dP[q][i] = q % 4 == 0 ? dvol : 0.0;
    }
    add_cell_products(dP, n, volume, gx, gy, gz, rows, base, offset, owned, out);
    return;
  }
  if (rows) {
    const double* ur[4];
    for (int r = 0; r < 4; ++r) ur[r] = u + 3 * (base[0] + offset[2 * r]);
    row_gradient(ur[0], ur[1], ur[2], ur[3], n, gx, gy, gz, dF);
    alignas(64) double dr[4][3 * (kCellBlock + 1)];  // the rows' displacements, interleaved as x
    row_displacements(n, base, offset, rest, x, X, dr);
    row_gradient(dr[0], dr[1], dr[2], dr[3], n, gx, gy, gz, G);
  } else {
    for (int d = 0; d < 3; ++d)
      for (int i = 0; i < n; ++i) {
        double v[8], w[8];
        for (int c = 0; c < 8; ++c) {
          const int j = 3 * (base[i] + offset[c]) + d;
          v[c] = u[j], w[c] = x[j] - X[j];
        }
        corner_gradient(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], gx, gy, gz, dF[3 * d][i], dF[3 * d + 1][i],
                        dF[3 * d + 2][i]);
        corner_gradient(w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7], gx, gy, gz, G[3 * d][i], G[3 * d + 1][i],
                        G[3 * d + 2][i]);
      }
  }
  // An inverted cell takes F = I (the residual is NaN already): found in a pass of its own, so that the lanes'
  // arithmetic below has no branch and vectorizes.
  alignas(64) double Js[kCellBlock];
  for (int i = 0; i < n; ++i) {
    double F[9], cof[9];
    for (int q = 0; q < 9; ++q) F[q] = G[q][i] + (q % 4 == 0 ? 1.0 : 0.0);
    cof_of(F, cof);
    Js[i] = F[0] * cof[0] + F[1] * cof[1] + F[2] * cof[2];
  }
  for (int i = 0; i < n; ++i)
    if (!(Js[i] > 0))
      for (int q = 0; q < 9; ++q) G[q][i] = 0.0;
  const double half = 0.5 * kappa;
  for (int i = 0; i < n; ++i) {
    double F[9], d[9], cof[9];
    for (int q = 0; q < 9; ++q) F[q] = G[q][i] + (q % 4 == 0 ? 1.0 : 0.0), d[q] = dF[q][i];
    cof_of(F, cof);
    const double J = F[0] * cof[0] + F[1] * cof[1] + F[2] * cof[2];
    double dcof[9];
    dcof_of(F, d, dcof);
    double dJ = 0;
    for (int q = 0; q < 9; ++q) dJ += cof[q] * d[q];
    const double rJ = 1.0 / J;
    const double vol = half * (J - rJ), dvol = half * (1.0 + rJ * rJ) * dJ;
    for (int q = 0; q < 9; ++q) dP[q][i] = dvol * cof[q] + vol * dcof[q];
  }
  add_cell_products(dP, n, volume, gx, gy, gz, rows, base, offset, owned, out);
}

// The pull form of the rest rows (CellElasticity::pull_rows_): a row block's Q into a cell row's slot of the ring.
TISSUE_CLONES
void rest_block_q(int n, const int* __restrict base, const int* __restrict offset, const double* __restrict u,
                  double kappa, double volume, const double g[3], RestRows* cache, double* __restrict Q) {
  rest_rows_q(n, base, offset, u, kappa, volume, g[0], g[1], g[2], cache, Q);
}

// Four doubles; V4u at any double's address (unaligned loads and stores, aliasing doubles).
typedef double V4 __attribute__((vector_size(32)));
typedef double V4u __attribute__((vector_size(32), aligned(8), may_alias));
#define TISSUE_LOADV(p) (*reinterpret_cast<const Vu*>(p))  // a V at any double's address (pull_row_vectors)

// The pull form with its molecule rows split once a product (CellElasticity::pull_cells_to): a molecule row into
// x, y, z, and a block's Q from its four rows' split molecules.
TISSUE_CLONES
void split_molecule_row(const double* __restrict r, int n, double* __restrict x, double* __restrict y,
                        double* __restrict z) {
  split_row(r, n, x, y, z);
}
TISSUE_CLONES
void rest_split_block_q(int n, const double* const* xs, const double* const* ys, const double* const* zs,
                        double kappa, double volume, const double g[3], double* __restrict Q) {
  rest_split_q(n, xs, ys, zs, kappa, volume, g[0], g[1], g[2], Q);
}

// The sign tables' period: 3 components, so a row longer than a block's is taken in chunks of kSignSpan entries
// (a multiple of 3) whose table index restarts at 3.
constexpr int kSignSpan = 3 * kCellBlock;

// One cell row's terms (Q, as its corner row r) added to a molecule row of n + 1 molecules, the first `touched`
// owned: add_row_corners_at_rest's operations for one r, over the whole cell row at once (its blocks' ends
// included: a molecule between two blocks took the first's cell before, then the second's cell after).
__attribute__((always_inline)) inline void pull_one_row(const double* __restrict Q, int r, int n, int touched,
                                                        double* __restrict fr) {
  const double* __restrict at = kRestCornerSigns.s[r][0];
  const double* __restrict next = kRestCornerSigns.s[r][1];
  const int m = 3 * std::min(n, touched), t = 3 * touched;
  for (int k = 0; k < std::min(3, m); ++k) fr[k] += at[k] * Q[k];
  for (int c = 3; c < m; c += kSignSpan) {
    const int e = std::min(m, c + kSignSpan), o = c - 3;
    for (int k = c; k < e; ++k) fr[k] = (fr[k] + next[k - o] * Q[k - 3]) + at[k - o] * Q[k];
  }
  for (int k = std::max(3, m); k < t; ++k) fr[k] += next[k % 3] * Q[k - 3];
}

// pull_row_at_rest's interior molecules from i on, L = the lanes of V molecules a step (3 L doubles, three vectors),
// while L fit before n; returns where it stopped. The mixed signs as +-(P q) with P one of three patterns by
// component, P0 = (-, +, +), P1 = (-, -, +), P2 = (-, +, -) (n3 = -1, a3 = -P0, n2 = P2, a2 = -P1, n1 = P1,
// a1 = -P2, n0 = P0, a0 = 1): P q is +-q exactly, so each sum is the scalar loop's; the nine vectors P of the three
// phases stay in registers (the compiler's own vectorization blended an addition and a subtraction per term).
// (The lane count, not the vector types, is the template's argument: an aligned(8) typedef passed as one loses
// its attribute, and the loads then assume the vector's own alignment; RowLanes holds both types by count.)
template <int L>
struct RowLanes;
template <>
struct RowLanes<8> {
  typedef double V __attribute__((vector_size(64)));
  typedef double Vu __attribute__((vector_size(64), aligned(8), may_alias));
};
template <>
struct RowLanes<4> {
  typedef V4 V;
  typedef V4u Vu;
};
template <int L>
__attribute__((always_inline)) inline int pull_row_vectors(int i, int n, const double* __restrict q3,
                                                           const double* __restrict q2, const double* __restrict q1,
                                                           const double* __restrict q0, double* __restrict fr) {
  typedef typename RowLanes<L>::V V;
  typedef typename RowLanes<L>::Vu Vu;
  V P[3][3];
  for (int j = 0; j < 3; ++j)
    for (int l = 0; l < L; ++l) {
      const int d = (L * j + l) % 3;
      P[0][j][l] = d == 0 ? -1.0 : 1.0, P[1][j][l] = d == 2 ? 1.0 : -1.0, P[2][j][l] = d == 1 ? 1.0 : -1.0;
    }
  for (; i + L <= n; i += L) {
    const int k0 = 3 * i;
    for (int j = 0; j < 3; ++j) {
      const int k = k0 + L * j;
      V v = TISSUE_LOADV(fr + k);
      v = v - TISSUE_LOADV(q3 + k - 3);
      v = v - P[0][j] * TISSUE_LOADV(q3 + k);
      v = v + P[2][j] * TISSUE_LOADV(q2 + k - 3);
      v = v - P[1][j] * TISSUE_LOADV(q2 + k);
      v = v + P[1][j] * TISSUE_LOADV(q1 + k - 3);
      v = v - P[2][j] * TISSUE_LOADV(q1 + k);
      v = v + P[0][j] * TISSUE_LOADV(q0 + k - 3);
      v = v + TISSUE_LOADV(q0 + k);
      *reinterpret_cast<Vu*>(fr + k) = v;
    }
  }
  return i;
}

// A molecule row's cells' terms, pulled: out's n + 1 molecules (touched of them owned) take their cell rows'
// Q[e] (as corner rows r[e]) in the cell rows' order, e = 0 .. count - 1, each molecule its cell before and then
// its cell after from each: the terms and their order of the push form (each block's add_row_corners_at_rest),
// so the same bits. A whole interior row (4 cell rows) reads and writes each molecule once.
TISSUE_CLONES
void pull_row_at_rest(const double* const* Q, const int* r, int count, int n, int touched, double* __restrict fr) {
  if (count != 4 || touched != n + 1 || r[0] != 3 || r[1] != 2 || r[2] != 1 || r[3] != 0) {
    for (int e = 0; e < count; ++e) pull_one_row(Q[e], r[e], n, touched, fr);
    return;
  }
  // An interior row: its cell rows (j - 1, k - 1), (j, k - 1), (j - 1, k), (j, k) as corner rows 3, 2, 1, 0, whose
  // signs (kRestCornerSigns) are written out: x takes -q of the cell before and +q of the cell after from each,
  // y -q, +q, -q, +q of the four rows' cells (both cells), z -q, -q, +q, +q (a + (-1 q) is a - q, a + 1 q is a + q).
  const double *__restrict q3 = Q[0], *__restrict q2 = Q[1], *__restrict q1 = Q[2], *__restrict q0 = Q[3];
  fr[0] = (((fr[0] + q3[0]) + q2[0]) + q1[0]) + q0[0];
  fr[1] = (((fr[1] - q3[1]) + q2[1]) - q1[1]) + q0[1];
  fr[2] = (((fr[2] - q3[2]) - q2[2]) + q1[2]) + q0[2];
  // Eight molecules a step (three 8-lane vectors), then four (three 4-lane vectors): pull_row_vectors.
  int i = pull_row_vectors<8>(1, n, q3, q2, q1, q0, fr);
  i = pull_row_vectors<4>(i, n, q3, q2, q1, q0, fr);
  for (; i < n; ++i) {
    double* __restrict f = fr + 3 * i;
    const int k = 3 * i;
    double x = f[0], y = f[1], z = f[2];
    x = (x - q3[k - 3]) + q3[k], y = (y - q3[k - 2]) - q3[k + 1], z = (z - q3[k - 1]) - q3[k + 2];
    x = (x - q2[k - 3]) + q2[k], y = (y + q2[k - 2]) + q2[k + 1], z = (z - q2[k - 1]) - q2[k + 2];
    x = (x - q1[k - 3]) + q1[k], y = (y - q1[k - 2]) - q1[k + 1], z = (z + q1[k - 1]) + q1[k + 2];
    x = (x - q0[k - 3]) + q0[k], y = (y + q0[k - 2]) + q0[k + 1], z = (z + q0[k - 1]) + q0[k + 2];
    f[0] = x, f[1] = y, f[2] = z;
  }
  const int m = 3 * n;
  fr[m] = (((fr[m] - q3[m - 3]) - q2[m - 3]) - q1[m - 3]) - q0[m - 3];
  fr[m + 1] = (((fr[m + 1] - q3[m - 2]) + q2[m - 2]) - q1[m - 2]) + q0[m - 2];
  fr[m + 2] = (((fr[m + 2] - q3[m - 1]) - q2[m - 1]) + q1[m - 1]) + q0[m - 1];
}

// The entries of dP/dF the tangent's diagonal reads, for a block's plain cells as vector lanes (the tangent
// state's layout: F's and the scale mu J^(-2/3), Fs[q n + c]): Dd[3p + j][c] = dP_(3i + j) / dF_p with i = p / 3
// (row i of P along direction p), the product's arithmetic (isotropic part, then the face diagonals) along e_p.
TISSUE_CLONES
void plain_block_diagonal_tangent(int n, const double* __restrict Fs, const Moduli* m,
                                  double (*__restrict Dd)[kCellBlock]) {
  const std::size_t sn = static_cast<std::size_t>(n);
  const double half = 0.5 * m->kappa;
  for (int p = 0; p < 9; ++p) {
    const int i = p / 3;
    for (int c = 0; c < n; ++c) {
      double F[9], d[9], P[9];
      for (int q = 0; q < 9; ++q) F[q] = Fs[q * sn + c], d[q] = q == p ? 1.0 : 0.0;
      isotropic_stress_direction(F, Fs[9 * sn + c], half, d, P);
      for (int j = 0; j < 3; ++j) Dd[3 * p + j][c] = P[3 * i + j];
    }
    for (int w = 0; w < 3; ++w) {
      if (m->alpha[w] == 0) continue;
      const int a = (w + 1) % 3, b = (w + 2) % 3;
      for (int k = 0; k < 2; ++k) {
        const double sign = k == 0 ? 1.0 : -1.0;
        for (int c = 0; c < n; ++c) {
          double Fa[3], Fb[3], da[3], db[3], t[3];
          for (int r = 0; r < 3; ++r)
            Fa[r] = Fs[(3 * r + a) * sn + c], Fb[r] = Fs[(3 * r + b) * sn + c], da[r] = 3 * r + a == p ? 1.0 : 0.0,
            db[r] = 3 * r + b == p ? 1.0 : 0.0;
          face_diagonal_stress_direction(Fa, Fb, da, db, sign, m->alpha[w], M_SQRT1_2, t);
          Dd[3 * p + a][c] += t[i], Dd[3 * p + b][c] += sign * t[i];
        }
      }
    }
  }
}

class CellElasticity final : public Term {
public:
  CellElasticity(const Scene& scene, const LocalModel& model) : m_(model) {
    const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
    std::unordered_map<std::int64_t, int> local;
    local.reserve(model.local);
    for (int i = 0; i < model.local; ++i) local.emplace(model.id[i], i);
    // Dense cell ids for the snapshots: body by body, (i, j, k) of the cell's lowest corner in x-fastest order.
    std::vector<std::int64_t> cell_offset(model.shape.bodies(), 0);
    for (int b = 0; b < model.shape.bodies(); ++b) {
      cell_offset[b] = global_cells_;
      const CalibrationSpec& calibration =
          b < static_cast<int>(scene.calibrations.size()) ? scene.calibrations[b] : scene.calibration;
      if (!body_has_cells(specs[b], calibration)) continue;
      const BoxGeometry& box = model.shape.body(b);
      global_cells_ += static_cast<std::int64_t>(box.n[0] - 1) * (box.n[1] - 1) * (box.n[2] - 1);
    }
    // The Prony tables, in the springs' order (viscoelastic.cpp): one per body, then one per region with its own.
    std::vector<const PronySpec*> tables;
    for (const auto& s : specs) tables.push_back(&s.viscoelastic);
    std::vector<std::vector<int>> region_table(specs.size());  // per body and region: its table or -1
    for (std::size_t b = 0; b < specs.size(); ++b)
      for (const auto& r : specs[b].regions) {
        region_table[b].push_back(r.viscoelastic.empty() ? -1 : static_cast<int>(tables.size()));
        if (!r.viscoelastic.empty()) tables.push_back(&r.viscoelastic);
      }
    const bool region_tables = tables.size() > specs.size();
    std::vector<std::int64_t> bases;
    for (int i = 0; i < model.owned; ++i) {
      const int b = model.body[i];
      if (!body_has_cells(specs[b], b < static_cast<int>(scene.calibrations.size()) ? scene.calibrations[b]
                                                                                    : scene.calibration))
        continue;
      const BoxGeometry& box = model.shape.body(b);
      const auto ijk = box.index(model.id[i]);
      for (int c = 0; c < 8; ++c) {
        const long q[3] = {ijk[0] - (c & 1), ijk[1] - ((c >> 1) & 1), ijk[2] - ((c >> 2) & 1)};
        bool inside = true;
        for (int d = 0; d < 3; ++d) inside = inside && q[d] >= 0 && q[d] <= box.n[d] - 2;
        if (inside) bases.push_back(box.id(q[0], q[1], q[2]));
      }
    }
    std::sort(bases.begin(), bases.end());
    bases.erase(std::unique(bases.begin(), bases.end()), bases.end());
    cells_ = static_cast<int>(bases.size());
    base_.resize(bases.size());
    pattern_.resize(bases.size());
    std::map<std::array<int, 8>, int> patterns;  // corner offsets from corner 0 -> index in patterns_
    kind_.resize(bases.size());
    std::map<std::array<double, 6>, int> kinds;  // (mu, kappa, alpha, body) -> its index in kinds_
    for (int k = 0; k < cells_; ++k) {
      const std::int64_t base = bases[k];
      auto it = local.find(base);
      if (it == local.end()) throw std::runtime_error("cell term: a cell corner is not on this rank");
      const int b = model.body[it->second];
      const BoxGeometry& box = model.shape.body(b);
      const auto ijk = box.index(base);
      double E_s = 0, mu = 0, kappa = 0, modulus = 0, density = 0;
      std::vector<Fibre> families;
      int corner[8];
      for (int c = 0; c < 8; ++c) {
        const std::int64_t g = box.id(ijk[0] + (c & 1), ijk[1] + ((c >> 1) & 1), ijk[2] + ((c >> 2) & 1));
        auto at = local.find(g);
        if (at == local.end())
          throw std::runtime_error("cell term: the ghost layer lacks a cell corner (the cell term needs a box lattice "
                                   "built by partition/lattice_model.cpp)");
        corner[c] = at->second;
        const MoleculeMaterial mat = molecule_material(specs[b], box, g);
        const CellModuli cm = cell_moduli(mat.youngs_modulus, mat.poisson_ratio, mat.fibres);
        E_s += cm.spring_modulus / 8, mu += cm.mu_c / 8, kappa += cm.kappa_c / 8;
        density += mat.density / 8;
        if (!mat.fibres) {
          modulus += p_wave_modulus(mat.youngs_modulus, mat.poisson_ratio) / 8;
          continue;
        }
        // The fibre terms of this corner's eighth of the cell; the time step from the stiffest wave (E_L).
        const TransverseIsotropy ti = transverse_isotropy(mat.youngs_modulus, mat.poisson_ratio, *mat.fibres);
        const FibreModuli fm = fibre_moduli(ti);
        modulus += ti_stiffest_modulus(ti_stiffness(ti)) / 8;
        Fibre f;
        for (int d = 0; d < 3; ++d) f.a[d] = mat.fibres->direction[d];
        f.E_f = fm.E_f / 8, f.dG = fm.dG / 8, f.alpha = fm.alpha / 8;
        f.tension_only = mat.fibres->tension_only;
        f.toe_stretch = mat.fibres->toe_stretch, f.toe_exponent = mat.fibres->toe_exponent;
        bool merged = false;
        for (Fibre& o : families)
          if (o.same_law(f)) o.E_f += f.E_f, o.dG += f.dG, o.alpha += f.alpha, merged = true;
        if (!merged) families.push_back(f);
      }
      // The cell's Prony table: that of the region whose box (the body's frame) holds the cell's rest centre, the
      // last such one, else its body's (the springs' rule with the rest midpoint).
      int table = b;
      for (std::size_t r = 0; region_tables && r < specs[b].regions.size(); ++r) {
        if (region_table[b][r] < 0) continue;
        bool inside = true;
        for (int d = 0; d < 3; ++d) {
          const double centre = model.rest[3 * corner[0] + d] + 0.5 * box.h[d] - specs[b].offset[d];
          inside = inside && centre >= specs[b].regions[r].lo[d] && centre <= specs[b].regions[r].hi[d];
        }
        if (inside) table = region_table[b][r];
      }
      if (!tables[table]->empty()) {
        // Quasi-linear viscoelasticity: a history per Prony term on this cell's stress (the springs carry theirs).
        if (history_.empty()) history_.assign(k, -1);
        history_.push_back(history_cells_++);
        if (region_tables) table_.push_back(static_cast<std::uint16_t>(table));
        double sum = 0;
        for (double g : tables[table]->gamma) sum += g;
        modulus *= 1.0 + sum;  // the explicit step follows the instantaneous modulus (an upper bound here)
      } else if (!history_.empty()) {
        history_.push_back(-1);
      }
      if (!families.empty() && fibre_begin_.empty()) fibre_begin_.assign(k + 1, 0);
      if (!fibre_begin_.empty()) {
        fibres_.insert(fibres_.end(), families.begin(), families.end());
        fibre_begin_.push_back(static_cast<int>(fibres_.size()));
      }
      const CellSprings split = cell_springs(box.h, find_topology(box.topology)->cells);
      Kind kind;
      kind.moduli.mu = mu, kind.moduli.kappa = kappa;
      for (int w = 0; w < 3; ++w) kind.moduli.alpha[w] = split.alpha[w] * E_s;
      kind.body = b;
      // Cells share their moduli (one per material and body): an index per cell instead of 48 bytes keeps the
      // explicit loop's memory traffic down.
      const std::array<double, 6> key{mu, kappa, kind.moduli.alpha[0], kind.moduli.alpha[1], kind.moduli.alpha[2],
                                      static_cast<double>(b)};
      auto found = kinds.emplace(key, static_cast<int>(kinds_.size()));
      if (found.second) kinds_.push_back(kind);
      kind_[k] = found.first->second;
      // Corners as corner 0 plus one of few offset patterns (one for most cells of a rank): 8 bytes per cell
      // instead of 32 in the explicit loop's stream.
      std::array<int, 8> offsets;
      for (int c = 0; c < 8; ++c) offsets[c] = corner[c] - corner[0];
      auto pattern = patterns.emplace(offsets, static_cast<int>(patterns_.size()));
      if (pattern.second) patterns_.push_back(offsets);
      base_[k] = corner[0];
      pattern_[k] = pattern.first->second;
      for (int c = 0; c < 8; ++c) {
        const Vec3 X = box.rest_position(model.id[corner[c]]);
        for (int d = 0; d < 3; ++d) lattice_rest_ = lattice_rest_ && model.rest[3 * corner[c] + d] == X[d];
      }
      owns_energy_.push_back(corner[0] < model.owned);
      cell_id_.push_back(cell_offset[b] + ijk[0] + (box.n[0] - 1) * (ijk[1] + (box.n[1] - 1) * ijk[2]));
      const double h = std::min({box.h[0], box.h[1], box.h[2]});
      // 0.8 h / c_p: measured limits of dynamic runs are 0.85-1.1 h / c_p (docs/poisson.md), so this is a lower
      // bound within 1.4x of them.
      dt_ = std::min(dt_, 0.8 * h / std::sqrt(modulus / density));
    }
    // Whether cells carry a history is the scene's (every rank agrees, for the checkpoint's collective writes),
    // though a rank may hold none of those cells.
    for (int b = 0; b < model.shape.bodies(); ++b) {
      bool prony = !specs[b].viscoelastic.empty();
      for (int t : region_table[b]) prony = prony || t >= 0;
      if (prony && body_has_cells(specs[b], b < static_cast<int>(scene.calibrations.size()) ? scene.calibrations[b]
                                                                                            : scene.calibration))
        for (const PronySpec* t : tables) width_ = std::max(width_, static_cast<int>(t->gamma.size()));
    }
    if (history_cells_ > 0) {
      const int nt = static_cast<int>(tables.size());
      gamma_.assign(nt * width_, 0.0), tau_.assign(nt * width_, 1.0);
      for (int t = 0; t < nt; ++t)
        for (std::size_t i = 0; i < tables[t]->gamma.size(); ++i)
          gamma_[t * width_ + i] = tables[t]->gamma[i], tau_[t * width_ + i] = tables[t]->tau[i];
      decay_.assign(gamma_.size(), 1.0), weight_.assign(gamma_.size(), 0.0);
      s_old_.assign(9 * static_cast<std::size_t>(history_cells_), 0.0);
      h_.assign(9 * static_cast<std::size_t>(history_cells_) * width_, 0.0);
    }
    // The gradient weights g_a and V0 per body.
    for (int b = 0; b < model.shape.bodies(); ++b) {
      const BoxGeometry& box = model.shape.body(b);
      Geometry geo;
      geo.volume = box.h[0] * box.h[1] * box.h[2];
      for (int c = 0; c < 8; ++c)
        for (int d = 0; d < 3; ++d) geo.g[c][d] = (((c >> d) & 1) ? 1.0 : -1.0) / (4.0 * box.h[d]);
      for (int a = 0; a < 8; ++a)
        for (int c = 0; c < 8; ++c) {
          const double *ga = geo.g[a], *gb = geo.g[c];
          geo.cross[a][c][0] = ga[1] * gb[2] - ga[2] * gb[1];
          geo.cross[a][c][1] = ga[2] * gb[0] - ga[0] * gb[2];
          geo.cross[a][c][2] = ga[0] * gb[1] - ga[1] * gb[0];
        }
      geometry_.push_back(geo);
    }
    for (int b = 0; b < model.shape.bodies(); ++b)
      ring_ = std::max<std::size_t>(ring_, 2 + static_cast<std::size_t>(model.shape.body(b).n[0]) *
                                                   (1 + static_cast<std::size_t>(model.shape.body(b).n[1])));
    ring_ = std::min<std::size_t>(ring_, std::max(cells_, 1));
    if (fibre_begin_.empty()) make_blocks();
  }

  void add_forces(const double* x, const double*, double, double* f) override {
    // The explicit solvers' inner loop. Without fibres and a running history, runs of cells that share their
    // moduli and corner pattern go through cell_block_forces (vectorized across cells: blocks_); otherwise
    // cell_forces does the same arithmetic one cell at a time.
    if (plain()) {
      for (const Block& b : blocks_) block_forces(b, x, f);
      return;
    }
    for (int k = 0; k < cells_; ++k) cell_forces(k, x, f);
  }

  // The same blocks in the same order, each as soon as its owned corners are final: the force model calls this
  // from the connection kernel's sweep (ForceModel::forces), one plane behind its front, so that x and f come
  // from the cache. Every molecule still sums its cells in increasing order: the same bits as add_forces.
  bool adds_by_rows() const override { return plain(); }
  int add_forces_below(const double* x, int below, int from, double* f) override {
    const int nb = static_cast<int>(blocks_.size());
    for (; from < nb && blocks_[from].reach <= below; ++from) block_forces(blocks_[from], x, f);
    return from;
  }

  double potential_energy(const double* x) const override {
    double e = 0;
    for (int k = 0; k < cells_; ++k) {
      if (!owns_energy_[k]) continue;
      const Geometry& geo = geometry_[kinds_[kind_[k]].body];
      double F[9];
      int corner[8];
      corners(k, corner);
      gradient(x, corner, geo, F);
      e += geo.volume * energy_density(F, kinds_[kind_[k]].moduli, fibres(k), fibre_count(k));
    }
    return e;
  }

  bool tangent_worth_caching() const override { return true; }
  bool tangent_within_cells() const override { return true; }
  bool volume_coupling(VolumeCoupling& out) const override {
    out = VolumeCoupling{};
    out.corners.resize(8 * static_cast<std::size_t>(cells_));
    out.k.resize(cells_), out.g.resize(3 * static_cast<std::size_t>(cells_));
    for (int k = 0; k < cells_; ++k) {
      corners(k, out.corners.data() + 8 * static_cast<std::size_t>(k));
      const Kind& kind = kinds_[kind_[k]];
      const Geometry& geo = geometry_[kind.body];
      out.k[k] = kind.moduli.kappa * geo.volume;  // W = kappa/4 (J^2 - 1 - 2 ln J): W''(1) = kappa
      for (int d = 0; d < 3; ++d) out.g[3 * k + d] = geo.g[7][d];
    }
    return cells_ > 0;
  }

  // The blocks row by row: a molecule's row (its up to 8 cells' blocks, summed per neighbour: at most 27) once its
  // last cell (the highest id) is computed, each cell's dP/dF kept in a ring of the last cells while its
  // corners' rows are open (one plane of cells and a row: the lattice's cell order). A consumer that sums a row
  // at a time (LatticeGalerkin's stream) then sees one run a row instead of one per cell, and 27 blocks instead
  // of 64; each block is the per-cell one summed over the row's cells in increasing cell order.
  PetscErrorCode add_tangent(const double* x, BlockAdd add, void* ctx) const override {
    if (cells_ == 0) return 0;
    if (ring_ > kRingCells) return add_tangent_by_cell(x, add, ctx);
    const std::size_t R = ring_;
    std::vector<double> ring(81 * R);
    VolumetricBlocks reuse[8];
    int hint[8] = {-2, -2, -2, -2, -2, -2, -2, -2};  // add_row's last cell found for each corner
    for (int k = 0; k < cells_; ++k) {
      double* slot = &ring[81 * (static_cast<std::size_t>(k) % R)];
      if (!(volumetric_only(k) ? volumetric_state(k, x, slot) : stress_tangent(k, x, slot)))
        return 0;  // inverted: the residual is NaN
      const BoxGeometry& box = m_.shape.body(kinds_[kind_[k]].body);
      const auto b = box.index(m_.id[base_[k]]);
      int corner[8];
      corners(k, corner);
      // Corner c's last cell is this one when along each axis it is the cell's lower corner or the lattice ends.
      for (int c = 0; c < 8; ++c) {
        if (corner[c] >= m_.owned) continue;
        bool last = true;
        for (int d = 0; d < 3; ++d) last = last && (!(c >> d & 1) || b[d] == box.n[d] - 2);
        if (!last) continue;
        const PetscErrorCode ierr = add_row(corner[c], k, ring.data(), add, ctx, reuse, hint);
        if (ierr) return ierr;
      }
    }
    return 0;
  }

  // A plane of cells beyond kRingCells (a wide thin layer: its plane is most of its cells) would make the ring
  // a copy of dP/dF for most cells: then the blocks go cell by cell (64 a cell, each row in a run per cell).
  static constexpr std::size_t kRingCells = std::size_t(1) << 16;  // 42 MB of dP/dF
  PetscErrorCode add_tangent_by_cell(const double* x, BlockAdd add, void* ctx) const {
    for (int k = 0; k < cells_; ++k) {
      int corner[8];
      corners(k, corner);
      const Geometry& geo = geometry_[kinds_[kind_[k]].body];
      double D[9][9];
      if (!stress_tangent(k, x, D[0])) return 0;  // inverted: the residual is NaN already
      // Dg[kl][a][i] = sum_j D[kl][ij] g_a[j]
      double Dg[9][8][3];
      for (int kl = 0; kl < 9; ++kl)
        for (int a = 0; a < 8; ++a)
          for (int i = 0; i < 3; ++i)
            Dg[kl][a][i] = D[kl][3 * i] * geo.g[a][0] + D[kl][3 * i + 1] * geo.g[a][1] + D[kl][3 * i + 2] * geo.g[a][2];
      for (int a = 0; a < 8; ++a) {
        if (corner[a] >= m_.owned) continue;
        for (int b = 0; b < 8; ++b) {
          // K_ab[i][k] = V0 sum_l Dg[kl][a][i] g_b[l]: -d f_a / d x_b
          double K[9];
          for (int i = 0; i < 3; ++i)
            for (int kk = 0; kk < 3; ++kk)
              K[3 * i + kk] = geo.volume * (Dg[3 * kk][a][i] * geo.g[b][0] + Dg[3 * kk + 1][a][i] * geo.g[b][1] +
                                            Dg[3 * kk + 2][a][i] * geo.g[b][2]);
          const PetscErrorCode ierr = add(ctx, corner[a], corner[b], K);
          if (ierr) return ierr;
        }
      }
    }
    return 0;
  }

  // A volumetric-only cell's blocks K_ab (b = 0..7) for one corner a, with what they are computed from: the cell's
  // state as volumetric_state fills it (F, cof F, W', W'', cof F g_b) and its geometry. Cells whose state is equal
  // to the bit have equal blocks (at rest every cell of a body: F = I), so add_row takes them from the last cell
  // computed for the same corner instead of computing them again.
  struct VolumetricBlocks {
    static constexpr int kState = 44;
    int body = -1;  // the geometry's
    double state[kState];
    double Kb[8][9];
  };

  // Molecule m's row of the tangent from its cells (the last one is cell `last`; their dP/dF in the ring).
  PetscErrorCode add_row(int m, int last, const double* ring, BlockAdd add, void* ctx,
                         VolumetricBlocks* reuse, int* hint) const {
    const BoxGeometry& box = m_.shape.body(kinds_[kind_[last]].body);
    const auto ijk = box.index(m_.id[m]);
    double K[27][9];
    int column[27];
    std::uint32_t present = 0;
    // m's cells in increasing id: the cell with m as corner a has its lowest corner at m - a's offsets.
    for (int a = 7; a >= 0; --a) {
      long q[3];
      bool inside = true;
      for (int d = 0; d < 3; ++d) q[d] = ijk[d] - (a >> d & 1), inside = inside && q[d] >= 0 && q[d] <= box.n[d] - 2;
      if (!inside) continue;
      const std::int64_t id = box.id(q[0], q[1], q[2]);
      // Among the ring's cells (ids increasing with the index) up to `last`: the one after the last found for
      // corner a (the previous row's, nearly always), else a binary search.
      int lo = std::max(0, last - static_cast<int>(ring_) + 1), hi = last + 1;
      const int next = hint[a] + 1;
      if (next >= lo && next < hi && m_.id[base_[next]] == id) {
        lo = next;
      } else {
        while (lo < hi) {
          const int mid = (lo + hi) / 2;
          if (m_.id[base_[mid]] < id) lo = mid + 1;
          else hi = mid;
        }
      }
      const int k = lo;
      hint[a] = k;
      PetscCheck(k <= last && m_.id[base_[k]] == id, PETSC_COMM_SELF, PETSC_ERR_PLIB,
                 "cell term: a molecule's cell is not among the last cells kept");
      const double* D = ring + 81 * (static_cast<std::size_t>(k) % ring_);
      const Geometry& geo = geometry_[kinds_[kind_[k]].body];
      int corner[8];
      corners(k, corner);
      double local[8][9];
      double(*Kb)[9] = local;
      VolumetricBlocks& last_a = reuse[a];
      const int body = kinds_[kind_[k]].body;
      if (volumetric_only(k) && last_a.body == body &&
          std::memcmp(last_a.state, D, sizeof last_a.state) == 0) {
        Kb = last_a.Kb;
      } else if (volumetric_only(k)) {
        Kb = last_a.Kb;
        last_a.body = body;
        std::memcpy(last_a.state, D, sizeof last_a.state);
        volumetric_blocks(D, body, a, Kb);
      } else {
        // Dg[kl][i] = sum_j D[kl][ij] g_a[j]; K_ab[i][k] = V0 sum_l Dg[kl][i] g_b[l]: -d f_a / d x_b
        double Dg[9][3];
        for (int kl = 0; kl < 9; ++kl)
          for (int i = 0; i < 3; ++i)
            Dg[kl][i] = D[9 * kl + 3 * i] * geo.g[a][0] + D[9 * kl + 3 * i + 1] * geo.g[a][1] +
                        D[9 * kl + 3 * i + 2] * geo.g[a][2];
        for (int b = 0; b < 8; ++b)
          for (int i = 0; i < 3; ++i)
            for (int kk = 0; kk < 3; ++kk)
              Kb[b][3 * i + kk] = geo.volume * (Dg[3 * kk][i] * geo.g[b][0] + Dg[3 * kk + 1][i] * geo.g[b][1] +
                                                Dg[3 * kk + 2][i] * geo.g[b][2]);
      }
      for (int b = 0; b < 8; ++b) {
        // the neighbour's slot: (dx + 1) + 3 (dy + 1) + 9 (dz + 1), d = b's offsets - a's
        const int slot = 13 + ((b & 1) - (a & 1)) + 3 * ((b >> 1 & 1) - (a >> 1 & 1)) + 9 * ((b >> 2 & 1) - (a >> 2 & 1));
        double* to = K[slot];
        if (present >> slot & 1) {
          for (int e = 0; e < 9; ++e) to[e] += Kb[b][e];
        } else {
          for (int e = 0; e < 9; ++e) to[e] = Kb[b][e];
          column[slot] = corner[b], present |= 1u << slot;
        }
      }
    }
    for (std::uint32_t rest = present; rest; rest &= rest - 1) {
      const int slot = __builtin_ctz(rest);
      const PetscErrorCode ierr = add(ctx, m, column[slot], K[slot]);
      if (ierr) return ierr;
    }
    return 0;
  }

  // A volumetric-only cell's blocks K_ab (b = 0..7) for its corner a from its state D (volumetric_state).
  void volumetric_blocks(const double* D, int body, int a, double (*Kb)[9]) const {
    const Geometry& geo = geometry_[body];
    // K_ab = V0 (W'' (cof g_a) (x) (cof g_b) + W' [F (g_a x g_b)]_x): d cof_ij / dF_kl = e_ikm e_jln F_mn
    // contracted with g_a's j and g_b's l is the skew matrix e_ikm w_m, w = F (g_a x g_b).
    // cof g_b of the cell's 8 corners kept with its state (volumetric_state), g_a x g_b with the geometry.
    const double *F = D, w1 = D[18], w2 = D[19], *cg = D + 20;
    const double* ca = cg + 3 * a;
    for (int b = 0; b < 8; ++b) {
      const double *cross = geo.cross[a][b], *cb = cg + 3 * b;
      double w[3];
      for (int i = 0; i < 3; ++i) w[i] = w1 * (F[3 * i] * cross[0] + F[3 * i + 1] * cross[1] + F[3 * i + 2] * cross[2]);
      const double skew[9] = {0, w[2], -w[1], -w[2], 0, w[0], w[1], -w[0], 0};
      for (int i = 0; i < 3; ++i)
        for (int kk = 0; kk < 3; ++kk) Kb[b][3 * i + kk] = geo.volume * (w2 * ca[i] * cb[kk] + skew[3 * i + kk]);
    }
  }

  // At the rest positions every volumetric-only cell's state is F = I exactly (the displacements are +0), so a
  // cell's blocks for its corner a depend on its kind alone (rest_blocks_), and a row's on which of its 8 cells
  // exist and their kinds: the row's key. Every cell of the rank volumetric-only, ids increasing with the index.
  bool rest_rows() const override {
    if (!rest_checked_) {
      rest_checked_ = true;
      bool ok = lattice_rest_;
      for (int k = 1; ok && k < cells_; ++k) ok = m_.id[base_[k - 1]] < m_.id[base_[k]];
      rest_body_.assign(m_.shape.bodies(), 0);
      std::vector<int> example(kinds_.size(), -1);
      for (int k = 0; k < cells_; ++k) {
        rest_body_[kinds_[kind_[k]].body] = 1;
        if (example[kind_[k]] < 0) example[kind_[k]] = k;
      }
      rest_blocks_.assign(kinds_.size() * 8 * 8 * 9, 0.0);
      for (std::size_t t = 0; ok && t < kinds_.size(); ++t) {
        if (example[t] < 0) continue;
        double D[81];
        const Moduli& mo = kinds_[t].moduli;  // volumetric_only's, but for plain(), which may change
        ok = mo.mu == 0 && mo.alpha[0] == 0 && mo.alpha[1] == 0 && mo.alpha[2] == 0 &&
             volumetric_state(example[t], m_.rest.data(), D);
        for (int a = 0; ok && a < 8; ++a)
          volumetric_blocks(D, kinds_[t].body, a, reinterpret_cast<double(*)[9]>(&rest_blocks_[(t * 8 + a) * 72]));
      }
      rest_ok_ = ok;
    }
    return rest_ok_ && plain();
  }
  // Owned molecule i's cell with i as corner a, -1 when the lattice has none (the cells' ids increase with the
  // index: the last found cell for the same corner, or the next, before a binary search).
  int cell_at(const BoxGeometry& box, const std::array<long, 3>& ijk, int a) const {
    long q[3];
    for (int d = 0; d < 3; ++d) {
      q[d] = ijk[d] - (a >> d & 1);
      if (q[d] < 0 || q[d] > box.n[d] - 2) return -1;
    }
    const std::int64_t id = box.id(q[0], q[1], q[2]);
    int& h = rest_hint_[a];
    if (h + 1 < cells_ && m_.id[base_[h + 1]] == id) return ++h;
    if (h < cells_ && m_.id[base_[h]] == id) return h;
    int lo = 0, hi = cells_;
    while (lo < hi) {
      const int mid = (lo + hi) / 2;
      if (m_.id[base_[mid]] < id) lo = mid + 1;
      else hi = mid;
    }
    if (lo == cells_ || m_.id[base_[lo]] != id) return -1;
    return h = lo;
  }
  // The stencil slot (0..26, 13 the row's own) of corner b of a cell whose corner a is the row's molecule.
  static constexpr std::array<std::array<std::uint8_t, 8>, 8> kCornerSlot = [] {
    std::array<std::array<std::uint8_t, 8>, 8> t{};
    for (int a = 0; a < 8; ++a)
      for (int b = 0; b < 8; ++b)
        t[a][b] = static_cast<std::uint8_t>(13 + ((b & 1) - (a & 1)) + 3 * ((b >> 1 & 1) - (a >> 1 & 1)) + 9 * ((b >> 2 & 1) - (a >> 2 & 1)));
    return t;
  }();
  // add_row's sums at rest from rest_blocks_; key: the kind of each cell (a = 7 .. 0, -1 none).
  template <class Emit>
  void rest_row_blocks(int i, Emit emit, double* key) const {
    const int body = m_.body[i];
    if (!rest_body_[body]) return;
    const BoxGeometry& box = m_.shape.body(body);
    const auto ijk = box.index(m_.id[i]);
    for (int a = 7; a >= 0; --a) {
      const int k = cell_at(box, ijk, a);
      if (key) key[7 - a] = k < 0 ? -1.0 : kind_[k];
      if (k >= 0) emit(a, k);
    }
  }
  void rest_row(int i, std::vector<int>& columns, std::vector<double>& key) const override {
    const std::size_t at = key.size();
    key.resize(at + 8, -1.0);
    std::uint32_t present = 0;
    int column[27];
    rest_row_blocks(i, [&](int a, int k) {
      int corner[8];
      corners(k, corner);
      for (int b = 0; b < 8; ++b) {
        const int slot = kCornerSlot[a][b];
        column[slot] = corner[b], present |= 1u << slot;
      }
    }, key.data() + at);
    for (std::uint32_t rest = present; rest; rest &= rest - 1) columns.push_back(column[__builtin_ctz(rest)]);
  }
  PetscErrorCode add_rest_row(int i, BlockAdd add, void* ctx) const override {
    double K[27][9];
    int column[27];
    std::uint32_t present = 0;
    rest_row_blocks(i, [&](int a, int k) {
      int corner[8];
      corners(k, corner);
      const double* Kb = &rest_blocks_[(static_cast<std::size_t>(kind_[k]) * 8 + a) * 72];
      for (int b = 0; b < 8; ++b) {  // as add_row
        const int slot = kCornerSlot[a][b];
        double* to = K[slot];
        if (present >> slot & 1) {
          for (int e = 0; e < 9; ++e) to[e] += Kb[9 * b + e];
        } else {
          for (int e = 0; e < 9; ++e) to[e] = Kb[9 * b + e];
          column[slot] = corner[b], present |= 1u << slot;
        }
      }
    }, nullptr);
    for (std::uint32_t rest = present; rest; rest &= rest - 1) {
      const int slot = __builtin_ctz(rest);
      const PetscErrorCode ierr = add(ctx, i, column[slot], K[slot]);
      if (ierr) return ierr;
    }
    return 0;
  }
  mutable bool rest_checked_ = false, rest_ok_ = false;
  mutable std::vector<std::uint8_t> rest_body_;  // per body: whether it has cells here
  mutable std::vector<double> rest_blocks_;      // per kind and corner a: K_ab at rest, b = 0..7
  mutable std::array<int, 8> rest_hint_{};

  // The matrix-free product (cell_block_tangent), from a state per cell kept for a Newton iteration: plain cells
  // in blocks (no fibres, no history running) F and mu J^(-2/3), 80 B a cell, the derivative of the stress along
  // dF in closed form on every product; otherwise dP/dF from the dual numbers, 648 B a cell (add_tangent's blocks:
  // 27 a molecule, 1,944 B). The state goes by the force's blocks, the block's cells as vector lanes (cell k of
  // the block from `first` with n cells at w first + c n + k - first, w values a cell); without blocks (fibres)
  // one cell at a time.
  bool has_tangent_state() const override { return true; }
  // Every cell volumetric-only (mu = 0, no virtual diagonals) and in blocks: the product needs no state but the
  // positions (tangent_state).
  bool volumetric() const {
    return !blocks_.empty() && plain() && std::all_of(kinds_.begin(), kinds_.end(), [](const Kind& k) {
      return k.moduli.mu == 0 && k.moduli.alpha[0] == 0 && k.moduli.alpha[1] == 0 && k.moduli.alpha[2] == 0;
    });
  }
  // Volumetric-only cell k's diagonal (add_row's closed form): K_aa[i][i] = V0 W'' (cof F g_a)_i^2, the skew
  // part's diagonal being zero; W'' = kappa/2 (1 + 1/J^2). F = I for an inverted cell (the state's).
  void add_volumetric_diagonal(int k, double F[9], double* diag) const {
    if (!(F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) + F[2] * (F[3] * F[7] - F[4] * F[6]) > 0))
      for (int q = 0; q < 9; ++q) F[q] = q % 4 == 0 ? 1.0 : 0.0;
    const double cof[9] = {F[4] * F[8] - F[5] * F[7], F[5] * F[6] - F[3] * F[8], F[3] * F[7] - F[4] * F[6],
                           F[2] * F[7] - F[1] * F[8], F[0] * F[8] - F[2] * F[6], F[1] * F[6] - F[0] * F[7],
                           F[1] * F[5] - F[2] * F[4], F[2] * F[3] - F[0] * F[5], F[0] * F[4] - F[1] * F[3]};
    const double J = F[0] * cof[0] + F[1] * cof[1] + F[2] * cof[2], rJ = 1.0 / J;
    const Geometry& geo = geometry_[kinds_[kind_[k]].body];
    const double w2 = geo.volume * (0.5 * kinds_[kind_[k]].moduli.kappa * (1.0 + rJ * rJ));
    int corner[8];
    corners(k, corner);
    for (int a = 0; a < 8; ++a) {
      if (corner[a] >= m_.owned) continue;
      const double* g = geo.g[a];
      for (int i = 0; i < 3; ++i) {
        const double ca = cof[3 * i] * g[0] + cof[3 * i + 1] * g[1] + cof[3 * i + 2] * g[2];
        diag[3 * corner[a] + i] += w2 * (ca * ca);
      }
    }
  }
  bool tangent_state_fast() const override { return state_width() == 10; }
  // state[0]: the width w it was made with (a history may start between the state and a product: begin_step).
  // Volumetric-only cells (volumetric()) keep nothing (width 0, or -1 at the rest positions): each product
  // recomputes F from the positions the state was made at (volumetric_block_tangent).
  std::size_t tangent_state_size() const override {
    return 1 + (volumetric() ? 0 : state_width() * static_cast<std::size_t>(cells_));
  }
  void tangent_state(const double* x, double* state_with_width) const override {
    if (volumetric()) {
      // -1: x is the rest positions to the bit (the first Newton iterate of a solve from rest), so every product
      // at x takes the F = I form, the same numbers as the general one at F = I.
      const bool at_rest = x == m_.rest.data() || std::equal(m_.rest.begin(), m_.rest.end(), x);
      state_with_width[0] = at_rest ? -1 : 0;
      return;
    }
    const int w = state_width();
    state_with_width[0] = w;
    double* state = state_with_width + 1;
    for_each_state_block([&](int first, int n) {
      double* block = state + w * static_cast<std::size_t>(first);
      for (int i = 0; i < n; ++i) {
        const int k = first + i;
        double D[81];
        if (w == 10) {
          int corner[8];
          corners(k, corner);
          gradient(x, corner, geometry_[kinds_[kind_[k]].body], D);
          const double J = D[0] * (D[4] * D[8] - D[5] * D[7]) - D[1] * (D[3] * D[8] - D[5] * D[6]) +
                           D[2] * (D[3] * D[7] - D[4] * D[6]);
          D[9] = kinds_[kind_[k]].moduli.mu * std::pow(J, -2.0 / 3.0);  // stress()'s
          // Inverted: the residual is NaN already; F = I and no isochoric part keep the product finite.
          if (!(J > 0)) std::fill(D, D + 10, 0.0), D[0] = D[4] = D[8] = 1.0;
        } else if (!stress_tangent(k, x, D)) {
          std::fill(D, D + 81, 0.0);  // inverted (as above)
        }
        for (int c = 0; c < w; ++c) block[static_cast<std::size_t>(c) * n + i] = D[c];
      }
    });
  }
  void apply_tangent_state(const double* x, const double* state_with_width, const double* u,
                           double* out) const override {
    const int w = static_cast<int>(state_with_width[0]);
    const double* state = state_with_width + 1;
    if (!blocks_.empty()) {
      rest_rows_.reset();  // a new product: u's rows not yet split
      if (pulled(w, x)) {
        pull_reset();
        pull_below(u, m_.owned, 0, out);
        return;
      }
      for (const Block& b : blocks_) block_tangent(b, w, x, state, u, out);
      return;
    }
    for (int k = 0; k < cells_; ++k) {
      const Geometry& geo = geometry_[kinds_[kind_[k]].body];
      const double g[3] = {geo.g[1][0], geo.g[2][1], geo.g[4][2]};
      cell_block_tangent(1, base_.data() + k, patterns_[pattern_[k]].data(), false, u,
                         state + 81 * static_cast<std::size_t>(k), nullptr, geo.volume, g, m_.owned, out);
    }
  }
  // The same blocks in the same order, each once its owned corners' rows are final in the springs' sweep
  // (ForceModel::apply_tangent's final_rows): u, x and out come from the cache.
  bool tangent_by_rows() const override { return !blocks_.empty(); }
  int apply_tangent_state_below(const double* x, const double* state_with_width, const double* u, int below,
                                int from, double* out) const override {
    const int w = static_cast<int>(state_with_width[0]);
    const int nb = static_cast<int>(blocks_.size());
    if (from == 0) rest_rows_.reset();  // a product's first piece: u's rows not yet split
    if (pulled(w, x)) {  // pieces: the pull form's molecule rows
      if (from == 0) pull_reset();
      return pull_below(u, below, from, out);
    }
    for (; from < nb && blocks_[from].reach <= below; ++from) block_tangent(blocks_[from], w, x, state_with_width + 1, u, out);
    return from;
  }
  void add_tangent_state_diagonal(const double* x, const double* state_with_width, double* diag) const override {
    const int w = static_cast<int>(state_with_width[0]);
    const double* state = state_with_width + 1;
    if (w < 0) {
      // x is the rest positions to the bit (the finest level's rest tangent): F = I, so cof F = I, J = 1 and
      // add_volumetric_diagonal's terms are V0 kappa/2 (1 + 1) g_a,i^2, the same doubles without x, F or cof.
      for (int k = 0; k < cells_; ++k) {
        int corner[8];
        corners(k, corner);
        const Geometry& geo = geometry_[kinds_[kind_[k]].body];
        const double w2 = geo.volume * (0.5 * kinds_[kind_[k]].moduli.kappa * (1.0 + 1.0));
        for (int a = 0; a < 8; ++a) {
          if (corner[a] >= m_.owned) continue;
          const double* g = geo.g[a];
          for (int i = 0; i < 3; ++i) diag[3 * corner[a] + i] += w2 * (g[i] * g[i]);
        }
      }
      return;
    }
    if (w == 0) {
      // F from the displacements x - X with the product's arithmetic (corner_gradient), then the closed form below.
      for (int k = 0; k < cells_; ++k) {
        int corner[8];
        corners(k, corner);
        const Geometry& geo = geometry_[kinds_[kind_[k]].body];
        double F[9];
        for (int d = 0; d < 3; ++d) {
          double v[8];
          for (int c = 0; c < 8; ++c) v[c] = x[3 * corner[c] + d] - m_.rest[3 * corner[c] + d];
          corner_gradient(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], geo.g[1][0], geo.g[2][1], geo.g[4][2],
                          F[3 * d], F[3 * d + 1], F[3 * d + 2]);
        }
        for (int q = 0; q < 9; q += 4) F[q] += 1.0;
        add_volumetric_diagonal(k, F, diag);
      }
      return;
    }
    for_each_state_block([&](int first, int n) {
      const double* block = state + w * static_cast<std::size_t>(first);
      // The entries of dP/dF read below, Dd[3p + j] = dP_(3i + j) / dF_p (i = p / 3): from the closed form over
      // the block's cells as lanes (plain cells; once per Newton iteration, not per product), else the state's.
      const Moduli& moduli = kinds_[kind_[first]].moduli;
      if (w == 10 && moduli.mu == 0 && moduli.alpha[0] == 0 && moduli.alpha[1] == 0 && moduli.alpha[2] == 0) {
        // Volumetric-only cells (add_row's closed form): K_aa[i][i] = V0 W'' (cof F g_a)_i^2, the skew part's
        // diagonal being zero; W'' = kappa/2 (1 + 1/J^2).
        const std::size_t sn = static_cast<std::size_t>(n);
        for (int k = first; k < first + n; ++k) {
          const std::size_t c = static_cast<std::size_t>(k - first);
          double F[9];
          for (int q = 0; q < 9; ++q) F[q] = block[q * sn + c];
          add_volumetric_diagonal(k, F, diag);
        }
        return;
      }
      alignas(64) double Dd[27][kCellBlock];
      if (w == 10) plain_block_diagonal_tangent(n, block, &moduli, Dd);
      for (int k = first; k < first + n; ++k) {
        int corner[8];
        corners(k, corner);
        const Geometry& geo = geometry_[kinds_[kind_[k]].body];
        double D[27];
        for (int p = 0; p < 9; ++p)
          for (int j = 0; j < 3; ++j)
            D[3 * p + j] = w == 10 ? Dd[3 * p + j][k - first]
                                   : block[static_cast<std::size_t>(9 * p + 3 * (p / 3) + j) * n + (k - first)];
        for (int a = 0; a < 8; ++a) {
          if (corner[a] >= m_.owned) continue;
          const double* g = geo.g[a];
          for (int i = 0; i < 3; ++i) {
            // K_aa[i][i] = V0 sum_jl dP_ij/dF_il g_a[j] g_a[l]
            double K = 0;
            for (int l = 0; l < 3; ++l)
              K += (D[3 * (3 * i + l)] * g[0] + D[3 * (3 * i + l) + 1] * g[1] + D[3 * (3 * i + l) + 2] * g[2]) * g[l];
            diag[3 * corner[a] + i] += geo.volume * K;
          }
        }
      }
    });
  }

  void add_couplings(std::vector<std::vector<int>>& extra) const override {
    for (int k = 0; k < cells_; ++k) {
      int corner[8];
      corners(k, corner);
      for (int a = 0; a < 8; ++a)
        if (corner[a] < m_.owned)
          for (int b = 0; b < 8; ++b) extra[corner[a]].push_back(corner[b]);
    }
  }

  double critical_time_step() const override { return dt_; }

  void add_force_scale(const double* x, std::vector<double>& scale, std::vector<double>& squares) const override {
    // A corner's force at unit strain: V0 |g| times the cell's moduli; from positions, that times R |g| / 2
    // (Term::add_force_scale).
    for (int k = 0; k < cells_; ++k) {
      const Moduli& md = kinds_[kind_[k]].moduli;
      const Geometry& geo = geometry_[kinds_[kind_[k]].body];
      double modulus = md.kappa + 2 * md.mu + 2 * (md.alpha[0] + md.alpha[1] + md.alpha[2]);
      for (int q = 0; q < fibre_count(k); ++q)
        modulus += std::abs(fibres(k)[q].E_f) + 2 * std::abs(fibres(k)[q].dG) + 2 * std::abs(fibres(k)[q].alpha);
      int corner[8];
      corners(k, corner);
      double R = 0;
      for (int a = 0; a < 8; ++a)
        for (int d = 0; d < 3; ++d) R = std::max(R, std::fabs(x[3 * corner[a] + d]));
      for (int a = 0; a < 8; ++a) {
        const double* g = geo.g[a];
        const double norm = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        const double unit = geo.volume * modulus * norm, positions = unit * R * norm / 2;
        scale[corner[a]] += unit, squares[corner[a]] += positions * positions;
      }
    }
  }

  bool has_history() const override { return history_cells_ > 0; }

  void begin_step(double dt) override {
    if (history_cells_ == 0) return;
    active_ = stepping_ = true;
    for (std::size_t j = 0; j < gamma_.size(); ++j) {
      const double r = dt / tau_[j];
      decay_[j] = std::exp(-r);
      weight_[j] = gamma_[j] * (r > 0 ? -std::expm1(-r) / r : 1.0);  // gamma beta, as the springs' history
    }
  }

  void commit_step(const double* x) override {
    if (!active_) return;
    for (int k = 0; k < cells_; ++k) {
      const int c = history_[k];
      if (c < 0) continue;
      double F[9], S[9];
      int corner[8];
      corners(k, corner);
      gradient(x, corner, geometry_[kinds_[kind_[k]].body], F);
      if (!cell_pk2(F, kinds_[kind_[k]].moduli, fibres(k), fibre_count(k), S)) continue;
      const double* w = weight_.data() + table(k, c) * width_;
      const double* e = decay_.data() + table(k, c) * width_;
      double* so = &s_old_[9 * static_cast<std::size_t>(c)];
      for (int i = 0; i < width_; ++i) {
        double* h = &h_[(static_cast<std::size_t>(c) * width_ + i) * 9];
        for (int q = 0; q < 9; ++q) h[q] = e[i] * h[q] + w[i] * (S[q] - so[q]);
      }
      for (int q = 0; q < 9; ++q) so[q] = S[q];
    }
    stepping_ = false;
  }

  // Checkpoints: per cell its committed S (9 values), then h per Prony term (9 each); cells of a body without a
  // Prony series write zeros. Every rank holding a cell computed the same values, so any one may write it.
  int cell_history_width() const override { return width_ > 0 ? 9 * (1 + width_) : 0; }
  std::int64_t cell_history_count() const override { return width_ > 0 ? global_cells_ : 0; }
  void save_cell_history(std::vector<std::int64_t>& ids, std::vector<double>& rows) const override {
    const int w = cell_history_width();
    ids.clear(), rows.clear();
    for (int k = 0; k < cells_; ++k) {
      if (!owns_energy_[k]) continue;
      ids.push_back(cell_id_[k]);
      const std::size_t at = rows.size();
      rows.resize(at + w, 0.0);
      if (!history_.empty() && history_[k] >= 0) history_row(k, rows.data() + at);
    }
  }
  std::vector<std::int64_t> cell_history_ids() const override {
    return width_ > 0 ? cell_id_ : std::vector<std::int64_t>{};
  }
  void load_cell_history(const double* rows) override {
    const int w = cell_history_width();
    for (int k = 0; k < cells_; ++k)
      if (!history_.empty() && history_[k] >= 0) set_history_row(k, rows + static_cast<std::size_t>(k) * w);
    // Committed and frozen, as the run that wrote them left them between two steps (a zero history adds zero).
    active_ = history_cells_ > 0, stepping_ = false;
  }

  bool fibre_field(const double* x, double* direction, double* stretch) const override {
    if (fibre_begin_.empty()) return false;
    std::vector<int> count(m_.owned, 0);
    std::fill(direction, direction + 3 * m_.owned, 0.0);
    std::fill(stretch, stretch + m_.owned, 0.0);
    for (int k = 0; k < cells_; ++k) {
      if (fibre_count(k) == 0) continue;
      double F[9], Fa[3];
      int corner[8];
      corners(k, corner);
      gradient(x, corner, geometry_[kinds_[kind_[k]].body], F);
      const double l = fibre_stretch(F, fibres(k), fibre_count(k), Fa);
      for (int c = 0; c < 8; ++c) {
        const int i = corner[c];
        if (i >= m_.owned) continue;
        for (int d = 0; d < 3; ++d) direction[3 * i + d] += Fa[d] / l;
        stretch[i] += l;
        ++count[i];
      }
    }
    for (int i = 0; i < m_.owned; ++i) {
      if (count[i] == 0) continue;
      stretch[i] /= count[i];
      const double* d = direction + 3 * i;
      const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      for (int j = 0; j < 3; ++j) direction[3 * i + j] /= n > 0 ? n : 1.0;
    }
    return true;
  }

  void cells(const double* x, CellField& out) const override {
    out.nodes = 8;
    out.global_count = global_cells_;
    // XDMF/VTK hexahedron order: the bottom face counter-clockwise, then the top face.
    static const int order[8] = {0, 1, 3, 2, 4, 5, 7, 6};
    for (int k = 0; k < cells_; ++k) {
      if (!owns_energy_[k]) continue;  // each cell once: on the rank owning its lowest corner
      int corner[8];
      corners(k, corner);
      double F[9];
      gradient(x, corner, geometry_[kinds_[kind_[k]].body], F);
      out.id.push_back(cell_id_[k]);
      for (int c : order) out.corners.push_back(m_.id[corner[c]]);
      out.volume_ratio.push_back(F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
                                 F[2] * (F[3] * F[7] - F[4] * F[6]));
      double Fa[3];
      out.fibre_stretch.push_back(fibre_begin_.empty() ? 0.0 : fibre_stretch(F, fibres(k), fibre_count(k), Fa));
    }
  }

private:
  // Quasi-linear viscoelasticity: P += F H, H = sum_i h_i the Prony histories of the cell's stress S,
  //   h_i <- exp(-dt/tau_i) h_i + gamma_i beta_i (S(n+1) - S(n))
  // (the springs' exact exponential update, src/physics/terms/viscoelastic.cpp); within a step H follows x (the
  // tangent is exact through the same dual numbers), outside one it is frozen. False when J <= 0.
  template <class T>
  bool add_history(const T F[9], int k, T P[9]) const {
    if (!active_ || history_.empty() || history_[k] < 0) return true;
    const std::size_t c = static_cast<std::size_t>(history_[k]);
    T H[9];
    for (int q = 0; q < 9; ++q) H[q] = T(0.0);
    if (stepping_) {
      T S[9];
      if (!cell_pk2(F, kinds_[kind_[k]].moduli, fibres(k), fibre_count(k), S)) return false;
      const double* w = weight_.data() + table(k, c) * width_;
      const double* e = decay_.data() + table(k, c) * width_;
      for (int i = 0; i < width_; ++i)
        for (int q = 0; q < 9; ++q)
          H[q] = H[q] + T(e[i] * h_[(c * width_ + i) * 9 + q]) + T(w[i]) * (S[q] - T(s_old_[9 * c + q]));
    } else {
      for (int i = 0; i < width_; ++i)
        for (int q = 0; q < 9; ++q) H[q] = H[q] + T(h_[(c * width_ + i) * 9 + q]);
    }
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        P[3 * i + j] = P[3 * i + j] + F[3 * i] * H[j] + F[3 * i + 1] * H[3 + j] + F[3 * i + 2] * H[6 + j];
    return true;
  }

  // The Prony table of cell k (history slot c): its region's, else its body's.
  int table(int k, std::size_t c) const { return table_.empty() ? kinds_[kind_[k]].body : table_[c]; }

  // Cell k's corner forces added to f (owned corners): g_a = (s_x / 4h_x, s_y / 4h_y, s_z / 4h_z) is used through
  // its signs, so F is sums of corner differences along each axis and a corner's force is a signed sum of
  // Q = V0 P / (4 h)'s columns (about 3x fewer operations than the general products; gradient() and the tangent
  // keep them). cell_block_forces does the same operations in the same order.
  void cell_forces(int k, const double* x, double* f) const {
    const double* X = m_.rest.data();
    int corner[8];
    corners(k, corner);
    const Kind& kind = kinds_[kind_[k]];
    const Geometry& geo = geometry_[kind.body];
    double u[8][3];
    for (int c = 0; c < 8; ++c) {
      const int j = 3 * corner[c];
      u[c][0] = x[j] - X[j], u[c][1] = x[j + 1] - X[j + 1], u[c][2] = x[j + 2] - X[j + 2];
    }
    double F[9], P[9];
    for (int i = 0; i < 3; ++i) {
      F[3 * i] = ((u[1][i] - u[0][i]) + (u[3][i] - u[2][i]) + (u[5][i] - u[4][i]) + (u[7][i] - u[6][i])) * geo.g[1][0];
      F[3 * i + 1] = ((u[2][i] - u[0][i]) + (u[3][i] - u[1][i]) + (u[6][i] - u[4][i]) + (u[7][i] - u[5][i])) * geo.g[2][1];
      F[3 * i + 2] = ((u[4][i] - u[0][i]) + (u[5][i] - u[1][i]) + (u[6][i] - u[2][i]) + (u[7][i] - u[3][i])) * geo.g[4][2];
    }
    F[0] += 1.0, F[4] += 1.0, F[8] += 1.0;
    if (!stress(F, kind.moduli, fibres(k), fibre_count(k), P) || !add_history(F, k, P)) {
      // An inverted cell: its energy is infinite; NaN forces make every solver's guard stop or cut back.
      for (int c = 0; c < 8; ++c)
        if (corner[c] < m_.owned)
          for (int i = 0; i < 3; ++i) f[3 * corner[c] + i] = std::numeric_limits<double>::quiet_NaN();
      return;
    }
    for (int i = 0; i < 3; ++i) {
      // corner c's force f_c[i] = -V0 sum_j P_ij g_c[j] = -(s_x q0 + s_y q1 + s_z q2)
      const double q0 = geo.volume * P[3 * i] * geo.g[1][0], q1 = geo.volume * P[3 * i + 1] * geo.g[2][1],
                   q2 = geo.volume * P[3 * i + 2] * geo.g[4][2];
      const double lo = q0 + q1, hi = q1 - q0;  // corners (-x, -y) and (+x, -y); their opposites negate them
      const double add[8] = {lo + q2, hi + q2, -hi + q2, -lo + q2, lo - q2, hi - q2, -hi - q2, -lo - q2};
      for (int c = 0; c < 8; ++c)
        if (corner[c] < m_.owned) f[3 * corner[c] + i] += add[c];
    }
  }

  // The tangent state's values a cell: F and mu J^(-2/3) for plain cells in blocks, else dP/dF.
  int state_width() const { return !blocks_.empty() && plain() ? 10 : 81; }

  // The tangent state's blocks (first cell, cells): the force's blocks, or one cell each without them (fibres).
  template <class Visit>
  void for_each_state_block(Visit visit) const {
    if (!blocks_.empty())
      for (const Block& b : blocks_) visit(b.first, b.n);
    else
      for (int k = 0; k < cells_; ++k) visit(k, 1);
  }

  // Without fibres and a running history the cells go in blocks (cell_block_forces).
  bool plain() const { return fibre_begin_.empty() && (history_.empty() || !active_); }

  // A block: cells [first, first + n) of one moduli and corner pattern, as a lattice row (rows) or gathered;
  // reach: 1 + its highest owned corner (the force model runs it once the rows below that are final).
  // kind, pattern: its cells' (kind_, pattern_); ijk: a row block's corner 0's lattice index (row_rest). Kept here
  // so that a product or force pass over the blocks reads no per-cell array and no molecule id (a cache miss a
  // block at 10^6 molecules).
  // base0: the block's first cell's base_ (a row block's products and forces read no other: base_ itself, 4 B a
  // cell, is out of the cache after a product's vectors stream by, and its one line a block missed at 10^6).
  struct Block {
    int first, n, reach, base0;
    bool rows;
    int kind, pattern;
    std::array<long, 3> ijk;
  };
  std::vector<Block> blocks_;  // in cell order; empty with fibres (no block ever runs then)
  mutable RestRows rest_rows_;  // the rest form's split rows within one product (volumetric_block_tangent)

  // The rest form's pull by molecule rows (at rest, every block a row block): where each block added its Q to its
  // four corner rows of out (four read-modify-write passes a molecule, at four times), each molecule row of out
  // is read and written once, taking the Q of its (up to four) cell rows from a ring of the last plane of cell
  // rows' Q, in the cell rows' order: the push form's terms in its order, so the same bits.
  // A cell row: consecutive row blocks that continue each other along x (cells [first_cell, + cells)).
  struct CellRow {
    int first_block, blocks, first_cell, cells;
    int q_at;  // its Q's offset in pull_ring_
  };
  // A molecule row: molecules [start, start + cells + 1), corner row r[e] of cell row cell_row[e], e < count.
  struct PullRow {
    int start, cells, count;
    int cell_row[4], r[4];
    int q_at[4];  // their Q's offsets in pull_ring_
  };
  mutable std::vector<CellRow> cell_rows_;
  mutable std::vector<PullRow> pull_rows_;     // those with an owned molecule, by start; empty: the push form
  mutable std::vector<char> row_needed_;       // per cell row: some pull row reads it
  mutable int ring_rows_ = 0, ring_stride_ = 0;  // the ring's cell rows (slot c % ring_rows_), 3 x its longest row
  mutable std::vector<double> pull_ring_;
  mutable int pull_computed_ = 0;  // this product's cell rows [0, pull_computed_) are in the ring
  // The molecule rows the needed cell rows read (ghosts' too), split into x, y, z once a product: numbered by
  // first use (run_start_: first molecule), per cell row its four (run_of_), in a ring of split_rows_ slots
  // (3 (cells + 1) doubles each); split_holds_: the run a slot holds in this product (-1: none). 0 slots: each
  // block splits its rows itself (RestRows).
  mutable std::vector<int> run_of_, run_at_, run_start_;  // run_at_: run_of_'s slot
  mutable int split_rows_ = 0, split_stride_ = 0;
  mutable std::vector<double> split_ring_;
  mutable std::vector<int> split_holds_;
  void pull_reset() const {
    pull_computed_ = 0;
    std::fill(split_holds_.begin(), split_holds_.end(), -1);
  }

  // The rest form with every block a row block (w < 0: the rest state; w = 0 at the rest array itself).
  bool pulled(int w, const double* x) const {
    if (!(w < 0 || (w == 0 && x == m_.rest.data()))) return false;
    if (!pull_made_) make_pull(), pull_made_ = true;
    return !pull_rows_.empty();
  }
  // The pull form's arrays are made at the first rest product, not with the term: among the set-up's arrays they
  // raised the 10^6 static solve's peak by 12 MB (docs/benchmarks.md), after it by nothing.
  mutable bool pull_made_ = false;
  bool pull_on_ = true;  // -static_cell_pull, read with the term
  // The cell rows up to c (those needed) into the ring, in order (RestRows' split rows carried block to block).
  void pull_cells_to(const double* u, int c) const {
    for (; pull_computed_ <= c; ++pull_computed_) {
      if (!row_needed_[pull_computed_]) continue;
      const CellRow& row = cell_rows_[pull_computed_];
      double* slot = pull_ring_.data() + row.q_at;
      if (split_rows_ > 0) {
        // Its four molecule rows from the split ring, each split at its first use in this product.
        const double *xs[4], *ys[4], *zs[4];
        const std::size_t len = static_cast<std::size_t>(row.cells) + 1;
        for (int r = 0; r < 4; ++r) {
          const std::size_t q = 4 * static_cast<std::size_t>(pull_computed_) + r;
          const int id = run_of_[q], at = run_at_[q];
          double* x = split_ring_.data() + static_cast<std::size_t>(at) * split_stride_;
          if (split_holds_[at] != id) {
            split_molecule_row(u + 3 * static_cast<std::size_t>(run_start_[id]), row.cells, x, x + len, x + 2 * len);
            split_holds_[at] = id;
          }
          xs[r] = x, ys[r] = x + len, zs[r] = x + 2 * len;
        }
        for (int q = row.first_block; q < row.first_block + row.blocks; ++q) {
          const Block& b = blocks_[q];
          const Kind& kind = kinds_[b.kind];
          const Geometry& geo = geometry_[kind.body];
          const double g[3] = {geo.g[1][0], geo.g[2][1], geo.g[4][2]};
          const int o = b.first - row.first_cell;
          const double* bx[4] = {xs[0] + o, xs[1] + o, xs[2] + o, xs[3] + o};
          const double* by[4] = {ys[0] + o, ys[1] + o, ys[2] + o, ys[3] + o};
          const double* bz[4] = {zs[0] + o, zs[1] + o, zs[2] + o, zs[3] + o};
          rest_split_block_q(b.n, bx, by, bz, kind.moduli.kappa, geo.volume, g, slot + 3 * o);
        }
        continue;
      }
      for (int q = row.first_block; q < row.first_block + row.blocks; ++q) {
        const Block& b = blocks_[q];
        const Kind& kind = kinds_[b.kind];
        const Geometry& geo = geometry_[kind.body];
        const double g[3] = {geo.g[1][0], geo.g[2][1], geo.g[4][2]};
        rest_block_q(b.n, &b.base0, patterns_[b.pattern].data(), u, kind.moduli.kappa, geo.volume, g, &rest_rows_,
                     slot + 3 * (b.first - row.first_cell));
      }
    }
  }
  // Molecule rows [from, ...) whose owned molecules are all below `below`; the next one.
  int pull_below(const double* u, int below, int from, double* out) const {
    const int nr = static_cast<int>(pull_rows_.size()), owned = m_.owned;
    for (; from < nr; ++from) {
      const PullRow& p = pull_rows_[from];
      const int touched = std::min(p.cells + 1, owned - p.start);
      if (p.start + touched > below) break;
      pull_cells_to(u, p.cell_row[p.count - 1]);
      const double* Q[4];
      for (int e = 0; e < p.count; ++e) Q[e] = pull_ring_.data() + p.q_at[e];
      pull_row_at_rest(Q, p.r, p.count, p.cells, touched, out + 3 * static_cast<std::size_t>(p.start));
    }
    return from;
  }
  // The split ring's runs and size, by the cell rows' order of computation (the needed ones); none where a
  // molecule row is read with two lengths.
  void make_split_ring() const {
    std::map<int, int> id_of;
    std::vector<int> run_of(4 * cell_rows_.size(), -1), start, length;
    int newest = -1, ring = 1;
    std::size_t longest = 0;
    for (int c = 0; c < static_cast<int>(cell_rows_.size()); ++c) {
      if (!row_needed_[c]) continue;
      const CellRow& row = cell_rows_[c];
      const Block& b = blocks_[row.first_block];
      const int* p = patterns_[b.pattern].data();
      int oldest = newest + 1;
      for (int r = 0; r < 4; ++r) {
        const int first = b.base0 + p[2 * r];
        auto found = id_of.emplace(first, static_cast<int>(start.size()));
        if (found.second) start.push_back(first), length.push_back(row.cells);
        const int id = found.first->second;
        if (length[id] != row.cells) return;
        run_of[4 * static_cast<std::size_t>(c) + r] = id;
        newest = std::max(newest, id), oldest = std::min(oldest, id);
      }
      ring = std::max(ring, newest - oldest + 1);
      longest = std::max<std::size_t>(longest, row.cells + 1);
    }
    const std::size_t doubles = static_cast<std::size_t>(ring) * 3 * longest;
    if (doubles > (std::size_t{1} << 22)) return;
    run_at_.resize(run_of.size());
    for (std::size_t q = 0; q < run_of.size(); ++q) run_at_[q] = run_of[q] < 0 ? -1 : run_of[q] % ring;
    run_of_ = std::move(run_of), run_start_ = std::move(start);
    split_rows_ = ring, split_stride_ = static_cast<int>(3 * longest);
    split_ring_.assign(doubles, 0.0);
    split_holds_.assign(ring, -1);
  }
  // The pull form's rows, where every block is a row block and the molecule rows are disjoint (each molecule in
  // one, from the same cell rows as in the push form); otherwise (gathered blocks: a row's last cells, a rank's
  // edge) pull_rows_ stays empty and the push form runs. -static_cell_pull false: the push form always.
  void make_pull() const {
    if (!pull_on_ || blocks_.empty()) return;
    for (const Block& b : blocks_)
      if (!b.rows) return;
    std::vector<CellRow> rows;
    for (int q = 0; q < static_cast<int>(blocks_.size()); ++q) {
      const Block& b = blocks_[q];
      if (!rows.empty()) {
        CellRow& last = rows.back();
        const Block& prev = blocks_[q - 1];
        if (b.pattern == prev.pattern && b.first == prev.first + prev.n && b.base0 == prev.base0 + prev.n) {
          ++last.blocks, last.cells += b.n;
          continue;
        }
      }
      rows.push_back({q, 1, b.first, b.n, 0});
    }
    std::map<int, PullRow> by_start;
    for (int c = 0; c < static_cast<int>(rows.size()); ++c) {
      const int* p = patterns_[blocks_[rows[c].first_block].pattern].data();
      for (int r = 0; r < 4; ++r) {
        const int start = blocks_[rows[c].first_block].base0 + p[2 * r];
        if (start >= m_.owned) continue;
        auto found = by_start.emplace(start, PullRow{start, rows[c].cells, 0, {}, {}, {}});
        PullRow& row = found.first->second;
        if (row.cells != rows[c].cells || row.count == 4 || (row.count > 0 && row.cell_row[row.count - 1] == c))
          return;
        row.cell_row[row.count] = c, row.r[row.count] = r, ++row.count;
      }
    }
    std::vector<PullRow> pull;
    for (const auto& [start, row] : by_start) {
      if (!pull.empty() && pull.back().start + pull.back().cells + 1 > start) return;  // overlapping rows
      pull.push_back(row);
    }
    // The ring: when a row is pulled, the cell rows up to its last are computed; each of its cell rows must still
    // be in its slot (none R or more after it computed yet).
    int computed = -1, ring = 1, longest = 0;
    for (const PullRow& row : pull) {
      computed = std::max(computed, row.cell_row[row.count - 1]);
      ring = std::max(ring, computed - row.cell_row[0] + 1);
      longest = std::max(longest, row.cells);
    }
    const std::size_t doubles = static_cast<std::size_t>(ring) * 3 * static_cast<std::size_t>(longest);
    if (pull.empty() || doubles > (std::size_t{1} << 22)) return;
    row_needed_.assign(rows.size(), 0);
    for (const PullRow& row : pull)
      for (int e = 0; e < row.count; ++e) row_needed_[row.cell_row[e]] = 1;
    for (int c = 0; c < static_cast<int>(rows.size()); ++c) rows[c].q_at = (c % ring) * 3 * longest;
    for (PullRow& row : pull)
      for (int e = 0; e < row.count; ++e) row.q_at[e] = rows[row.cell_row[e]].q_at;
    cell_rows_ = std::move(rows), pull_rows_ = std::move(pull);
    ring_rows_ = ring, ring_stride_ = 3 * longest;
    pull_ring_.assign(doubles, 0.0);
    make_split_ring();
    // Inside a product (no error code to return): a failure aborts every rank.
    PetscCallAbort(PETSC_COMM_SELF, PetscInfo(nullptr, "cell term: the rest rows pulled, %zu molecule rows, %zu cell "
                                              "rows, a ring of %d\n", pull_rows_.size(), cell_rows_.size(), ring_rows_));
  }
  // add_tangent's ring of dP/dF: the most cells between a molecule's first and last cell (ids x-fastest).
  std::size_t ring_ = 1;

  // Greedy from each cell: up to kCellBlock cells that share their moduli and corner pattern; cells consecutive
  // along x (at least 8, their four corner rows apart) are a row block, the rest gathered.
  void make_blocks() {
    for (int k = 0; k < cells_;) {
      int n = 1;
      while (n < kCellBlock && k + n < cells_ && kind_[k + n] == kind_[k] && pattern_[k + n] == pattern_[k]) ++n;
      const std::array<int, 8>& p = patterns_[pattern_[k]];
      int along = 1;  // cells consecutive along x from k
      while (along < n && base_[k + along] == base_[k] + along) ++along;
      bool rows = along >= 8 && p[1] == 1 && p[3] == p[2] + 1 && p[5] == p[4] + 1 && p[7] == p[6] + 1;
      for (int r = 0; rows && r < 4; ++r)  // the rows' molecules (along + 1 each) must not overlap
        for (int t = r + 1; t < 4; ++t) rows = rows && std::abs(p[2 * t] - p[2 * r]) > along;
      if (rows) n = along;  // short runs stay with the general gather
      int reach = 0;
      for (int i = k; i < k + n; ++i)
        for (int c = 0; c < 8; ++c)
          if (base_[i] + p[c] < m_.owned) reach = std::max(reach, base_[i] + p[c] + 1);
      const std::array<long, 3> ijk =
          rows ? m_.shape.body(kinds_[kind_[k]].body).index(m_.id[base_[k]]) : std::array<long, 3>{0, 0, 0};
      blocks_.push_back({k, n, reach, base_[k], rows, kind_[k], pattern_[k], ijk});
      k += n;
    }
    blocks_.shrink_to_fit();
    PetscBool on = PETSC_TRUE;
    if (PetscOptionsGetBool(nullptr, nullptr, "-static_cell_pull", &on, nullptr))
      throw InputError("PETSc options", "-static_cell_pull", "expects true or false");
    pull_on_ = on;
  }

  // Block b's product (state of width w: 0 volumetric-only, from x, -1 the same at the rest positions; 10 F and
  // mu J^(-2/3) a cell; 81 dP/dF).
  void block_tangent(const Block& b, int w, const double* x, const double* state, const double* u,
                     double* out) const {
    const Kind& kind = kinds_[b.kind];
    const Geometry& geo = geometry_[kind.body];
    const double g[3] = {geo.g[1][0], geo.g[2][1], geo.g[4][2]};
    const int* base = b.rows ? &b.base0 : base_.data() + b.first;  // a row block's kernels read base[0] only
    const int* pattern = patterns_[b.pattern].data();
    if (w <= 0) {
      RowRest rest;
      const bool computed = b.rows && lattice_rest_;
      if (computed) row_rest(b, rest);
      // x is the rest array itself for the rest tangent (MatrixFreeTangent at rest): F = I, the short form.
      volumetric_block_tangent(b.n, base, pattern, b.rows, computed ? &rest : nullptr, u, x, m_.rest.data(),
                               kind.moduli.kappa, geo.volume, g, m_.owned, out, w < 0 || x == m_.rest.data(),
                               &rest_rows_);
      return;
    }
    cell_block_tangent(b.n, base, pattern, b.rows, u, state + w * static_cast<std::size_t>(b.first),
                       w == 10 ? &kind.moduli : nullptr, geo.volume, g, m_.owned, out);
  }
  // A row block's lattice (its corner 0's index): the rest positions cell_block_forces computes.
  void row_rest(const Block& b, RowRest& rest) const {
    const BoxGeometry& box = m_.shape.body(kinds_[b.kind].body);
    for (int d = 0; d < 3; ++d) rest.offset[d] = box.offset[d], rest.h[d] = box.h[d], rest.ijk[d] = b.ijk[d];
  }

  void block_forces(const Block& b, const double* x, double* f) const {
    const int k = b.first;
    const Kind& kind = kinds_[b.kind];
    const Geometry& geo = geometry_[kind.body];
    const double g[3] = {geo.g[1][0], geo.g[2][1], geo.g[4][2]};
    RowRest rest;
    const bool computed = b.rows && lattice_rest_;
    if (computed) row_rest(b, rest);
    cell_block_forces(b.n, b.rows ? &b.base0 : base_.data() + k, patterns_[b.pattern].data(), b.rows,
                      computed ? &rest : nullptr, x, m_.rest.data(), kind.moduli, geo.volume, g, m_.owned, f);
  }

  // Cells whose law is its volumetric part alone, W = kappa/4 (J^2 - 1 - 2 ln J) (mu_c = 0, no virtual diagonals,
  // no fibres, no history running: cubic cells at nu > 1/4): their tangent blocks in closed form from F, cof F,
  // W' = kappa/2 (J - 1/J) and W'' = kappa/2 (1 + 1/J^2) (add_row) instead of dP/dF by nine dual-number stresses.
  bool volumetric_only(int k) const {
    const Moduli& m = kinds_[kind_[k]].moduli;
    return plain() && m.mu == 0 && m.alpha[0] == 0 && m.alpha[1] == 0 && m.alpha[2] == 0;
  }
  // Fills s[0..8] = F, s[9..17] = cof F, s[18] = W', s[19] = W'', s[20 + 3b + i] = (cof F g_b)_i (b = 0..7);
  // false when the cell is inverted.
  bool volumetric_state(int k, const double* x, double* s) const {
    int corner[8];
    corners(k, corner);
    double* F = s;
    gradient(x, corner, geometry_[kinds_[kind_[k]].body], F);
    double* cof = s + 9;
    cof[0] = F[4] * F[8] - F[5] * F[7], cof[1] = F[5] * F[6] - F[3] * F[8], cof[2] = F[3] * F[7] - F[4] * F[6];
    cof[3] = F[2] * F[7] - F[1] * F[8], cof[4] = F[0] * F[8] - F[2] * F[6], cof[5] = F[1] * F[6] - F[0] * F[7];
    cof[6] = F[1] * F[5] - F[2] * F[4], cof[7] = F[2] * F[3] - F[0] * F[5], cof[8] = F[0] * F[4] - F[1] * F[3];
    const double J = F[0] * cof[0] + F[1] * cof[1] + F[2] * cof[2];
    if (!(J > 0)) return false;
    const double half = 0.5 * kinds_[kind_[k]].moduli.kappa, rJ = 1.0 / J;
    s[18] = half * (J - rJ), s[19] = half * (1.0 + rJ * rJ);
    const Geometry& geo = geometry_[kinds_[kind_[k]].body];
    for (int b = 0; b < 8; ++b) {
      const double* gb = geo.g[b];
      for (int i = 0; i < 3; ++i) s[20 + 3 * b + i] = cof[3 * i] * gb[0] + cof[3 * i + 1] * gb[1] + cof[3 * i + 2] * gb[2];
    }
    return true;
  }

  // Cell k's dP/dF at x, D[9 kl + ij] = dP_ij / dF_kl, one direction kl at a time (dual numbers through stress()
  // and the history); false when the cell is inverted.
  bool stress_tangent(int k, const double* x, double* D) const {
    int corner[8];
    corners(k, corner);
    double F[9];
    gradient(x, corner, geometry_[kinds_[kind_[k]].body], F);
    for (int kl = 0; kl < 9; ++kl) {
      Dual Fd[9], Pd[9];
      for (int q = 0; q < 9; ++q) Fd[q] = Dual(F[q], q == kl ? 1.0 : 0.0);
      if (!stress(Fd, kinds_[kind_[k]].moduli, fibres(k), fibre_count(k), Pd) || !add_history(Fd, k, Pd)) return false;
      for (int q = 0; q < 9; ++q) D[9 * kl + q] = Pd[q].d;
    }
    return true;
  }

  // Cell k's row of a checkpoint: its committed S, then h per Prony term.
  void history_row(int k, double* row) const {
    const std::size_t c = static_cast<std::size_t>(history_[k]);
    std::copy_n(&s_old_[9 * c], 9, row);
    std::copy_n(&h_[9 * c * width_], 9 * width_, row + 9);
  }
  void set_history_row(int k, const double* row) {
    const std::size_t c = static_cast<std::size_t>(history_[k]);
    std::copy_n(row, 9, &s_old_[9 * c]);
    std::copy_n(row + 9, 9 * width_, &h_[9 * c * width_]);
  }

  struct Geometry {
    double volume = 0;
    double g[8][3];
    double cross[8][8][3];  // g_a x g_b (add_row's volumetric blocks)
  };
  // F = I + sum_a u_a (x) g_a, from displacements (positions far from the origin would cost digits of F - I).
  void gradient(const double* x, const int* corner, const Geometry& geo, double F[9]) const {
    double G[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    for (int c = 0; c < 8; ++c) {
      const double* xc = x + 3 * corner[c];
      const double* Xc = m_.rest.data() + 3 * corner[c];
      for (int i = 0; i < 3; ++i) {
        const double u = xc[i] - Xc[i];
        for (int j = 0; j < 3; ++j) G[3 * i + j] += u * geo.g[c][j];
      }
    }
    for (int q = 0; q < 9; ++q) F[q] = G[q] + (q % 4 == 0 ? 1.0 : 0.0);
  }

  // The fibre families of cell k: fibres_[fibre_begin_[k] .. fibre_begin_[k + 1]); both empty on a rank
  // without fibres (a body without fibres pays nothing).
  const Fibre* fibres(int k) const { return fibre_begin_.empty() ? nullptr : fibres_.data() + fibre_begin_[k]; }
  int fibre_count(int k) const { return fibre_begin_.empty() ? 0 : fibre_begin_[k + 1] - fibre_begin_[k]; }

  const LocalModel& m_;
  int cells_ = 0;
  std::vector<int> fibre_begin_;
  std::vector<Fibre> fibres_;
  // Viscoelastic cells only (all empty otherwise): history_[k] = the cell's history slot or -1.
  std::vector<int> history_;
  int history_cells_ = 0, width_ = 0;
  std::vector<std::uint16_t> table_;  // per history cell, only when some region has its own table
  std::vector<double> gamma_, tau_, decay_, weight_;  // per table (bodies, then regions with their own) and term
  std::vector<double> s_old_, h_;                     // per history cell: committed S (9), h per term (9 each)
  bool active_ = false, stepping_ = false;
  // A cell's 8 local corner indices (corner c = (c & 1, c >> 1 & 1, c >> 2 & 1)): base_ + patterns_[pattern_].
  std::vector<int> base_, pattern_;
  // Every corner's rest position is BoxGeometry::rest_position's double: the row blocks compute X, not read it.
  bool lattice_rest_ = true;
  std::vector<std::array<int, 8>> patterns_;
  void corners(int k, int corner[8]) const {
    const std::array<int, 8>& p = patterns_[pattern_[k]];
    for (int c = 0; c < 8; ++c) corner[c] = base_[k] + p[c];
  }
  struct Kind {
    Moduli moduli;
    int body = 0;
  };
  std::vector<Kind> kinds_;  // the distinct (moduli, body) of the cells
  std::vector<int> kind_;    // per cell: its index in kinds_
  std::vector<char> owns_energy_;
  std::vector<std::int64_t> cell_id_;  // dense global id per cell (snapshots)
  std::int64_t global_cells_ = 0;
  std::vector<Geometry> geometry_;
  double dt_ = std::numeric_limits<double>::infinity();
};

}  // namespace

std::unique_ptr<Term> make_cell_elasticity(const TermContext& c) {
  return std::make_unique<CellElasticity>(c.scene, c.model);
}

TISSUE_TERM(cell_elasticity, {"cell-elasticity", scene_has_cells, make_cell_elasticity,
                              "homogenized with poisson_ratio != 1/4 or flat cells: one energy per lattice cell of "
                              "its centre deformation gradient (docs/poisson.md)",
                              5, /*energy_never_grows=*/true, ContactReport::none, /*reads_velocity=*/false,
                              /*energy_line_search=*/true});

}  // namespace tissue
