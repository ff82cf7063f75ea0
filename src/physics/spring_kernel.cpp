#include "src/physics/spring_kernel.hpp"

#include "src/physics/rest_pull.hpp"
#include "src/vector_clones.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>

namespace tissue {

namespace {

// Each kernel is compiled for AVX-512, AVX2 and the baseline (TISSUE_CLONES, src/vector_clones.hpp), and the
// loader picks the best the CPU has: the square roots and divisions are the slow instructions, and wider vectors
// do more of them at once.

// Generic: connections [begin, end) of any list, sorted by end a. k comes through the type table ks when
// `ktype` is given, else per connection; l0 likewise through `ltype` and ls.
//
// Three passes over blocks of connections small enough to stay in L1: (1) gather the separation vectors and
// k, l0; (2) the square root and the division, a plain loop the compiler vectorizes; (3) scatter the forces. The
// force on end a is summed in registers over its run of connections and stored once. A block never splits a run
// of the same end a: where the runs end does not depend on the partition, where a block ends does, and a split
// run would sum the force on a in another grouping.
template <class Layout>
__attribute__((always_inline)) inline void generic_body(int begin_c, int end_c, const int* a, const int* b,
                                                        const std::uint16_t* ktype, const std::uint16_t* ltype,
                                                        const double* ks, const double* ls, const double* x,
                                                        double* f, Layout at) {
  constexpr int kBlock = 256;
  alignas(64) double d0[kBlock], d1[kBlock], d2[kBlock], k[kBlock], l0[kBlock], s[kBlock];
  for (int begin = begin_c, n = 0; begin < end_c; begin += n) {
    n = std::min(kBlock, end_c - begin);
    if (begin + n < end_c)
      while (n > 1 && a[begin + n] == a[begin + n - 1]) --n;
    for (int i = 0; i < n; ++i) {
      const int c = begin + i;
      const int ea = a[c], eb = b[c];
      d0[i] = x[at(eb, 0)] - x[at(ea, 0)], d1[i] = x[at(eb, 1)] - x[at(ea, 1)], d2[i] = x[at(eb, 2)] - x[at(ea, 2)];
      k[i] = ks[ktype ? ktype[c] : c];
      l0[i] = ls[ltype ? ltype[c] : c];
    }
    // Geometrically exact: the force acts along the current direction, k times the change of length.
    for (int i = 0; i < n; ++i) {
      const double len = std::sqrt(d0[i] * d0[i] + d1[i] * d1[i] + d2[i] * d2[i]);
      s[i] = k[i] * (len - l0[i]) / len;
    }
    int i = 0;
    while (i < n) {
      const int ia = a[begin + i];
      double fa0 = 0, fa1 = 0, fa2 = 0;
      for (; i < n && a[begin + i] == ia; ++i) {
        const double g0 = s[i] * d0[i], g1 = s[i] * d1[i], g2 = s[i] * d2[i];
        fa0 += g0, fa1 += g1, fa2 += g2;
        const int eb = b[begin + i];
        f[at.f(eb, 0)] -= g0, f[at.f(eb, 1)] -= g1, f[at.f(eb, 2)] -= g2;
      }
      f[at.f(ia, 0)] += fa0, f[at.f(ia, 1)] += fa1, f[at.f(ia, 2)] += fa2;
    }
  }
}

TISSUE_CLONES
void generic_forces_interlaced(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                               const std::uint16_t* ltype, const double* ks, const double* ls, const double* x,
                               double* f, Interlaced at) {
  generic_body(begin_c, end_c, a, b, ktype, ltype, ks, ls, x, f, at);
}
TISSUE_CLONES
void generic_forces_ring(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                         const std::uint16_t* ltype, const double* ks, const double* ls, const double* x, double* f,
                         RingStreams at) {
  generic_body(begin_c, end_c, a, b, ktype, ltype, ks, ls, x, f, at);
}
TISSUE_CLONES
void generic_forces_streams(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                            const std::uint16_t* ltype, const double* ks, const double* ls, const double* x,
                            double* f, Streams at) {
  generic_body(begin_c, end_c, a, b, ktype, ltype, ks, ls, x, f, at);
}

constexpr int kMaxDirections = 32, kStencilBlock = 64;
// The forces' blocks (stencil_body): each direction's loop runs over this many molecules, and the block's forces
// (g, 3 x 8 B a direction and molecule) stay in L1 for the own sums (docs/benchmarks.md: 128 against 64).
constexpr int kForceBlock = 128;
// With final_rows, the sweep goes in chunks of molecules so that a chunk's rows are handed over while still in
// cache (sweep()); the largest ring forces_ring uses (rows: 1.5 MB).
constexpr int kChunk = 8 * kForceBlock, kLargestRing = 1 << 16;
// The pull form's force ring (SpringKernel::pull_segment): backward springs of offsets in [kRingNearest,
// kRingFarthest] (a lattice's in-plane ones) read their force from where end a's own sum stored it, kRingRows rows
// of it (slid back when full: the farthest offset's rows copied once every ~kRingRows rows). kRingNearest keeps
// the reads of a vector of rows clear of its own writes (pull_body's ivdep).
constexpr int kRingNearest = 32, kRingFarthest = 512, kRingRows = 1024, kRingDirections = 3;
static_assert(kRingFarthest + kForceBlock <= kRingRows, "a piece fits the ring above the farthest offset's rows");
alignas(64) constexpr double kNoRingRows[kForceBlock] = {};  // the ring's reads where no end a is in the segment

// One direction of a stencil block: the springs from molecules a0 .. a0 + n - 1 to a0 + offset; their forces go
// into end b's rows at once and into g for end a's sum. Masked: a spring whose keep[i] is 0 gives +0.0 (a select,
// not a product: the separation of two unconnected molecules may have any length), and f - 0 = f, s + 0 = s bit
// for bit (neither sum is ever -0.0: both start at +0.0).
template <bool kMasked>
__attribute__((always_inline)) inline void stencil_direction(int n, const double* __restrict xa,
                                                             const double* __restrict xb, double* __restrict fb,
                                                             double ks, double ls, const double* __restrict keep,
                                                             double* __restrict g0, double* __restrict g1,
                                                             double* __restrict g2) {
  for (int i = 0; i < n; ++i) {
    const double d0 = xb[3 * i] - xa[3 * i], d1 = xb[3 * i + 1] - xa[3 * i + 1], d2 = xb[3 * i + 2] - xa[3 * i + 2];
    const double len = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    const double sc = ks * (len - ls) / len;
    double e0 = sc * d0, e1 = sc * d1, e2 = sc * d2;
    if constexpr (kMasked) {
      const bool on = keep[i] != 0.0;
      e0 = on ? e0 : 0.0, e1 = on ? e1 : 0.0, e2 = on ? e2 : 0.0;
    }
    fb[3 * i] -= e0, fb[3 * i + 1] -= e1, fb[3 * i + 2] -= e2;
    g0[i] = e0, g1[i] = e1, g2[i] = e2;
  }
}

// A stencil block's start, in both kernels: f's owned rows zeroed up to what the block writes (a0 + n - 1 +
// max_offset; `zeroed`: rows below it are zeroed), and the missing directions of the block's exceptions marked in
// keep (next_exception moves past them); returns the directions some exception of the block lacks (bit s:
// direction s is masked; a row end lacks 2-3 of a face-diagonal lattice's 9, the other directions run unmasked).
template <int kBlock, class Layout>
__attribute__((always_inline)) inline std::uint32_t begin_block(int a0, int n, int directions,
                                                       const StencilException* exceptions, int n_exceptions,
                                                       int& next_exception, double (*keep)[kBlock], double* f,
                                                       Layout at, int owned, int max_offset, int* zeroed) {
  const int reach = std::min(owned, a0 + n + max_offset);
  if (reach > *zeroed) {
    at.zero(f, *zeroed, reach);
    *zeroed = reach;
  }
  const int e0 = next_exception;
  while (next_exception < n_exceptions && exceptions[next_exception].molecule < a0 + n) ++next_exception;
  std::uint32_t lacking = 0;
  for (int e = e0; e < next_exception; ++e) {
    lacking |= ~exceptions[e].present;
    for (int s = 0; s < directions; ++s)
      if (!(exceptions[e].present >> s & 1u)) keep[s][exceptions[e].molecule - a0] = 0.0;
  }
  return lacking;
}

// The same arithmetic on three streams (x, y, z each contiguous): every load and store is a plain vector one,
// where the interlaced form spends most of its instructions de-interleaving (docs/benchmarks.md). Masked with one
// select, on k (l - l0) / l: a missing spring's forces are then +0.0 or -0.0, and f - (-0.0) = f + 0.0 = f, s + (-0.0)
// = s bit for bit unless f or s is -0.0, which neither ever is (both start at +0.0, and a sum of doubles is -0.0
// only when both terms are), so the same bits as three selects, with the rest of the loop unmasked.
template <bool kMasked>
__attribute__((always_inline)) inline void stencil_direction_streams(
    int n, const double* __restrict xa0, const double* __restrict xa1, const double* __restrict xa2,
    const double* __restrict xb0, const double* __restrict xb1, const double* __restrict xb2,
    double* __restrict fb0, double* __restrict fb1, double* __restrict fb2, double ks, double ls,
    const double* __restrict keep, double* __restrict g0, double* __restrict g1, double* __restrict g2) {
  for (int i = 0; i < n; ++i) {
    const double d0 = xb0[i] - xa0[i], d1 = xb1[i] - xa1[i], d2 = xb2[i] - xa2[i];
    const double len = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    double sc = ks * (len - ls) / len;
    if constexpr (kMasked) sc = keep[i] != 0.0 ? sc : 0.0;
    const double e0 = sc * d0, e1 = sc * d1, e2 = sc * d2;
    fb0[i] -= e0, fb1[i] -= e1, fb2[i] -= e2;
    g0[i] = e0, g1[i] = e1, g2[i] = e2;
  }
}

// A stencil segment: molecules first .. first + count - 1, each with `directions` forward connections to the
// molecule `offset[s]` further on (every offset > 0), of constants k[s], l0[s], except the molecules listed in
// `exceptions` (by molecule), which have only the directions of their `present` bits. `scatter` lists the
// directions by decreasing offset: within a block of molecules, a molecule that receives forces from two
// directions then gets them from the lower end a first, as the generic kernel (the connection order) adds them.
// Each molecule's own sum runs over its directions in connection order, and is added after every force it
// receives as end b from the block (all from lower ends a: offsets are positive), again as the generic kernel
// does. A missing direction adds +0.0 in both places, which changes no bit.
//
// f's owned rows are zeroed just ahead of the block that first writes them (`zeroed`: rows below it are zeroed;
// a block writes rows up to a0 + n - 1 + max_offset): a row then comes to the kernel from the cache, written
// back once, instead of a separate pass over memory before the kernel (docs/benchmarks.md). max_offset is the
// segment's largest offset to an owned row (Segment::owned_reach): a direction into the ghosts' rows reaches an owned
// row only where a molecule lacks it, and subtracts +0.0 there, which changes no bit, zeroed or not.
template <class Layout>
__attribute__((always_inline)) inline void stencil_body(int first, int count, int directions, const int* offset,
                                                        const int* scatter, const double* k, const double* l0,
                                                        const StencilException* exceptions, int n_exceptions,
                                                        const double* __restrict x, double* __restrict f,
                                                        Layout at, int owned, int max_offset, int* zeroed,
                                                        const ReadAhead* ahead = nullptr) {
  alignas(64) double g[kMaxDirections][3][kForceBlock];
  // keep[s][i]: 1 where molecule a0 + i has direction s; 0 only for the exceptions of the current block.
  alignas(64) double keep[kMaxDirections][kForceBlock];
  for (int s = 0; s < directions; ++s) std::fill(keep[s], keep[s] + kForceBlock, 1.0);
  int next_exception = 0;
  for (int a0 = first; a0 < first + count; a0 += kForceBlock) {
    const int n = std::min(kForceBlock, first + count - a0);
    const int e0 = next_exception;
    const std::uint32_t masked = begin_block(a0, n, directions, exceptions, n_exceptions, next_exception, keep, f,
                                             at, owned, max_offset, zeroed);
    if (ahead) {  // a cache line (8 rows) at a time
      const int end = std::min(a0 + n, ahead->end);
      for (int r = 0; r < ahead->streams; ++r)
        for (int i = a0; i < end; i += 8) __builtin_prefetch(ahead->rows[r] + i, 0, 2);
    }
    for (int q = 0; q < directions; ++q) {
      const int s = scatter[q], b0 = a0 + offset[s];
      if constexpr (!std::is_same_v<Layout, Interlaced>) {
        // In pieces that lie contiguous in f (one piece but where a ring turns): each spring is on its own, so
        // the pieces change no bit.
        for (int i0 = 0, len = 0; i0 < n; i0 += len) {
          len = at.run(b0 + i0, n - i0);
          const double *xa0 = x + at(a0 + i0, 0), *xa1 = x + at(a0 + i0, 1), *xa2 = x + at(a0 + i0, 2);
          const double *xb0 = x + at(b0 + i0, 0), *xb1 = x + at(b0 + i0, 1), *xb2 = x + at(b0 + i0, 2);
          double *fb0 = f + at.f(b0 + i0, 0), *fb1 = f + at.f(b0 + i0, 1), *fb2 = f + at.f(b0 + i0, 2);
          if (masked >> s & 1u)
            stencil_direction_streams<true>(len, xa0, xa1, xa2, xb0, xb1, xb2, fb0, fb1, fb2, k[s], l0[s],
                                            keep[s] + i0, g[s][0] + i0, g[s][1] + i0, g[s][2] + i0);
          else
            stencil_direction_streams<false>(len, xa0, xa1, xa2, xb0, xb1, xb2, fb0, fb1, fb2, k[s], l0[s],
                                             keep[s] + i0, g[s][0] + i0, g[s][1] + i0, g[s][2] + i0);
        }
      } else {
        const double* xa = x + at(a0, 0);
        const double* xb = x + at(b0, 0);
        double* fb = f + at(b0, 0);
        if (masked >> s & 1u)
          stencil_direction<true>(n, xa, xb, fb, k[s], l0[s], keep[s], g[s][0], g[s][1], g[s][2]);
        else
          stencil_direction<false>(n, xa, xb, fb, k[s], l0[s], keep[s], g[s][0], g[s][1], g[s][2]);
      }
    }
    for (int e = e0; e < next_exception; ++e)
      for (int s = 0; s < directions; ++s) keep[s][exceptions[e].molecule - a0] = 1.0;
    // Each molecule's sum over its directions in order, vectorized across molecules; three directions a pass (the
    // same additions in the same order: a third of the partial sums' loads and stores).
    alignas(64) double s0[kForceBlock] = {}, s1[kForceBlock] = {}, s2[kForceBlock] = {};
    int s = 0;
    for (; s + 3 <= directions; s += 3)
      for (int i = 0; i < n; ++i) {
        s0[i] = ((s0[i] + g[s][0][i]) + g[s + 1][0][i]) + g[s + 2][0][i];
        s1[i] = ((s1[i] + g[s][1][i]) + g[s + 1][1][i]) + g[s + 2][1][i];
        s2[i] = ((s2[i] + g[s][2][i]) + g[s + 1][2][i]) + g[s + 2][2][i];
      }
    for (; s < directions; ++s)
      for (int i = 0; i < n; ++i) s0[i] += g[s][0][i], s1[i] += g[s][1][i], s2[i] += g[s][2][i];
    if constexpr (!std::is_same_v<Layout, Interlaced>) {
      for (int i0 = 0, len = 0; i0 < n; i0 += len) {
        len = at.run(a0 + i0, n - i0);
        double *__restrict fa0 = f + at.f(a0 + i0, 0), *__restrict fa1 = f + at.f(a0 + i0, 1),
                           *__restrict fa2 = f + at.f(a0 + i0, 2);
        for (int i = 0; i < len; ++i) fa0[i] += s0[i0 + i], fa1[i] += s1[i0 + i], fa2[i] += s2[i0 + i];
      }
    } else {
      double* __restrict fa = f + at(a0, 0);
      for (int i = 0; i < n; ++i) fa[3 * i] += s0[i], fa[3 * i + 1] += s1[i], fa[3 * i + 2] += s2[i];
    }
  }
}

// The tangent (SpringKernel::tangent), generic form: connections [begin_c, end_c) of any list, one at a time
// (a lattice's row ends, about 2 % of its connections). A row below `owned` is out's, the others ghost's.
void generic_tangent(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                     const std::uint16_t* ltype, const double* ks, const double* ls, const double* x, const double* u,
                     double* out, double* ghost, int owned) {
  auto row = [&](int m) { return m < owned ? out + 3 * m : ghost + 3 * (m - owned); };
  for (int c = begin_c; c < end_c; ++c) {
    const double *xa = x + 3 * a[c], *xb = x + 3 * b[c], *ua = u + 3 * a[c], *ub = u + 3 * b[c];
    const double d0 = xb[0] - xa[0], d1 = xb[1] - xa[1], d2 = xb[2] - xa[2];
    const double w0 = ua[0] - ub[0], w1 = ua[1] - ub[1], w2 = ua[2] - ub[2];
    const double k = ks[ktype ? ktype[c] : c], l0 = ls[ltype ? ltype[c] : c];
    const double len2 = d0 * d0 + d1 * d1 + d2 * d2, geo = 1.0 - l0 / std::sqrt(len2);
    const double along = (1.0 - geo) * (d0 * w0 + d1 * w1 + d2 * w2) / len2;
    const double e0 = k * (geo * w0 + along * d0), e1 = k * (geo * w1 + along * d1), e2 = k * (geo * w2 + along * d2);
    double *fa = row(a[c]), *fb = row(b[c]);
    fa[0] += e0, fa[1] += e1, fa[2] += e2;
    fb[0] -= e0, fb[1] -= e1, fb[2] -= e2;
  }
}

// One direction of a stencil block of the tangent: e_i = K_i (u_a - u_b) for the springs from molecules a0 .. a0 +
// n - 1 to a0 + offset, into g (subtracted from end b's rows and summed into end a's by the caller). Masked as
// stencil_direction: a missing spring gives +0.0. End a's positions and values come as three streams (the block's,
// de-interleaved once for all its directions), end b's interlaced.
template <bool kMasked>
__attribute__((always_inline)) inline void tangent_direction(int n, const double* __restrict xa0,
                                                             const double* __restrict xa1,
                                                             const double* __restrict xa2,
                                                             const double* __restrict xb,
                                                             const double* __restrict ua0,
                                                             const double* __restrict ua1,
                                                             const double* __restrict ua2,
                                                             const double* __restrict ub, double ks, double ls,
                                                             const double* __restrict keep, double* __restrict g0,
                                                             double* __restrict g1, double* __restrict g2) {
  for (int i = 0; i < n; ++i) {
    const double d0 = xb[3 * i] - xa0[i], d1 = xb[3 * i + 1] - xa1[i], d2 = xb[3 * i + 2] - xa2[i];
    const double w0 = ua0[i] - ub[3 * i], w1 = ua1[i] - ub[3 * i + 1], w2 = ua2[i] - ub[3 * i + 2];
    const double len2 = d0 * d0 + d1 * d1 + d2 * d2, geo = 1.0 - ls / std::sqrt(len2);
    const double along = (1.0 - geo) * (d0 * w0 + d1 * w1 + d2 * w2) / len2;
    double e0 = ks * (geo * w0 + along * d0), e1 = ks * (geo * w1 + along * d1), e2 = ks * (geo * w2 + along * d2);
    if constexpr (kMasked) {
      const bool on = keep[i] != 0.0;
      e0 = on ? e0 : 0.0, e1 = on ? e1 : 0.0, e2 = on ? e2 : 0.0;
    }
    g0[i] = e0, g1[i] = e1, g2[i] = e2;
  }
}

// Rows m .. m + n - 1 (+= sign * g): those below `owned` in out, the rest in ghost.
template <int kSign>
__attribute__((always_inline)) inline void add_to_rows(int m, int n, const double* __restrict g0,
                                                       const double* __restrict g1, const double* __restrict g2,
                                                       double* __restrict out, double* __restrict ghost, int owned) {
  const int split = std::clamp(owned - m, 0, n);
  double* __restrict o = out + 3 * static_cast<std::ptrdiff_t>(m);
  for (int i = 0; i < split; ++i) o[3 * i] += kSign * g0[i], o[3 * i + 1] += kSign * g1[i], o[3 * i + 2] += kSign * g2[i];
  if (split == n) return;
  double* __restrict h = ghost + 3 * static_cast<std::ptrdiff_t>(m + split - owned);
  for (int i = split; i < n; ++i)
    h[3 * (i - split)] += kSign * g0[i], h[3 * (i - split) + 1] += kSign * g1[i], h[3 * (i - split) + 2] += kSign * g2[i];
}

// A stencil segment's tangent, block by block as stencil_forces (the same segments, exceptions and zeroing ahead).
TISSUE_CLONES
void stencil_tangent(int first, int count, int directions, const int* offset, const int* scatter, const double* k,
                     const double* l0, const StencilException* exceptions, int n_exceptions,
                     const double* __restrict x, const double* __restrict u, double* __restrict out,
                     double* __restrict ghost, int owned, int max_offset, int* zeroed) {
  alignas(64) double g[kMaxDirections][3][kStencilBlock];
  alignas(64) double keep[kMaxDirections][kStencilBlock];
  for (int s = 0; s < directions; ++s) std::fill(keep[s], keep[s] + kStencilBlock, 1.0);
  int next_exception = 0;
  for (int a0 = first; a0 < first + count; a0 += kStencilBlock) {
    const int n = std::min(kStencilBlock, first + count - a0);
    const int e0 = next_exception;
    const std::uint32_t masked = begin_block(a0, n, directions, exceptions, n_exceptions, next_exception, keep,
                                             out, Interlaced{}, owned, max_offset, zeroed);
    const double* __restrict xa = x + 3 * a0;
    const double* __restrict ua = u + 3 * a0;
    alignas(64) double xs[3][kStencilBlock], us[3][kStencilBlock];  // end a's, de-interleaved once for every direction
    for (int i = 0; i < n; ++i)
      for (int r = 0; r < 3; ++r) xs[r][i] = xa[3 * i + r], us[r][i] = ua[3 * i + r];
    for (int q = 0; q < directions; ++q) {
      const int s = scatter[q], b0 = a0 + offset[s];
      if (masked >> s & 1u)
        tangent_direction<true>(n, xs[0], xs[1], xs[2], x + 3 * b0, us[0], us[1], us[2], u + 3 * b0, k[s], l0[s],
                                keep[s], g[s][0], g[s][1], g[s][2]);
      else
        tangent_direction<false>(n, xs[0], xs[1], xs[2], x + 3 * b0, us[0], us[1], us[2], u + 3 * b0, k[s], l0[s],
                                 keep[s], g[s][0], g[s][1], g[s][2]);
      add_to_rows<-1>(b0, n, g[s][0], g[s][1], g[s][2], out, ghost, owned);
    }
    for (int e = e0; e < next_exception; ++e)
      for (int s = 0; s < directions; ++s) keep[s][exceptions[e].molecule - a0] = 1.0;
    alignas(64) double s0[kStencilBlock] = {}, s1[kStencilBlock] = {}, s2[kStencilBlock] = {};
    for (int s = 0; s < directions; ++s)
      for (int i = 0; i < n; ++i) s0[i] += g[s][0][i], s1[i] += g[s][1][i], s2[i] += g[s][2][i];
    add_to_rows<1>(a0, n, s0, s1, s2, out, ghost, owned);
  }
}

// One direction of a stencil block of the tangent at rest: e_i = K (u_a - u_b) with the direction's constant
// K = a a^T (a = sqrt(k) n: RestStencil), as (a . w) a, masked as tangent_direction.
template <bool kMasked>
__attribute__((always_inline)) inline void rest_direction(int n, const double* __restrict ua0,
                                                          const double* __restrict ua1,
                                                          const double* __restrict ua2,
                                                          const double* __restrict ub, const double* K,
                                                          const double* __restrict keep, double* __restrict g0,
                                                          double* __restrict g1, double* __restrict g2) {
  const double a0 = K[0], a1 = K[1], a2 = K[2];
  for (int i = 0; i < n; ++i) {
    const double w0 = ua0[i] - ub[3 * i], w1 = ua1[i] - ub[3 * i + 1], w2 = ua2[i] - ub[3 * i + 2];
    const double t = a0 * w0 + a1 * w1 + a2 * w2;
    double e0 = t * a0, e1 = t * a1, e2 = t * a2;
    if constexpr (kMasked) {
      const bool on = keep[i] != 0.0;
      e0 = on ? e0 : 0.0, e1 = on ? e1 : 0.0, e2 = on ? e2 : 0.0;
    }
    g0[i] = e0, g1[i] = e1, g2[i] = e2;
  }
}

// stencil_tangent at rest: the same blocks, exceptions and zeroing ahead, a = sqrt(k) n per direction (3 values
// each) instead of k, l0 and the positions.
TISSUE_CLONES
void stencil_rest_tangent(int first, int count, int directions, const int* offset, const int* scatter,
                          const double* a, const StencilException* exceptions, int n_exceptions,
                          const double* __restrict u, double* __restrict out, double* __restrict ghost, int owned,
                          int max_offset, int* zeroed) {
  alignas(64) double g[kMaxDirections][3][kStencilBlock];
  alignas(64) double keep[kMaxDirections][kStencilBlock];
  for (int s = 0; s < directions; ++s) std::fill(keep[s], keep[s] + kStencilBlock, 1.0);
  int next_exception = 0;
  for (int a0 = first; a0 < first + count; a0 += kStencilBlock) {
    const int n = std::min(kStencilBlock, first + count - a0);
    const int e0 = next_exception;
    const std::uint32_t masked = begin_block(a0, n, directions, exceptions, n_exceptions, next_exception, keep,
                                             out, Interlaced{}, owned, max_offset, zeroed);
    const double* __restrict ua = u + 3 * a0;
    alignas(64) double us[3][kStencilBlock];
    for (int i = 0; i < n; ++i)
      for (int r = 0; r < 3; ++r) us[r][i] = ua[3 * i + r];
    for (int q = 0; q < directions; ++q) {
      const int s = scatter[q], b0 = a0 + offset[s];
      if (masked >> s & 1u)
        rest_direction<true>(n, us[0], us[1], us[2], u + 3 * b0, a + 3 * s, keep[s], g[s][0], g[s][1], g[s][2]);
      else
        rest_direction<false>(n, us[0], us[1], us[2], u + 3 * b0, a + 3 * s, keep[s], g[s][0], g[s][1], g[s][2]);
      add_to_rows<-1>(b0, n, g[s][0], g[s][1], g[s][2], out, ghost, owned);
    }
    for (int e = e0; e < next_exception; ++e)
      for (int s = 0; s < directions; ++s) keep[s][exceptions[e].molecule - a0] = 1.0;
    alignas(64) double s0[kStencilBlock] = {}, s1[kStencilBlock] = {}, s2[kStencilBlock] = {};
    for (int s = 0; s < directions; ++s)
      for (int i = 0; i < n; ++i) s0[i] += g[s][0][i], s1[i] += g[s][1][i], s2[i] += g[s][2][i];
    add_to_rows<1>(a0, n, s0, s1, s2, out, ghost, owned);
  }
}

TISSUE_CLONES
void stencil_forces_interlaced(int first, int count, int directions, const int* offset, const int* scatter,
                               const double* k, const double* l0, const StencilException* exceptions,
                               int n_exceptions, const double* x, double* f, Interlaced at, int owned,
                               int max_offset, int* zeroed) {
  stencil_body(first, count, directions, offset, scatter, k, l0, exceptions, n_exceptions, x, f, at, owned,
               max_offset, zeroed);
}
TISSUE_CLONES
void stencil_forces_ring(int first, int count, int directions, const int* offset, const int* scatter,
                         const double* k, const double* l0, const StencilException* exceptions, int n_exceptions,
                         const double* x, double* f, RingStreams at, int owned, int max_offset, int* zeroed,
                         const ReadAhead* ahead) {
  stencil_body(first, count, directions, offset, scatter, k, l0, exceptions, n_exceptions, x, f, at, owned,
               max_offset, zeroed, ahead);
}
TISSUE_CLONES
void stencil_forces_streams(int first, int count, int directions, const int* offset, const int* scatter,
                            const double* k, const double* l0, const StencilException* exceptions, int n_exceptions,
                            const double* x, double* f, Streams at, int owned, int max_offset, int* zeroed,
                            const ReadAhead* ahead) {
  stencil_body(first, count, directions, offset, scatter, k, l0, exceptions, n_exceptions, x, f, at, owned,
               max_offset, zeroed, ahead);
}

// The two layouts' entry points, overloaded for SpringKernel::sweep.
void generic_forces(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                    const std::uint16_t* ltype, const double* ks, const double* ls, const double* x, double* f,
                    Interlaced at) {
  generic_forces_interlaced(begin_c, end_c, a, b, ktype, ltype, ks, ls, x, f, at);
}
void generic_forces(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                    const std::uint16_t* ltype, const double* ks, const double* ls, const double* x, double* f,
                    Streams at) {
  generic_forces_streams(begin_c, end_c, a, b, ktype, ltype, ks, ls, x, f, at);
}
void generic_forces(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                    const std::uint16_t* ltype, const double* ks, const double* ls, const double* x, double* f,
                    RingStreams at) {
  generic_forces_ring(begin_c, end_c, a, b, ktype, ltype, ks, ls, x, f, at);
}
void stencil_forces(int first, int count, int directions, const int* offset, const int* scatter, const double* k,
                    const double* l0, const StencilException* exceptions, int n_exceptions, const double* x,
                    double* f, RingStreams at, int owned, int max_offset, int* zeroed, const ReadAhead* ahead) {
  stencil_forces_ring(first, count, directions, offset, scatter, k, l0, exceptions, n_exceptions, x, f, at, owned,
                      max_offset, zeroed, ahead);
}
void stencil_forces(int first, int count, int directions, const int* offset, const int* scatter, const double* k,
                    const double* l0, const StencilException* exceptions, int n_exceptions, const double* x,
                    double* f, Interlaced at, int owned, int max_offset, int* zeroed, const ReadAhead*) {
  stencil_forces_interlaced(first, count, directions, offset, scatter, k, l0, exceptions, n_exceptions, x, f, at,
                            owned, max_offset, zeroed);
}
void stencil_forces(int first, int count, int directions, const int* offset, const int* scatter, const double* k,
                    const double* l0, const StencilException* exceptions, int n_exceptions, const double* x,
                    double* f, Streams at, int owned, int max_offset, int* zeroed, const ReadAhead* ahead) {
  stencil_forces_streams(first, count, directions, offset, scatter, k, l0, exceptions, n_exceptions, x, f, at,
                         owned, max_offset, zeroed, ahead);
}

// One end of every connection read by index, as the constructor below reads it (mostly forward, then one pass
// backward): plain ends from their array; ends stored as runs decoded a window at a time (ConnectionEnd::decode),
// not by a run search and a division per read.
class EndReader {
public:
  explicit EndReader(const ConnectionEnd& end) : end_(end), plain_(end.plain() ? end.data() : nullptr) {}
  bool plain() const { return plain_ != nullptr; }
  int operator[](int c) const {
    if (plain_) return plain_[c];
    if (c < w0_ || c >= w1_) fill(c);
    return window_[c - w0_];
  }

private:
  static constexpr int kWindow = 4096, kMargin = 64;
  void fill(int c) const {
    const int n = static_cast<int>(end_.size());
    w0_ = c >= w1_ ? std::max(0, c - kMargin) : std::max(0, c - kWindow + kMargin);
    w1_ = std::min(n, w0_ + kWindow);
    window_.resize(kWindow);
    end_.decode(w0_, w1_, window_.data());
  }
  const ConnectionEnd& end_;
  const int* plain_;
  mutable std::vector<int> window_;
  mutable int w0_ = 0, w1_ = 0;
};

// A pull row's present springs (bit q: the q-th backward / own forward one; at most 13 directions). 32 bits: the
// compiler vectorizes pull_body over 16 rows a zmm iteration (two registers a double); 64-bit bits (8 rows, half
// the spills) ran faster at 40^3 but slower at 10^6 on Zen 5 (docs/benchmarks.md, kern18l), 1.04-1.05x faster on
// Zen 4 (docs/benchmarks.md, "A Zen 4 host").
using PullBits = std::uint32_t;

// v where bit q of bits is set, +0.0 where it is not: the select as a bitwise and, which every vector instruction
// set has. Written as `bit ? v : 0.0` after a division, GCC 12 keeps a branch around the division and vectorizes the
// loop only with AVX-512's masks: the AVX2 and SSE2 clones of the pull ran scalar, 3.2x slower (docs/benchmarks.md).
__attribute__((always_inline)) inline double kept(double v, PullBits bits, int q) {
  std::uint64_t u;
  std::memcpy(&u, &v, sizeof u);
  u &= 0 - static_cast<std::uint64_t>(bits >> q & 1u);
  std::memcpy(&v, &u, sizeof v);
  return v;
}

// The pull form (SpringKernel::pull_segment): each row's force summed in registers from every spring on it, its
// backward ones (end b: from the molecules at offset bo[q] below, by decreasing offset, i.e. by increasing end a)
// subtracted from the row's value so far, then the sum of its own forward ones (end a, in direction order) added,
// the row written once: the additions the push form does, in its order, on the same operands (a backward spring's
// separation is x_b - x_a as the push form computes it), so the same bits; every spring is computed twice, from each
// end (but kRingBack's: below), and no row is updated twice (docs/benchmarks.md). x and f point at the piece's
// first row (three streams each). Masked with one select on k (l - l0) / l, as the push form: bit q of pb[i] (of
// pf[i]) says whether backward spring q (forward spring s) of row i exists; a missing one subtracts or adds +-0.0,
// which leaves the sums' bits as they are (neither is ever -0.0). kOwn: the rows are the segment's molecules
// (their own sums).
// Always masked, also where every spring is present (the unmasked loop ran slower: docs/benchmarks.md, kern18k).
// kRingBack (bits q) and kRingOwn (bits s), the force ring: own spring s's force sc (x_b - x_a) is stored at
// wf_[3 s + c][i] as the own sum adds it, and backward spring q reads it at rb_[3 q + c][i] (end a's row) instead
// of computing it again: the same product, so the same bits (a missing one subtracts +0.0 instead of +-0.0).
template <int D, bool kOwn, unsigned kRingBack = 0u, unsigned kRingOwn = 0u>
__attribute__((always_inline)) inline void pull_body(int n, const double* __restrict x0, const double* __restrict x1,
                                                     const double* __restrict x2, double* __restrict f0,
                                                     double* __restrict f1, double* __restrict f2, const int* bo_,
                                                     const double* bk_, const double* bl_, const int* fo_,
                                                     const double* fk_, const double* fl_,
                                                     const PullBits* __restrict pb,
                                                     const PullBits* __restrict pf, const double* const* rb_ = nullptr,
                                                     double* const* wf_ = nullptr) {
  int bo[D], fo[D];
  double bk[D], bl[D], fk[D], fl[D];
  for (int q = 0; q < D; ++q) bo[q] = bo_[q], bk[q] = bk_[q], bl[q] = bl_[q], fo[q] = fo_[q], fk[q] = fk_[q], fl[q] = fl_[q];
  // The force ring (kRingBack, kRingOwn: pull_ring): backward spring q's force read where its end a stored it.
  const double* rb[D][3] = {};
  double* wf[D][3] = {};
  for (int q = 0; q < D; ++q)
    for (int c = 0; c < 3; ++c) {
      if (kRingBack >> q & 1u) rb[q][c] = rb_[3 * q + c];
      if (kRingOwn >> q & 1u) wf[q][c] = wf_[3 * q + c];
    }
  // The ring's reads lie at least kRingNearest rows below its writes: no dependence within a vector's rows.
#pragma GCC ivdep
  for (int i = 0; i < n; ++i) {
    const double y0 = x0[i], y1 = x1[i], y2 = x2[i];
    double a0 = f0[i], a1 = f1[i], a2 = f2[i];
#pragma GCC unroll 32
    for (int q = 0; q < D; ++q) {
      if (kRingBack >> q & 1u) {  // sc (x_b - x_a), as end a's own sum computed it (and stored it)
        // read whether or not the spring is there (the ring's rows are always readable), then kept: a load under
        // a condition needs AVX-512's masked loads
        const double g0 = kept(rb[q][0][i], pb[i], q), g1 = kept(rb[q][1][i], pb[i], q),
                     g2 = kept(rb[q][2][i], pb[i], q);
        a0 -= g0, a1 -= g1, a2 -= g2;
        continue;
      }
      const int j = i - bo[q];
      const double d0 = y0 - x0[j], d1 = y1 - x1[j], d2 = y2 - x2[j];
      const double len = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
      double sc = bk[q] * (len - bl[q]) / len;
      sc = kept(sc, pb[i], q);
      a0 -= sc * d0, a1 -= sc * d1, a2 -= sc * d2;
    }
    if constexpr (kOwn) {
      double o0 = 0, o1 = 0, o2 = 0;
#pragma GCC unroll 32
      for (int s = 0; s < D; ++s) {
        const int j = i + fo[s];
        const double d0 = x0[j] - y0, d1 = x1[j] - y1, d2 = x2[j] - y2;
        const double len = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        double sc = fk[s] * (len - fl[s]) / len;
        sc = kept(sc, pf[i], s);
        const double g0 = sc * d0, g1 = sc * d1, g2 = sc * d2;
        if (kRingOwn >> s & 1u) wf[s][0][i] = g0, wf[s][1][i] = g1, wf[s][2][i] = g2;
        o0 += g0, o1 += g1, o2 += g2;
      }
      a0 += o0, a1 += o1, a2 += o2;
    }
    f0[i] = a0, f1[i] = a1, f2[i] = a2;
  }
}

// The pull form's pieces, one clone set per direction count (the patterns' counts a lattice has: rectangular 3,
// face-diagonals 9, body-diagonals 13; other counts keep the push form).
struct PullPiece {
  int n;
  const double* x[3];
  double* f[3];
  const int *bo, *fo;
  const double *bk, *bl, *fk, *fl;
  const PullBits *pb, *pf;
  bool own;
  // The force ring (pull_ring): backward q's three components at rb[3 q + c] (the piece's first row's end a),
  // own direction s's at wf[3 s + c] (the piece's first row); ring: whether the piece uses them.
  const double* const* rb = nullptr;
  double* const* wf = nullptr;
  int ring = 0;
};
template <int D, unsigned kRingBack = 0u, unsigned kRingOwn = 0u>
__attribute__((always_inline)) inline void pull_dispatch(const PullPiece& p) {
  if (p.own)
    pull_body<D, true, kRingBack, kRingOwn>(p.n, p.x[0], p.x[1], p.x[2], p.f[0], p.f[1], p.f[2], p.bo, p.bk, p.bl,
                                            p.fo, p.fk, p.fl, p.pb, p.pf, p.rb, p.wf);
  else
    pull_body<D, false, kRingBack, kRingOwn>(p.n, p.x[0], p.x[1], p.x[2], p.f[0], p.f[1], p.f[2], p.bo, p.bk, p.bl,
                                             p.fo, p.fk, p.fl, p.pb, p.pf, p.rb, p.wf);
}
TISSUE_CLONES void pull_rows3(const PullPiece& p) { pull_dispatch<3>(p); }
TISSUE_CLONES void pull_rows9(const PullPiece& p) { pull_dispatch<9>(p); }
TISSUE_CLONES void pull_rows13(const PullPiece& p) { pull_dispatch<13>(p); }
// The force ring's direction sets (backward bits, own bits) that have a kernel: the in-plane directions N - 1, N,
// N + 1 of the face-diagonals lattice (backward 5-7 of 9 by decreasing offset; own 1-3 by increasing offset) and
// N of the rectangular one.
constexpr unsigned kRing9Back = 0xE0u, kRing9Own = 0x0Eu, kRing3Back = 0x2u, kRing3Own = 0x2u;
TISSUE_CLONES void pull_rows9_ring(const PullPiece& p) { pull_dispatch<9, kRing9Back, kRing9Own>(p); }
TISSUE_CLONES void pull_rows3_ring(const PullPiece& p) { pull_dispatch<3, kRing3Back, kRing3Own>(p); }
bool pull_directions(int d) { return d == 3 || d == 9 || d == 13; }
// Whether a kernel takes the force ring for these directions (pull_ring).
bool pull_ring_kernel(int d, unsigned back, unsigned own) {
  return (d == 9 && back == kRing9Back && own == kRing9Own) || (d == 3 && back == kRing3Back && own == kRing3Own);
}
void pull_rows(int d, const PullPiece& p) {
  if (d == 9) p.ring ? pull_rows9_ring(p) : pull_rows9(p);
  else if (d == 13) pull_rows13(p);
  else p.ring ? pull_rows3_ring(p) : pull_rows3(p);
}

}  // namespace

TISSUE_CLONES
void tangent_diagonal_terms(int n, const double* __restrict d0, const double* __restrict d1,
                            const double* __restrict d2, const double* __restrict k, const double* __restrict l0,
                            double* __restrict K0, double* __restrict K1, double* __restrict K2) {
  for (int i = 0; i < n; ++i) {
    const double len2 = d0[i] * d0[i] + d1[i] * d1[i] + d2[i] * d2[i], geo = 1.0 - l0[i] / std::sqrt(len2);
    K0[i] = k[i] * (geo + (1.0 - geo) * d0[i] * d0[i] / len2);
    K1[i] = k[i] * (geo + (1.0 - geo) * d1[i] * d1[i] / len2);
    K2[i] = k[i] * (geo + (1.0 - geo) * d2[i] * d2[i] / len2);
  }
}

SpringKernel::SpringKernel(const LocalModel& model) : model_(model) {
  const int nc = model.connections();
  const EndReader a(model.end_a);  // indexed as arrays; runs (ConnectionEnd) give the same values
  const EndReader b(model.end_b);
  // Ends stored as runs: the generic connections [c0, c1) get arrays of their own; returns where they start.
  auto keep_generic = [&](int c0, int c1) {
    const int at = static_cast<int>(generic_a_.size());
    if (a.plain()) return at;
    for (int c = c0; c < c1; ++c) generic_a_.push_back(a[c]), generic_b_.push_back(b[c]);
    return at;
  };
  if (!model.typed()) {  // k may still change (calibration): nothing cached, every connection generic
    tail_at_ = keep_generic(0, nc);
    return;
  }
  const ConnectionColumn kc = model.table.stiffness_column(), lc = model.table.rest_length_column();
  const std::uint16_t* type = kc.type;  // typed: k and l0 share the connection type
  auto run_end = [&](int c) {
    int e = c + 1;
    const int first = a[c];
    while (e < nc && a[e] == first) ++e;
    return e;
  };
  // A run of one end a fits a stencil when its offsets are positive and increasing (the connection order is
  // by end b): then a pattern is a sorted list of (offset, type), and a run's directions a sub-list of it.
  auto usable = [&](int c, int e) {
    if (e - c > kMaxDirections || b[c] <= a[c]) return false;
    for (int t = c + 1; t < e; ++t)
      if (b[t] <= b[t - 1]) return false;
    return true;
  };
  // The owned rows of f that generic connections [c0, c1) write: below the returned index.
  const int owned = model.owned, local = model.local;
  auto reach_of = [&](int c0, int c1) {
    int reach = 0;
    for (int c = c0; c < c1; ++c) {
      if (a[c] < owned) reach = std::max(reach, a[c] + 1);
      if (b[c] < owned) reach = std::max(reach, b[c] + 1);
    }
    return reach;
  };
  struct Direction {
    int offset;
    std::uint16_t type;
  };
  // The union of `pattern` and run [c, e) (both by increasing offset) into `merged`; false where one offset has
  // two types (two materials meet: the segment ends there).
  auto merge = [&](const std::vector<Direction>& pattern, int c, int e, std::vector<Direction>& merged) {
    merged.clear();
    std::size_t p = 0;
    for (int t = c; t < e; ++t) {
      const int off = b[t] - a[t];
      for (; p < pattern.size() && pattern[p].offset < off; ++p) merged.push_back(pattern[p]);
      if (p < pattern.size() && pattern[p].offset == off) {
        if (pattern[p].type != type[t]) return false;
        ++p;
      }
      merged.push_back({off, type[t]});
    }
    for (; p < pattern.size(); ++p) merged.push_back(pattern[p]);
    return static_cast<int>(merged.size()) <= kMaxDirections;
  };
  int generic_begin = 0;
  constexpr int kShortest = 4;  // shorter runs of molecules stay generic
  std::vector<Direction> pattern, merged;
  std::vector<std::pair<int, int>> members;  // per molecule of the segment: its run [first, end) (empty: none)
  for (int c = 0; c < nc;) {
    const int e = run_end(c);
    if (!usable(c, e)) {
      c = e;
      continue;
    }
    pattern.clear();
    for (int t = c; t < e; ++t) pattern.push_back({b[t] - a[t], type[t]});
    const int first_molecule = a[c];  // read once: the loop below reads ends far ahead of c
    if (first_molecule + pattern.back().offset >= local) {
      c = e;
      continue;
    }
    members.assign(1, {c, e});
    // Extend over the next molecules while their runs fit the pattern (growing it by union), every stream stays
    // inside the local arrays (the missing directions are read and written too: + 0.0), and at most a quarter
    // of the segment's direction slots are missing ones (a row end's or a face's, not an irregular mesh's).
    int next = e, molecules = 1;
    long present = e - c;
    for (;;) {
      const int m = first_molecule + molecules;
      int run_first = next, run_last = next;
      if (next < nc && a[next] == m) {
        run_last = run_end(next);
        if (!usable(next, run_last)) break;
      } else if (next < nc && a[next] < m) {
        break;
      }
      // Most runs are the pattern itself (a lattice's interior): then the union is the pattern, unbuilt.
      bool same = run_last - run_first == static_cast<int>(pattern.size());
      for (int t = run_first, s = 0; same && t < run_last; ++t, ++s)
        same = pattern[s].offset == b[t] - a[t] && pattern[s].type == type[t];
      if (!same && (!merge(pattern, run_first, run_last, merged) || merged.empty())) break;
      const std::vector<Direction>& grown = same ? pattern : merged;
      if (m + grown.back().offset >= local) break;
      const long slots = static_cast<long>(molecules + 1) * static_cast<long>(grown.size());
      if (4 * (slots - present - (run_last - run_first)) > slots) break;
      if (!same) pattern.swap(merged);
      members.push_back({run_first, run_last});
      present += run_last - run_first;
      next = run_last;
      ++molecules;
    }
    // Trailing molecules without connections only cost time.
    while (molecules > 1 && members.back().first == members.back().second) members.pop_back(), --molecules;
    if (molecules < kShortest) {
      c = e;
      continue;
    }
    next = members.back().second;
    const int len = static_cast<int>(pattern.size());
    // A new pattern, or the last one again (a lattice's planes repeat theirs).
    int id = static_cast<int>(directions_.size());
    if (!segments_.empty()) {
      const int p = segments_.back().pattern;
      bool same = directions_[p] == len;
      for (int s = 0; same && s < len; ++s)
        same = offsets_[pattern_start_[p] + s] == pattern[s].offset && types_[pattern_start_[p] + s] == pattern[s].type;
      if (same) id = p;
    }
    if (id == static_cast<int>(directions_.size())) {
      const int start = static_cast<int>(offsets_.size());
      pattern_start_.push_back(start);
      directions_.push_back(len);
      for (int s = 0; s < len; ++s) {
        offsets_.push_back(pattern[s].offset), types_.push_back(pattern[s].type);
        k_.push_back(kc.value[pattern[s].type]), l0_.push_back(lc.value[pattern[s].type]);
        scatter_.push_back(s);
      }
      reach_.push_back(pattern.back().offset);
      std::sort(scatter_.begin() + start, scatter_.end(),
                [&](int s, int t) { return offsets_[start + s] > offsets_[start + t]; });
    }
    const int first_exception = static_cast<int>(exceptions_.size());
    for (int i = 0; i < molecules; ++i) {
      const auto [r0, r1] = members[i];
      if (r1 - r0 == len) continue;
      std::uint32_t bits = 0;
      for (int t = r0, s = 0; t < r1; ++t) {
        while (pattern[s].offset != b[t] - a[t]) ++s;
        bits |= 1u << s;
      }
      exceptions_.push_back({first_molecule + i, bits});
    }
    int owned_reach = 0;
    for (int t = c; t < next; ++t)
      if (b[t] < owned) owned_reach = std::max(owned_reach, b[t] - a[t]);
    segments_.push_back({c, next - c, first_molecule, molecules, id, reach_of(generic_begin, c),
                         keep_generic(generic_begin, c), first_exception,
                         static_cast<int>(exceptions_.size()) - first_exception, 0, owned_reach});
    structured_ += next - c;
    c = next;
    generic_begin = c;
  }
  tail_reach_ = reach_of(generic_begin, nc);
  tail_at_ = keep_generic(generic_begin, nc);
  generic_a_.shrink_to_fit(), generic_b_.shrink_to_fit();
  // Each segment's `later`: the lowest row any connection after it touches.
  int lowest = std::numeric_limits<int>::max(), c = nc;
  for (auto seg = segments_.rbegin(); seg != segments_.rend(); ++seg) {
    for (const int end = seg->first_connection + seg->connections; c > end; --c)
      lowest = std::min({lowest, a[c - 1], b[c - 1]});
    seg->later = lowest;
    c = seg->first_connection;
  }
  for (Segment& seg : segments_)
    if (pull_directions(directions_[seg.pattern]) && seg.molecules >= kChunk) {
      pull_marks(seg);
      if (pull_ring_rows_.empty())
        pull_ring_rows_.assign(static_cast<std::size_t>(3 * kRingDirections) * kRingRows, 0.0);
    }
  marks_.shrink_to_fit();
  // The ring's rows: the sweep with final_rows (sweep(), the same steps without the arithmetic) holds rows
  // [done, zeroed) live; the ring must hold the widest such window.
  long done = 0, zeroed = 0, widest = 0;
  auto zero_to = [&](long reach) {
    zeroed = std::max(zeroed, std::min<long>(reach, owned));
    widest = std::max(widest, zeroed - done);
  };
  auto finish = [&](long below) {
    below = std::min<long>(below, owned);
    if (below <= done) return;
    zero_to(below);
    done = below;
  };
  c = 0;
  for (const Segment& seg : segments_) {
    if (c < seg.first_connection) {
      zero_to(seg.generic_reach);
      finish(std::min(seg.first_molecule, seg.later));
    }
    for (int m0 = 0; m0 < seg.molecules; m0 += kChunk) {
      const long end = seg.first_molecule + m0 + std::min(kChunk, seg.molecules - m0);
      zero_to(end + seg.owned_reach);  // the chunk's last block zeroes up to here
      finish(std::min<long>(end, seg.later));
    }
    c = seg.first_connection + seg.connections;
  }
  if (c < nc) zero_to(tail_reach_);
  finish(owned);
  long rows = 64;
  while (rows < widest) rows *= 2;
  // Worth it only when much smaller than f, and small enough to stay in cache (24 B a row).
  if (rows <= kLargestRing && 2 * rows <= owned) ring_rows_ = static_cast<int>(rows);
}

template <class Layout>
void SpringKernel::zero_ahead(double* f, Layout at, int& zeroed, int reach) const {
  reach = std::min(reach, model_.owned);
  if (reach <= zeroed) return;
  at.zero(f, zeroed, reach);
  zeroed = reach;
}

void SpringKernel::forces(const double* x, double* f, FinalRows final_rows, void* context) const {
  sweep(x, f, Interlaced{}, final_rows, context);
}

void SpringKernel::forces_streams(const double* x, double* f, std::size_t stride, FinalRows final_rows,
                                  void* context, const ReadAhead* ahead) const {
  sweep(x, f, Streams{stride}, final_rows, context, ahead);
}

void SpringKernel::forces_ring(const double* x, double* ring, std::size_t stride, FinalRows final_rows,
                               void* context, const ReadAhead* ahead) const {
  sweep(x, ring,
        RingStreams{stride, static_cast<std::size_t>(ring_rows_), static_cast<std::size_t>(model_.local - model_.owned),
                    model_.owned},
        final_rows, context, ahead);
}

// A segment in the pull form (pull_body): its rows [first, first + molecules + P) below the owned count, P its
// largest offset to an owned row, in pieces of at most kForceBlock rows (within one turn of a ring, on one side of
// the segment's end and of each first + offset, below which a direction has no spring on the piece's rows). A row
// reads x up to P rows below it, so a row goes to final_rows (which may change its x) once the rows P above it are
// done: the rows live in f are those the push form keeps (the chunk and P: the same ring).
SpringKernel::Backward SpringKernel::backward(const Segment& seg) const {
  const int start = pattern_start_[seg.pattern], directions = directions_[seg.pattern];
  Backward bw;
  for (int q = 0; q < directions; ++q) {
    const int s = scatter_[start + q], o = offsets_[start + s];
    if (o > seg.owned_reach) continue;
    bw.s[bw.n] = s, bw.offset[bw.n] = o, bw.k[bw.n] = k_[start + s], bw.l0[bw.n] = l0_[start + s], ++bw.n;
  }
  for (int q = bw.n; q < directions; ++q) bw.s[q] = -1, bw.offset[q] = 0, bw.k[q] = 1.0, bw.l0[q] = 0.0;
  bw.full = (1u << bw.n) - 1u;  // n <= 13 (pull_directions)
  return bw;
}

void SpringKernel::pull_bits(const Segment& seg, const Backward& bw, int r0, int n, int* e_back, int& e_own,
                             std::uint32_t* pb, std::uint32_t* pf) const {
  const int directions = directions_[seg.pattern], first = seg.first_molecule, end = first + seg.molecules;
  const StencilException* exceptions = exceptions_.data() + seg.first_exception;
  const int n_exceptions = seg.exceptions;
  std::fill(pb, pb + n, bw.full);
  for (int q = 0; q < bw.n; ++q) {
    const int o = bw.offset[q], s = bw.s[q];
    if (r0 < first + o) {  // no spring: end a below the segment
      for (int i = 0; i < n; ++i) pb[i] &= ~(1u << q);
      continue;
    }
    for (int i = std::max(0, end + o - r0); i < n; ++i) pb[i] &= ~(1u << q);  // end a past the end
    int& e = e_back[q];
    while (e < n_exceptions && exceptions[e].molecule < r0 - o) ++e;
    for (int t = e; t < n_exceptions && exceptions[t].molecule < r0 + n - o; ++t)
      if (!(exceptions[t].present >> s & 1u)) pb[exceptions[t].molecule + o - r0] &= ~(1u << q);
  }
  std::fill(pf, pf + n, (1u << directions) - 1u);
  if (r0 >= end) return;
  while (e_own < n_exceptions && exceptions[e_own].molecule < r0) ++e_own;
  for (int t = e_own; t < n_exceptions && exceptions[t].molecule < r0 + n; ++t)
    pf[exceptions[t].molecule - r0] = exceptions[t].present;
}

void SpringKernel::pull_marks(Segment& seg) {
  const Backward bw = backward(seg);
  const int first = seg.first_molecule, end = first + seg.molecules;
  const int rows_end = std::min(end + (bw.n ? bw.offset[0] : 0), model_.owned);
  const std::uint32_t all = (1u << directions_[seg.pattern]) - 1u;
  seg.first_mark = static_cast<int>(marks_.size());
  int e_back[kPullDirections] = {}, e_own = 0;
  std::uint32_t pb[kForceBlock], pf[kForceBlock];
  for (int r0 = first, n = 0; r0 < rows_end; r0 += n) {
    n = std::min(kForceBlock, rows_end - r0);
    if (r0 < end) n = std::min(n, end - r0);
    for (int q = 0; q < bw.n; ++q)
      if (r0 < first + bw.offset[q]) n = std::min(n, first + bw.offset[q] - r0);
    pull_bits(seg, bw, r0, n, e_back, e_own, pb, pf);
    for (int i = 0; i < n; ++i)
      if (pb[i] != bw.full || pf[i] != all) marks_.push_back({r0 + i, pb[i], pf[i]});
  }
  seg.marks = static_cast<int>(marks_.size()) - seg.first_mark;
}

// The force ring's directions of a pull segment: the nearest backward ones whose offsets lie in [kRingNearest,
// kRingFarthest] (by increasing offset), three of the face-diagonals lattice's (in-plane: N - 1, N, N + 1) and one
// of the rectangular one's (N), when a kernel takes that set (pull_ring_kernel); q: their backward indices, far:
// the largest offset.
bool SpringKernel::pull_ring(const Segment& seg, const Backward& bw, int* q, int& n, int& far) const {
  n = 0, far = 0;
  const int directions = directions_[seg.pattern], most = directions == 9 ? 3 : directions == 3 ? 1 : 0;
  if (pull_ring_rows_.empty()) return false;
  unsigned back = 0, own = 0;
  for (int t = bw.n - 1; t >= 0 && n < most; --t)
    if (bw.offset[t] >= kRingNearest && bw.offset[t] <= kRingFarthest)
      back |= 1u << t, own |= 1u << bw.s[t], far = std::max(far, bw.offset[t]), q[n++] = t;
  return pull_ring_kernel(directions, back, own);
}

int SpringKernel::pull_ring_segments() const {
  int count = 0;
  for (const Segment& seg : segments_) {
    int q[kRingDirections], n = 0, far = 0;
    count += pull_directions(directions_[seg.pattern]) && seg.molecules >= kChunk &&
             pull_ring(seg, backward(seg), q, n, far);
  }
  return count;
}

// A segment in the pull form (pull_body): its rows [first, first + molecules + P) below the owned count, P its
// largest offset to an owned row, in pieces of at most kForceBlock rows (within one turn of a ring, on one side of
// the segment's end and of each first + offset, below which a direction has no spring on the piece's rows). A row
// reads x up to P rows below it, so a row goes to final_rows (which may change its x) once the rows P above it are
// done: the rows live in f are those the push form keeps (the chunk and P: the same ring). The rows whose springs
// are not all present come from the segment's marks (pull_marks), not from its exceptions piece by piece.
template <class Layout, class Finish>
void SpringKernel::pull_segment(const Segment& seg, const double* x, double* f, Layout at, int& zeroed,
                                Finish& finish, const ReadAhead* ahead) const {
  const int p = seg.pattern, start = pattern_start_[p], directions = directions_[p];
  const int* offset = offsets_.data() + start;
  const double *k = k_.data() + start, *l0 = l0_.data() + start;
  const int first = seg.first_molecule, end = first + seg.molecules;
  const Backward bw = backward(seg);
  const int reach = bw.n ? bw.offset[0] : 0, rows_end = std::min(end + reach, model_.owned);
  const std::uint32_t all = (1u << directions) - 1u;
  alignas(64) PullBits pb[kForceBlock], pf[kForceBlock];
  std::fill(pb, pb + kForceBlock, bw.full), std::fill(pf, pf + kForceBlock, all);
  const PullMark *mark = marks_.data() + seg.first_mark, *marks_end = mark + seg.marks;
  int piece_bo[kMaxDirections];
  // The force ring: the in-plane springs computed once, at end a (its own sum stores each force), and read back at
  // end b kRingNearest or more rows later (the live rows, the farthest offset and a piece: ~16 kB at N = 100, in
  // L1), instead of computed again there.
  int ring_base = first, ring_q[kRingDirections], ring_n = 0, ring_far = 0;
  const bool ring = pull_ring_ && pull_ring(seg, bw, ring_q, ring_n, ring_far);
  const double* rb[3 * kMaxDirections] = {};
  double* wf[3 * kMaxDirections] = {};
  double* ring_rows = pull_ring_rows_.data();
  auto handed = [&](int below) { return below >= model_.owned ? model_.owned : below - reach; };
  // Rows past the segment's end that the next segments or generic connections still touch stay live (`later` counts
  // only the generic ones: the push form never hands over a row past a segment's end).
  const int later = std::min(seg.later, &seg + 1 < segments_.data() + segments_.size() ? (&seg + 1)->first_molecule
                                                                                       : seg.later);
  for (int c0 = first; c0 < rows_end; c0 += kChunk) {
    const int c1 = std::min(c0 + kChunk, rows_end);
    for (int r0 = c0, n = 0; r0 < c1; r0 += n) {
      n = at.run(r0, std::min(kForceBlock, c1 - r0));
      const bool own = r0 < end;
      if (own) n = std::min(n, end - r0);
      for (int q = 0; q < bw.n; ++q)
        if (r0 < first + bw.offset[q]) n = std::min(n, first + bw.offset[q] - r0);
      zero_ahead(f, at, zeroed, r0 + n);
      for (int q = 0; q < directions; ++q)  // no spring: end a below the segment (read x at the row itself)
        piece_bo[q] = q >= bw.n || r0 < first + bw.offset[q] ? 0 : bw.offset[q];
      const PullMark* piece_marks = mark;
      for (; mark < marks_end && mark->row < r0 + n; ++mark)
        pb[mark->row - r0] = static_cast<PullBits>(mark->pb), pf[mark->row - r0] = static_cast<PullBits>(mark->pf);
      if (ahead) {  // the rows handed over next (a cache line, 8 rows, at a time)
        const int a0 = std::max(0, r0 - reach), a1 = std::min(r0 + n - reach, ahead->end);
        for (int r = 0; r < ahead->streams; ++r)
          for (int i = a0; i < a1; i += 8) __builtin_prefetch(ahead->rows[r] + i, 0, 2);
      }
      if (ring) {
        if (r0 + n - ring_base > kRingRows) {  // slide: keep the rows the farthest offset still reads
          const int keep = r0 - ring_far;
          for (int c = 0; c < 3 * ring_n; ++c) {
            double* col = ring_rows + static_cast<std::size_t>(c) * kRingRows;
            std::copy(col + (keep - ring_base), col + (r0 - ring_base), col);
          }
          ring_base = keep;
        }
        for (int t = 0; t < ring_n; ++t) {
          const int q = ring_q[t], o = bw.offset[q], s = bw.s[q];
          for (int c = 0; c < 3; ++c) {
            double* col = ring_rows + static_cast<std::size_t>(3 * t + c) * kRingRows;
            rb[3 * q + c] = r0 >= first + o ? col + (r0 - o - ring_base) : kNoRingRows;
            wf[3 * s + c] = col + (r0 - ring_base);
          }
        }
      }
      const PullPiece piece{n,        {x + at(r0, 0), x + at(r0, 1), x + at(r0, 2)},
                            {f + at.f(r0, 0), f + at.f(r0, 1), f + at.f(r0, 2)},
                            piece_bo, offset, bw.k, bw.l0, k, l0, pb, pf, own, rb, wf, ring ? 1 : 0};
      pull_rows(directions, piece);
      for (const PullMark* t = piece_marks; t < mark; ++t) pb[t->row - r0] = bw.full, pf[t->row - r0] = all;
    }
    finish(std::min(handed(c1), later));
  }
  finish(std::min(std::max(end, handed(rows_end)), later));
}

template <class Layout>
void SpringKernel::sweep(const double* x, double* f, Layout at, FinalRows final_rows, void* context,
                         const ReadAhead* ahead) const {
  const LocalModel& m = model_;
  // The ghost rows (scratch, few) now; the owned rows just ahead of their first write (zero_ahead).
  at.zero(f, m.owned, m.local);
  int zeroed = 0;
  // Each of k and l0 is per connection or by type (partition/connection_table.hpp).
  const ConnectionColumn kc = m.table.stiffness_column(), lc = m.table.rest_length_column();
  const std::uint16_t *ktype = kc.type, *ltype = lc.type;
  const double *ks = kc.value, *ls = lc.value;
  // Generic connections [c0, c1): from the model's arrays, or (ends stored as runs) from this kernel's copies of
  // their ends starting at `from`, the same connections in the same order.
  auto generic = [&](int c0, int c1, int from) {
    if (m.end_a.plain()) {
      generic_forces(c0, c1, m.end_a.data(), m.end_b.data(), ktype, ltype, ks, ls, x, f, at);
      return;
    }
    generic_forces(0, c1 - c0, generic_a_.data() + from, generic_b_.data() + from, ktype ? ktype + c0 : nullptr,
                   ltype ? ltype + c0 : nullptr, ktype ? ks : ks + c0, ltype ? ls : ls + c0, x, f, at);
  };
  // Owned rows below `done` went to final_rows; rows below `below` are final (no connection still to come
  // touches them).
  int done = 0;
  auto finish = [&](int below) {
    below = std::min(below, m.owned);
    if (!final_rows || below <= done) return;
    zero_ahead(f, at, zeroed, below);  // rows no connection touches are final too: zero
    for (int len = 0; done < below; done += len) {  // each run within one turn of a ring
      len = at.run(done, below - done);
      final_rows(context, done, done + len);
    }
  };
  // With final_rows, a segment goes in chunks so that a chunk's rows are handed over while still in cache (a
  // row is final once the sweep passed it as end a: it is end b only of lower ends a). The chunks keep the
  // blocks of kForceBlock molecules, and no block boundary changes a bit anyway.
  int c = 0;
  for (const Segment& seg : segments_) {
    if (c < seg.first_connection) {
      zero_ahead(f, at, zeroed, seg.generic_reach);
      generic(c, seg.first_connection, seg.generic_at);
      finish(std::min(seg.first_molecule, seg.later));
    }
    const int p = seg.pattern, start = pattern_start_[p];
    if constexpr (!std::is_same_v<Layout, Interlaced>) {
      if (pull_ && pull_directions(directions_[p]) && seg.molecules >= kChunk) {
        pull_segment(seg, x, f, at, zeroed, finish, ahead);
        c = seg.first_connection + seg.connections;
        continue;
      }
    }
    const StencilException* exceptions = exceptions_.data() + seg.first_exception;
    const int chunk = final_rows ? kChunk : seg.molecules;
    for (int m0 = 0, e0 = 0; m0 < seg.molecules; m0 += chunk) {
      const int count = std::min(chunk, seg.molecules - m0), end = seg.first_molecule + m0 + count;
      int e1 = e0;
      while (e1 < seg.exceptions && exceptions[e1].molecule < end) ++e1;
      stencil_forces(seg.first_molecule + m0, count, directions_[p], offsets_.data() + start, scatter_.data() + start,
                     k_.data() + start, l0_.data() + start, exceptions + e0, e1 - e0, x, f, at, m.owned, seg.owned_reach,
                     &zeroed, ahead);
      e0 = e1;
      finish(std::min(end, seg.later));
    }
    c = seg.first_connection + seg.connections;
  }
  if (c < m.connections()) {
    zero_ahead(f, at, zeroed, tail_reach_);
    generic(c, m.connections(), tail_at_);
  }
  zero_ahead(f, at, zeroed, m.owned);
  finish(m.owned);
}

template <class Stencil>
void SpringKernel::tangent_sweep(const double* x, const double* u, double* out, double* ghost, FinalRows final_rows,
                                 void* context, Stencil stencil) const {
  const LocalModel& m = model_;
  std::fill(ghost, ghost + 3 * static_cast<std::size_t>(m.local - m.owned), 0.0);
  int zeroed = 0;  // out's rows below it are zeroed (just ahead of their first write, as in forces())
  const ConnectionColumn kc = m.table.stiffness_column(), lc = m.table.rest_length_column();
  auto generic = [&](int c0, int c1, int at) {
    if (m.end_a.plain()) {
      generic_tangent(c0, c1, m.end_a.data(), m.end_b.data(), kc.type, lc.type, kc.value, lc.value, x, u, out, ghost,
                      m.owned);
      return;
    }
    generic_tangent(0, c1 - c0, generic_a_.data() + at, generic_b_.data() + at, kc.type ? kc.type + c0 : nullptr,
                    lc.type ? lc.type + c0 : nullptr, kc.type ? kc.value : kc.value + c0,
                    lc.type ? lc.value : lc.value + c0, x, u, out, ghost, m.owned);
  };
  // Owned rows below `done` went to final_rows (sweep()'s push form: a row is final once the sweep passed it as
  // end a, unless a later generic connection touches it).
  int done = 0;
  auto finish = [&](int below) {
    below = std::min(below, m.owned);
    if (!final_rows || below <= done) return;
    zero_ahead(out, Interlaced{}, zeroed, below);
    final_rows(context, done, below);
    done = below;
  };
  int c = 0;
  for (std::size_t q = 0; q < segments_.size(); ++q) {
    const Segment& seg = segments_[q];
    if (c < seg.first_connection) {
      zero_ahead(out, Interlaced{}, zeroed, seg.generic_reach);
      generic(c, seg.first_connection, seg.generic_at);
      finish(std::min(seg.first_molecule, seg.later));
    }
    const StencilException* exceptions = exceptions_.data() + seg.first_exception;
    const int chunk = final_rows ? kChunk : seg.molecules;  // a multiple of the blocks: the same blocks
    for (int m0 = 0, e0 = 0; m0 < seg.molecules; m0 += chunk) {
      const int count = std::min(chunk, seg.molecules - m0), end = seg.first_molecule + m0 + count;
      int e1 = e0;
      while (e1 < seg.exceptions && exceptions[e1].molecule < end) ++e1;
      stencil(q, seg.first_molecule + m0, count, exceptions + e0, e1 - e0, &zeroed);
      e0 = e1;
      finish(std::min(end, seg.later));
    }
    c = seg.first_connection + seg.connections;
  }
  if (c < m.connections()) {
    zero_ahead(out, Interlaced{}, zeroed, tail_reach_);
    generic(c, m.connections(), tail_at_);
  }
  zero_ahead(out, Interlaced{}, zeroed, m.owned);
  finish(m.owned);
}

namespace {
// One direction of energy_and_shortest's block: end a's rows [a0, a0 + n) to a0 + offset; x interlaced (stride 0:
// component c of row i at [3 i + c]) or as three streams ([c * stride + i]).
TISSUE_CLONES
void energy_direction(int n, const double* __restrict xa, const double* __restrict xb, std::size_t stride, double k,
                      double l0, double* __restrict energy, double* __restrict ratio) {
  if (stride) {
    const double *a1 = xa + stride, *a2 = xa + 2 * stride, *b1 = xb + stride, *b2 = xb + 2 * stride;
    for (int i = 0; i < n; ++i) {
      const double d0 = xb[i] - xa[i], d1 = b1[i] - a1[i], d2 = b2[i] - a2[i];
      const double length = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2), stretch = length - l0;
      energy[i] = 0.5 * k * stretch * stretch;
      ratio[i] = length / l0;
    }
    return;
  }
  for (int i = 0; i < n; ++i) {
    const double d0 = xb[3 * i] - xa[3 * i], d1 = xb[3 * i + 1] - xa[3 * i + 1], d2 = xb[3 * i + 2] - xa[3 * i + 2];
    const double length = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2), stretch = length - l0;
    energy[i] = 0.5 * k * stretch * stretch;
    ratio[i] = length / l0;
  }
}
// A block's energies and ratios into 8 lanes (sums; smallest ratios, a NaN never taken): independent chains, where
// one running sum and minimum were a chain of dependent operations a connection.
constexpr int kLanes = 8;
TISSUE_CLONES
void accumulate_lanes(int n, const double* __restrict energy, const double* __restrict ratio,
                      double* __restrict sums, double* __restrict smallest) {
  int i = 0;
  for (; i + kLanes <= n; i += kLanes)
    for (int j = 0; j < kLanes; ++j) {
      sums[j] += energy[i + j];
      smallest[j] = ratio[i + j] < smallest[j] ? ratio[i + j] : smallest[j];
    }
  for (; i < n; ++i) {
    sums[0] += energy[i];
    smallest[0] = ratio[i] < smallest[0] ? ratio[i] : smallest[0];
  }
}
}  // namespace

void SpringKernel::energy_and_shortest(const double* x, double* energy, double* shortest, std::size_t streams) const {
  const LocalModel& m = model_;
  const int owned = m.owned;
  const ConnectionColumn kc = m.table.stiffness_column(), lc = m.table.rest_length_column();
  double e = 0, w = std::numeric_limits<double>::infinity();
  // component c of row i; a row's start (xa below): interlaced 3 i, streams i
  const Components at{x, streams};
  const std::size_t row = streams ? 1 : 3;
  auto spring = [&](int c, int a, int b) {  // LocalModel::for_each_written's connection, as the guard computes it
    if (a >= owned) return;
    const double d0 = at(b, 0) - at(a, 0), d1 = at(b, 1) - at(a, 1), d2 = at(b, 2) - at(a, 2);
    const double length = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2), l0 = lc[c], stretch = length - l0;
    e += 0.5 * kc[c] * stretch * stretch;
    const double ratio = length / l0;
    if (ratio < w) w = ratio;
  };
  auto generic = [&](int c0, int c1, int at) {
    if (m.end_a.plain()) {
      for (int c = c0; c < c1; ++c) spring(c, m.end_a.data()[c], m.end_b.data()[c]);
      return;
    }
    for (int c = c0; c < c1; ++c) spring(c, generic_a_[at + c - c0], generic_b_[at + c - c0]);
  };
  alignas(64) double en[kStencilBlock], ra[kStencilBlock], sums[kLanes] = {}, smallest[kLanes];
  std::fill(smallest, smallest + kLanes, std::numeric_limits<double>::infinity());
  int c = 0;
  for (const Segment& seg : segments_) {
    if (c < seg.first_connection) generic(c, seg.first_connection, seg.generic_at);
    const int p = seg.pattern, start = pattern_start_[p], directions = directions_[p];
    const StencilException* exceptions = exceptions_.data() + seg.first_exception;
    const int last = std::min(seg.first_molecule + seg.molecules, owned);
    int e0 = 0;
    for (int a0 = seg.first_molecule; a0 < last; a0 += kStencilBlock) {
      const int n = std::min(kStencilBlock, last - a0);
      int e1 = e0;
      while (e1 < seg.exceptions && exceptions[e1].molecule < a0 + n) ++e1;
      for (int s = 0; s < directions; ++s) {
        const double* xa = x + row * static_cast<std::size_t>(a0);
        energy_direction(n, xa, xa + static_cast<std::ptrdiff_t>(row) * offsets_[start + s], streams, k_[start + s],
                         l0_[start + s], en, ra);
        for (int q = e0; q < e1; ++q)  // a molecule without this direction: no spring
          if (!(exceptions[q].present >> s & 1u)) {
            const int i = exceptions[q].molecule - a0;
            en[i] = 0.0, ra[i] = std::numeric_limits<double>::infinity();
          }
        accumulate_lanes(n, en, ra, sums, smallest);
      }
      e0 = e1;
    }
    c = seg.first_connection + seg.connections;
  }
  if (c < m.connections()) generic(c, m.connections(), tail_at_);
  for (int j = 0; j < kLanes; ++j) e += sums[j], w = smallest[j] < w ? smallest[j] : w;  // the lanes in a fixed order
  *energy = e, *shortest = w;
}

void SpringKernel::tangent(const double* x, const double* u, double* out, double* ghost, FinalRows final_rows,
                           void* context) const {
  tangent_sweep(x, u, out, ghost, final_rows, context,
                [&](std::size_t q, int first, int count, const StencilException* exceptions, int n, int* zeroed) {
                  const int p = segments_[q].pattern, start = pattern_start_[p];
                  stencil_tangent(first, count, directions_[p], offsets_.data() + start, scatter_.data() + start,
                                  k_.data() + start, l0_.data() + start, exceptions, n, x, u, out, ghost,
                                  model_.owned, reach_[p], zeroed);
                });
}

void SpringKernel::rest_tangent(const RestStencil& rest, const double* u, double* out, double* ghost,
                                FinalRows final_rows, void* context) const {
  if (rest.pull) {  // every owned row from its own springs; the ghosts' rows are not needed (their owners')
    rest.pull->apply(u, out, final_rows, context);
    return;
  }
  tangent_sweep(model_.rest.data(), u, out, ghost, final_rows, context,
                [&](std::size_t q, int first, int count, const StencilException* exceptions, int n, int* zeroed) {
                  const int p = segments_[q].pattern, start = pattern_start_[p];
                  stencil_rest_tangent(first, count, directions_[p], offsets_.data() + start,
                                       scatter_.data() + start, rest.a.data() + 3 * rest.first[q], exceptions, n, u,
                                       out, ghost, model_.owned, reach_[p], zeroed);
                });
}

RestStencil SpringKernel::rest_stencil() const {
  RestStencil rest;
  rest.exact = true;
  const double* X = model_.rest.data();
  constexpr double kTolerance = 1e-12;
  for (const Segment& seg : segments_) {
    const int p = seg.pattern, start = pattern_start_[p], directions = directions_[p];
    rest.first.push_back(static_cast<int>(rest.a.size() / 3));
    const StencilException* exceptions = exceptions_.data() + seg.first_exception;
    for (int s = 0; s < directions; ++s) {
      // The direction's first spring, then every other checked against it.
      double d[3] = {0.0, 0.0, 0.0};
      bool found = false;
      for (int i = 0, e = 0; i < seg.molecules; ++i) {
        const int a = seg.first_molecule + i;
        while (e < seg.exceptions && exceptions[e].molecule < a) ++e;
        if (e < seg.exceptions && exceptions[e].molecule == a && !(exceptions[e].present >> s & 1u)) continue;
        const int b = a + offsets_[start + s];
        double v[3];
        for (int r = 0; r < 3; ++r) v[r] = X[3 * b + r] - X[3 * a + r];
        if (!found) {
          for (int r = 0; r < 3; ++r) d[r] = v[r];
          found = true;
          const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
          if (!(std::abs(len - l0_[start + s]) <= kTolerance * l0_[start + s])) rest.exact = false;
        }
        const double scale = kTolerance * l0_[start + s];
        for (int r = 0; r < 3; ++r)
          if (!(std::abs(v[r] - d[r]) <= scale)) rest.exact = false;
      }
      const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), k = k_[start + s];
      for (int r = 0; r < 3; ++r) rest.a.push_back(found && len > 0 ? std::sqrt(k) * d[r] / len : 0.0);
    }
  }
  return rest;
}

}  // namespace tissue
