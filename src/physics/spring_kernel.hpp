// The connection-force kernel (F_C of Eq. 2: k (l - l0) along the current direction, on both ends), in two
// forms that give bit-identical forces:
//   - generic: any connection list (gather, vectorized sqrt and division, scatter; blocks of 256);
//   - stencil segments: runs of consecutive local molecules whose forward connections all follow one pattern
//     (the same local offsets end b - end a and the same connection types), as a lattice's rows do on any
//     partition. There end b is end a plus a fixed offset, so each direction is a contiguous stream with no
//     index arrays and k, l0 are constants: the compiler vectorizes it (AVX2 / AVX-512 clones, picked at run time).
//     A molecule that lacks some of the pattern's directions (a box's row ends, faces and edges) stays in the
//     segment as an exception: its missing directions give a force of +0.0, which leaves every sum's bits as
//     they are, so a segment spans whole planes of a box instead of a row between two row ends.
// The stencil form comes in two shapes with the same bits: push (each spring once, subtracted from end b's row and
// summed into end a's) and, for the explicit solver's streams and ring, pull (each row's springs from both ends summed
// in registers, the row written once; every spring computed twice).
// Both sum every molecule's force in the same order (connections on it as end b by increasing end a, then the
// sum of its own forward connections by increasing end b: the order of the global connection list), with no
// fused multiply-add, so forces do not depend on which form ran, nor on the partition.
#pragma once
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "partition/local_model.hpp"

namespace tissue {

class RestPull;  // src/physics/rest_pull.hpp

// Where component d (x, y, z) of local molecule i sits in a position or force array: interlaced, as PETSc's blocks
// hold it (x[3 i + d]), or as three streams, a structure of arrays (x[d * stride + i], stride >= the local
// molecules), which the explicit solver's fused step keeps between steps (src/solvers/dynamic.cpp).
// A layout maps x (operator()) and f (f(), zero(), and run(r, n): how many of rows r .. r + n - 1 lie contiguous in
// f from row r on); the first two use one map for both.
struct Interlaced {
  std::size_t operator()(int i, int d) const { return 3 * static_cast<std::size_t>(i) + d; }
  std::size_t f(int i, int d) const { return (*this)(i, d); }
  int run(int, int n) const { return n; }
  void zero(double* f, int begin, int end) const { std::fill(f + (*this)(begin, 0), f + (*this)(end, 0), 0.0); }
};
struct Streams {
  std::size_t stride;
  std::size_t operator()(int i, int d) const { return d * stride + static_cast<std::size_t>(i); }
  std::size_t f(int i, int d) const { return (*this)(i, d); }
  int run(int, int n) const { return n; }
  void zero(double* f, int begin, int end) const {
    for (int d = 0; d < 3; ++d) std::fill(f + (*this)(begin, d), f + (*this)(end, d), 0.0);
  }
};
// x as three streams (stride), f as three rings of `rows` rows (a power of two) for the owned molecules, row i at
// i mod rows, then the ghosts' rows (scratch) as three streams of `ghosts`: the sweep holds only a window of f's rows
// live (zeroed, not yet handed to FinalRows; SpringKernel::ring_rows), so f stays in cache and never goes to memory.
struct RingStreams {
  std::size_t stride, rows, ghosts;
  int owned;
  std::size_t operator()(int i, int d) const { return d * stride + static_cast<std::size_t>(i); }
  std::size_t f(int i, int d) const {
    return i < owned ? d * rows + (static_cast<std::size_t>(i) & (rows - 1))
                     : 3 * rows + d * ghosts + static_cast<std::size_t>(i - owned);
  }
  int run(int r, int n) const {
    if (r >= owned) return n;
    const long to_wrap = static_cast<long>(rows - (static_cast<std::size_t>(r) & (rows - 1)));
    return static_cast<int>(std::min<long>({static_cast<long>(n), to_wrap, static_cast<long>(owned - r)}));
  }
  void zero(double* f, int begin, int end) const {
    for (int r = begin; r < end;) {
      const int len = run(r, end - r);
      for (int d = 0; d < 3; ++d) std::fill(f + this->f(r, d), f + this->f(r, d) + len, 0.0);
      r += len;
    }
  }
};

// Component d of molecule i of a position, velocity or force array in either of those layouts, read: stride 0 for
// interlaced (a[3 i + d]), else the streams' stride (a[d * stride + i]); SolverState::x_streams gives it.
struct Components {
  const double* a;
  std::size_t stride;
  double operator()(std::size_t i, int d) const { return stride ? a[d * stride + i] : a[3 * i + d]; }
};

// Streams of one double a row that the FinalRows callback reads (the kicks' velocities and masses): the stencil
// kernel asks for each block's rows of them as it computes that block, so that they come from memory while it
// computes, not when the callback reads them (hints only: nothing changes but when the memory is read).
struct ReadAhead {
  static constexpr int kStreams = 4;
  const double* rows[kStreams] = {};
  int streams = 0;
  int end = 0;  // each stream has rows [0, end)
};

// A stencil segment's molecule that lacks some of the pattern's directions.
struct StencilException {
  int molecule;
  std::uint32_t present;  // bit s: the molecule has the pattern's direction s
};

// The connections' tangent at the rest positions as constants (SpringKernel::rest_stencil): per stencil segment and
// direction of its pattern, K = k n n^T = a a^T (a = sqrt(k) n) with n the direction's unit vector at rest, the same
// for every spring of the direction. At rest l = l0, so the geometric part k (1 - l0 / l) (I - n n^T) is zero, and
// the product needs neither the positions nor a square root or a division: e = (a . (u_a - u_b)) a.
struct RestStencil {
  std::vector<double> a;   // 3 per segment direction, segments in order, each its pattern's directions in order
  std::vector<int> first;  // per segment: its first direction's index (a + 3 * index)
  // Every stencil spring's rest separation is its direction's and its length its l0, to 1e-12 relative (a lattice
  // at rest): otherwise the constants are not the tangent at rest, and rest_tangent must not be used.
  bool exact = false;
  // Set (src/solvers/rest_tangent.cpp): rest_tangent's owned rows in the pull form, each row's springs summed once.
  std::shared_ptr<const RestPull> pull;
};

class SpringKernel {
public:
  // Finds the stencil segments when the model's connections are typed (k, l0 final); otherwise all generic.
  explicit SpringKernel(const LocalModel& model);
  // Called with owned rows [begin, end) whose forces are final (no connection still to come touches them), in
  // increasing order, each row once, [0, owned) in all, during forces(): the caller may change those rows of
  // x (and anything else) as soon as it is called.
  using FinalRows = void (*)(void* context, int begin, int end);
  // f: 3 * local values, zeroed here; the forces on ghosts are partial (scratch).
  void forces(const double* x, double* f) const { forces(x, f, nullptr, nullptr); }
  void forces(const double* x, double* f, FinalRows final_rows, void* context) const;
  // The same forces, bit for bit, with x and f as three streams each (Streams: x[d * stride + i]).
  void forces_streams(const double* x, double* f, std::size_t stride, FinalRows final_rows, void* context,
                      const ReadAhead* ahead = nullptr) const;
  // The same forces into a ring (RingStreams: 3 * ring_rows() values, then 3 * (local - owned) for the ghosts'
  // rows), with final_rows (required): each run it hands over lies within one turn of the ring (f's row begin
  // at ring[d * ring_rows() + begin % ring_rows()]); a row's forces are there until the call returns.
  void forces_ring(const double* x, double* ring, std::size_t stride, FinalRows final_rows, void* context,
                   const ReadAhead* ahead = nullptr) const;
  // The ring's rows: a power of two that holds every row between the lowest one not yet handed over and the
  // highest zeroed at any point of the sweep; 0 when no small ring does (forces_ring unusable).
  int ring_rows() const { return ring_rows_; }
  // Connections handled by stencil segments (the rest go through the generic form).
  long structured_connections() const { return structured_; }
  // Whether forces_streams and forces_ring sum a long segment's rows in the pull form (each row's springs from
  // both of its ends, the row written once) or in the push form (each spring once, added to both ends' rows):
  // the same bits either way; the pull form is the default (docs/benchmarks.md), the push form kept for tests.
  void set_pull(bool on) { pull_ = on; }
  // Whether the pull form reads a lattice's in-plane springs from a ring of the forces their end a computed (each
  // computed once) or computes them again at end b: the same bits either way; on by default, off for tests.
  void set_pull_ring(bool on) { pull_ring_ = on; }
  // How many segments the pull form sums with the force ring (when on).
  int pull_ring_segments() const;
  // The connections' tangent applied to u (the matrix-free Newton tangent's springs, ForceModel::apply_tangent):
  // each connection's K (u_a - u_b) added to end a's row and subtracted from end b's, K = k [n n^T + (1 - l0/l)
  // (I - n n^T)] at x (local, ghosts up to date), on the same segments as forces(): per direction a constant k
  // and l0 and contiguous streams, the square root and division vectorized. out: 3 * owned values (zeroed here);
  // ghost: 3 * (local - owned) values of scratch for the ghosts' rows (their owners compute those).
  // With final_rows, out's owned rows are handed over as they become final (as forces() does; chunks of the same
  // blocks, the same bits), so that a term can add its part while they are in cache (the cell term's product).
  void tangent(const double* x, const double* u, double* out, double* ghost, FinalRows final_rows = nullptr,
               void* context = nullptr) const;
  // The guards' pass over the connections whose end a is owned (LocalModel::for_each_written's): the sum of their
  // energies k (l - l0)^2 / 2 (in another order than that walk's: the last bits may differ) and their smallest
  // l / l0 (the same double as that walk's: l and the ratio computed as there; non-finite ratios skipped as there),
  // on the stencil segments (per direction a constant k and l0, contiguous rows) and the generic connections.
  // streams: 0 (x interlaced) or the stride of x's three streams (the dynamic solver's layout between steps): the
  // same doubles either way.
  void energy_and_shortest(const double* x, double* energy, double* shortest, std::size_t streams = 0) const;
  // The constants of the tangent at the rest positions (model.rest), found from the first spring of each segment's
  // direction and checked against every other (RestStencil::exact).
  RestStencil rest_stencil() const;
  // tangent() at the rest positions from those constants (the generic connections, a lattice's row ends, from the
  // rest positions as tangent() computes them): the same rows, handed over in the same chunks; equal to tangent()
  // at x = rest to round-off (the geometric part's 1 - l0 / l of order 1e-16 is left out).
  void rest_tangent(const RestStencil& rest, const double* u, double* out, double* ghost,
                    FinalRows final_rows = nullptr, void* context = nullptr) const;

private:
  struct Segment {
    int first_connection, connections;                // its connections [first_connection, + connections)
    int first_molecule, molecules;                    // molecules [first_molecule, + molecules), local indices
    int pattern;                                      // index into offsets_ / types_ (directions_ entries each)
    int generic_reach;  // the generic connections before it: 1 + the highest owned molecule they write
    int generic_at;     // ends stored as runs (ConnectionEnd): where those connections' ends start in generic_a_
    int first_exception, exceptions;  // its molecules that lack directions: exceptions_[first, + exceptions)
    int later;                        // the lowest row a connection after it touches
    // Its largest offset to an owned row (the owned rows of f a block writes: up to its last molecule + this).
    // A direction into the ghosts' rows (the partition's cut: an offset of about the owned count) writes owned
    // rows only where a molecule lacks it (+0.0, which leaves any value's bits as they are), so the sweep need not
    // zero that far ahead: zeroing to the pattern's largest offset would keep every owned row live at once and
    // leave the rank without a ring (ring_rows).
    int owned_reach;
    // The pull form's rows whose springs are not all present (pull_marks_): marks_[first_mark, + marks).
    int first_mark = 0, marks = 0;
  };
  // A row of a pull segment whose backward springs (pb: bit q for the q-th by decreasing offset) or own forward
  // springs (pf: bit s) are not all present; every other row has them all (the segment's Backward::full and all
  // directions' bits).
  struct PullMark {
    int row;
    std::uint32_t pb, pf;
  };
  // A pull segment's backward directions: those that can end on an owned row, by decreasing offset.
  static constexpr int kPullDirections = 32;  // as many as a pattern may have
  struct Backward {
    int n = 0;  // how many (the pattern's other directions: never present)
    int s[kPullDirections], offset[kPullDirections];  // the direction, its offset
    double k[kPullDirections], l0[kPullDirections];
    std::uint32_t full = 0;  // the bits of the n directions
  };
  Backward backward(const Segment& seg) const;
  // tangent()'s sweep with the stencil segments' chunks computed by stencil(seg, first molecule, count, exceptions,
  // how many, zeroed) and the generic connections from x.
  template <class Stencil>
  void tangent_sweep(const double* x, const double* u, double* out, double* ghost, FinalRows final_rows,
                     void* context, Stencil stencil) const;
  // Each row's present springs for rows [r0, r0 + n) of a pull segment (n <= kForceBlock; the rows on one side of
  // the segment's end and of each first + offset), from its exceptions; e_back, e_own: the exception cursors.
  void pull_bits(const Segment& seg, const Backward& bw, int r0, int n, int* e_back, int& e_own, std::uint32_t* pb,
                 std::uint32_t* pf) const;
  // Fills marks_ for a pull segment (once, in the constructor).
  void pull_marks(Segment& seg);
  // The force ring's directions of a pull segment (spring_kernel.cpp); false: none (no kernel for them).
  bool pull_ring(const Segment& seg, const Backward& bw, int* q, int& n, int& far) const;
  template <class Layout, class Finish>
  void pull_segment(const Segment& seg, const double* x, double* f, Layout at, int& zeroed, Finish& finish,
                    const ReadAhead* ahead) const;
  template <class Layout>
  void sweep(const double* x, double* f, Layout at, FinalRows final_rows, void* context,
             const ReadAhead* ahead = nullptr) const;
  // Zeroes f's owned rows [zeroed, reach) (reach clamped to the owned molecules) and advances `zeroed`.
  template <class Layout>
  void zero_ahead(double* f, Layout at, int& zeroed, int reach) const;
  const LocalModel& model_;
  std::vector<Segment> segments_;         // in connection order; generic connections between them
  std::vector<int> offsets_;              // per pattern and direction: end b - end a
  std::vector<std::uint16_t> types_;      // per pattern and direction: connection type
  std::vector<double> k_, l0_;            // per pattern and direction: its type's k and l0
  std::vector<int> scatter_;              // per pattern: its directions by decreasing offset
  std::vector<int> directions_;           // per pattern: forward connections per molecule
  std::vector<int> pattern_start_;        // per pattern: start in offsets_ / types_
  std::vector<int> reach_;                // per pattern: its largest offset
  std::vector<StencilException> exceptions_;     // per segment, by molecule
  std::vector<PullMark> marks_;                   // per pull segment, by row
  // The generic connections after the last segment, as generic_reach (untyped models: all of them, all rows).
  int tail_reach_ = std::numeric_limits<int>::max();
  long structured_ = 0;
  // Ends stored as runs (partition/local_model.hpp's ConnectionEnd has no array to point at): the generic
  // connections' ends, in connection order (a lattice's row ends: about 2 % of the connections).
  std::vector<int> generic_a_, generic_b_;
  int tail_at_ = 0;
  int ring_rows_ = 0;
  bool pull_ = true;
  bool pull_ring_ = true;
  mutable std::vector<double> pull_ring_rows_;  // the pull form's force ring (pull_segment), 3 a direction
};

// The diagonal of n connections' tangent blocks, K_rr = k (g + (1 - g) d_r^2 / |d|^2) with g = 1 - l0 / |d|, from d
// (three streams), k and l0: ForceModel::tangent_diagonal's operations in its order, every value its own to the
// bit, but vectorized (here for this file's -fno-rounding-math, CMakeLists.txt; as scalars its four divisions and
// square root a connection were most of that function's time).
void tangent_diagonal_terms(int n, const double* d0, const double* d1, const double* d2, const double* k,
                            const double* l0, double* K0, double* K1, double* K2);

}  // namespace tissue
