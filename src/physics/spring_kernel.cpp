#include "src/physics/spring_kernel.hpp"

#include <algorithm>
#include <cmath>

namespace tissue {

namespace {

// Each kernel is compiled for AVX-512, AVX2 and the baseline, and the loader picks the best the CPU has: the
// square roots and divisions are the slow instructions, and wider vectors do more of them at once. IEEE sqrt and
// division round the same at any width, and fused multiply-adds are off (CMakeLists.txt), so every clone gives
// the same bits.
#define TISSUE_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))

// Generic: connections [begin, end) of any list, sorted by end a. k comes through the type table ks when
// `ktype` is given, else per connection; l0 likewise through `ltype` and ls.
//
// Three passes over blocks of connections small enough to stay in L1: (1) gather the separation vectors and
// k, l0; (2) the square root and the division, a plain loop the compiler vectorizes; (3) scatter the forces. The
// force on end a is summed in registers over its run of connections and stored once. A block never splits a run
// of the same end a: where the runs end does not depend on the partition, where a block ends does, and a split
// run would sum the force on a in another grouping.
TISSUE_CLONES
void generic_forces(int begin_c, int end_c, const int* a, const int* b, const std::uint16_t* ktype,
                    const std::uint16_t* ltype, const double* ks, const double* ls, const double* x, double* f) {
  constexpr int kBlock = 256;
  alignas(64) double d0[kBlock], d1[kBlock], d2[kBlock], k[kBlock], l0[kBlock], s[kBlock];
  for (int begin = begin_c, n = 0; begin < end_c; begin += n) {
    n = std::min(kBlock, end_c - begin);
    if (begin + n < end_c)
      while (n > 1 && a[begin + n] == a[begin + n - 1]) --n;
    for (int i = 0; i < n; ++i) {
      const int c = begin + i;
      const double* xa = x + 3 * a[c];
      const double* xb = x + 3 * b[c];
      d0[i] = xb[0] - xa[0], d1[i] = xb[1] - xa[1], d2[i] = xb[2] - xa[2];
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
        double* fb = f + 3 * b[begin + i];
        fb[0] -= g0, fb[1] -= g1, fb[2] -= g2;
      }
      double* fa = f + 3 * ia;
      fa[0] += fa0, fa[1] += fa1, fa[2] += fa2;
    }
  }
}

constexpr int kMaxDirections = 32, kStencilBlock = 64;

// A stencil segment: molecules first .. first + count - 1, each with `directions` forward connections to the
// molecule `offset[s]` further on (every offset > 0), of constants k[s], l0[s]. `scatter` lists the directions
// by decreasing offset: within a block of molecules, a molecule that receives forces from two directions then
// gets them from the lower end a first, as the generic kernel (the connection order) adds them. Each molecule's
// own sum runs over its directions in connection order, and is added after every force it receives as end b
// from the block (all from lower ends a: offsets are positive), again as the generic kernel does.
//
// f's owned rows are zeroed just ahead of the block that first writes them (`zeroed`: rows below it are zeroed;
// a block writes rows up to a0 + n - 1 + max_offset): a row then comes to the kernel from the cache, written
// back once, instead of a separate pass over memory before the kernel (docs/benchmarks.md).
TISSUE_CLONES
void stencil_forces(int first, int count, int directions, const int* offset, const int* scatter, const double* k,
                    const double* l0, const double* __restrict x, double* __restrict f, int owned, int max_offset,
                    int* zeroed) {
  alignas(64) double g[kMaxDirections][3][kStencilBlock];
  for (int a0 = first; a0 < first + count; a0 += kStencilBlock) {
    const int n = std::min(kStencilBlock, first + count - a0);
    const int reach = std::min(owned, a0 + n + max_offset);
    if (reach > *zeroed) {
      std::fill(f + 3 * static_cast<std::size_t>(*zeroed), f + 3 * static_cast<std::size_t>(reach), 0.0);
      *zeroed = reach;
    }
    const double* __restrict xa = x + 3 * a0;
    for (int q = 0; q < directions; ++q) {
      const int s = scatter[q];
      const double* __restrict xb = x + 3 * (a0 + offset[s]);
      double* __restrict fb = f + 3 * (a0 + offset[s]);
      double* __restrict g0 = g[s][0];
      double* __restrict g1 = g[s][1];
      double* __restrict g2 = g[s][2];
      const double ks = k[s], ls = l0[s];
      for (int i = 0; i < n; ++i) {
        const double d0 = xb[3 * i] - xa[3 * i], d1 = xb[3 * i + 1] - xa[3 * i + 1], d2 = xb[3 * i + 2] - xa[3 * i + 2];
        const double len = std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
        const double sc = ks * (len - ls) / len;
        const double e0 = sc * d0, e1 = sc * d1, e2 = sc * d2;
        fb[3 * i] -= e0, fb[3 * i + 1] -= e1, fb[3 * i + 2] -= e2;
        g0[i] = e0, g1[i] = e1, g2[i] = e2;
      }
    }
    // Each molecule's sum over its directions in order, vectorized across molecules.
    alignas(64) double s0[kStencilBlock] = {}, s1[kStencilBlock] = {}, s2[kStencilBlock] = {};
    for (int s = 0; s < directions; ++s)
      for (int i = 0; i < n; ++i) s0[i] += g[s][0][i], s1[i] += g[s][1][i], s2[i] += g[s][2][i];
    double* __restrict fa = f + 3 * a0;
    for (int i = 0; i < n; ++i) fa[3 * i] += s0[i], fa[3 * i + 1] += s1[i], fa[3 * i + 2] += s2[i];
  }
}

}  // namespace

SpringKernel::SpringKernel(const LocalModel& model) : model_(model) {
  const int nc = model.connections();
  const ConnectionEnd& a = model.end_a;  // indexed as arrays; runs (ConnectionEnd) give the same values
  const ConnectionEnd& b = model.end_b;
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
  // Runs of the same end a; consecutive runs of consecutive molecules with one pattern form a segment.
  auto run_end = [&](int c) {
    int e = c + 1;
    while (e < nc && a[e] == a[c]) ++e;
    return e;
  };
  auto same_pattern = [&](int c, int d, int len) {
    for (int s = 0; s < len; ++s)
      if (a[d + s] != a[d] || b[c + s] - a[c] != b[d + s] - a[d] || type[c + s] != type[d + s]) return false;
    return true;
  };
  auto usable = [&](int c, int len) {
    if (len > kMaxDirections) return false;
    for (int s = 0; s < len; ++s)
      if (b[c + s] <= a[c]) return false;
    return true;
  };
  // The owned rows of f that generic connections [c0, c1) write: below the returned index.
  const int owned = model.owned;
  auto reach_of = [&](int c0, int c1) {
    int reach = 0;
    for (int c = c0; c < c1; ++c) {
      if (a[c] < owned) reach = std::max(reach, a[c] + 1);
      if (b[c] < owned) reach = std::max(reach, b[c] + 1);
    }
    return reach;
  };
  int generic_begin = 0;
  constexpr int kShortest = 4;  // shorter runs of molecules stay generic
  for (int c = 0; c < nc;) {
    const int e = run_end(c), len = e - c;
    int molecules = 1, next = e;
    if (usable(c, len))
      while (next < nc && a[next] == a[c] + molecules && next + len <= nc && same_pattern(c, next, len) &&
             (next + len == nc || a[next + len] != a[next])) {
        ++molecules;
        next += len;
      }
    if (molecules < kShortest) {
      c = e;
      continue;
    }
    // A new pattern, or the last one again (a lattice's rows repeat theirs).
    int pattern = static_cast<int>(directions_.size());
    if (!segments_.empty()) {
      const Segment& last = segments_.back();
      const int p = last.pattern;
      bool same = directions_[p] == len;
      for (int s = 0; same && s < len; ++s)
        same = offsets_[pattern_start_[p] + s] == b[c + s] - a[c] && types_[pattern_start_[p] + s] == type[c + s];
      if (same) pattern = p;
    }
    if (pattern == static_cast<int>(directions_.size())) {
      const int start = static_cast<int>(offsets_.size());
      pattern_start_.push_back(start);
      directions_.push_back(len);
      for (int s = 0; s < len; ++s) {
        offsets_.push_back(b[c + s] - a[c]), types_.push_back(type[c + s]);
        k_.push_back(kc.value[type[c + s]]), l0_.push_back(lc.value[type[c + s]]);
        scatter_.push_back(s);
      }
      reach_.push_back(*std::max_element(offsets_.begin() + start, offsets_.end()));
      std::sort(scatter_.begin() + start, scatter_.end(),
                [&](int s, int t) { return offsets_[start + s] > offsets_[start + t]; });
    }
    segments_.push_back({c, a[c], molecules, pattern, reach_of(generic_begin, c), keep_generic(generic_begin, c)});
    structured_ += static_cast<long>(molecules) * len;
    c = next;
    generic_begin = c;
  }
  tail_reach_ = reach_of(generic_begin, nc);
  tail_at_ = keep_generic(generic_begin, nc);
  generic_a_.shrink_to_fit(), generic_b_.shrink_to_fit();
}

void SpringKernel::zero_ahead(double* f, int& zeroed, int reach) const {
  reach = std::min(reach, model_.owned);
  if (reach <= zeroed) return;
  std::fill(f + 3 * static_cast<std::size_t>(zeroed), f + 3 * static_cast<std::size_t>(reach), 0.0);
  zeroed = reach;
}

void SpringKernel::forces(const double* x, double* f) const {
  const LocalModel& m = model_;
  // The ghost rows (scratch, few) now; the owned rows just ahead of their first write (zero_ahead).
  std::fill(f + 3 * static_cast<std::size_t>(m.owned), f + 3 * static_cast<std::size_t>(m.local), 0.0);
  int zeroed = 0;
  // Each of k and l0 is per connection or by type (partition/connection_table.hpp).
  const ConnectionColumn kc = m.table.stiffness_column(), lc = m.table.rest_length_column();
  const std::uint16_t *ktype = kc.type, *ltype = lc.type;
  const double *ks = kc.value, *ls = lc.value;
  // Generic connections [c0, c1): from the model's arrays, or (ends stored as runs) from this kernel's copies of
  // their ends starting at `at`, the same connections in the same order.
  auto generic = [&](int c0, int c1, int at) {
    if (m.end_a.plain()) {
      generic_forces(c0, c1, m.end_a.data(), m.end_b.data(), ktype, ltype, ks, ls, x, f);
      return;
    }
    generic_forces(0, c1 - c0, generic_a_.data() + at, generic_b_.data() + at, ktype ? ktype + c0 : nullptr,
                   ltype ? ltype + c0 : nullptr, ktype ? ks : ks + c0, ltype ? ls : ls + c0, x, f);
  };
  int c = 0;
  for (const Segment& seg : segments_) {
    if (c < seg.first_connection) {
      zero_ahead(f, zeroed, seg.generic_reach);
      generic(c, seg.first_connection, seg.generic_at);
    }
    const int p = seg.pattern, start = pattern_start_[p];
    stencil_forces(seg.first_molecule, seg.molecules, directions_[p], offsets_.data() + start,
                   scatter_.data() + start, k_.data() + start, l0_.data() + start, x, f, m.owned, reach_[p], &zeroed);
    c = seg.first_connection + seg.molecules * directions_[p];
  }
  if (c < m.connections()) {
    zero_ahead(f, zeroed, tail_reach_);
    generic(c, m.connections(), tail_at_);
  }
  zero_ahead(f, zeroed, m.owned);
}

}  // namespace tissue
