// The springs' tangent at rest in the pull form (issue 18): each owned row sums its own springs, both directions,
// and is written once, instead of each spring added to both ends (SpringKernel::rest_tangent's push form). At rest
// a spring's block is K = a a^T (a = sqrt(k) n, n its rest direction), so row i is
//   out_i = sum over its springs (a . (u_i - u_j)) a.
// The work is by rows, never by segments: every owned row is one of three kinds, found once from the connections:
//   - full: it has the lattice's interior pattern whole, each direction s forward (i -> i + o_s) and backward
//     (i - o_s -> i) with the same a_s, and nothing else: out_i = sum_s (a_s . ((u_i - u_{i+o}) + (u_i - u_{i-o}))) a_s,
//     contiguous rows vectorized, a_s constants;
//   - masked: a part of that pattern (a face's, an edge's, a row end's rows), each direction's a the same both ways
//     but maybe not the pattern's (a face's springs of another type: a variant of the pattern, one a run): the same
//     sum, a missing spring read at the row itself (its difference exactly 0);
//   - listed: any other (a spring of another type or direction, into the ghosts, a generic connection): its springs
//     as a list (the other end, its a), summed in connection order.
// A row's sum order differs from the push form's: the product moves at round-off (docs/benchmarks.md). Where the
// pattern does not fit (no repeated pattern, fewer than half the rows full or masked, rest separations that are
// not a few directions' own), make() gives null and the push form stays.
#pragma once
#include <cstdint>
#include <memory>
#include <vector>

#include "partition/local_model.hpp"

namespace tissue {

class RestPull {
public:
  // Called with owned rows [begin, end) of out as they become final, in order (SpringKernel::FinalRows).
  using FinalRows = void (*)(void* context, int begin, int end);
  // From the model's connections and rest positions (typed connections only); null where the pull form does not
  // apply (above). Local: ranks may differ.
  static std::unique_ptr<RestPull> make(const LocalModel& model);
  // out (3 * owned) = the springs' rest tangent times u (3 * local, ghosts up to date); every owned row written.
  void apply(const double* u, double* out, FinalRows final_rows = nullptr, void* context = nullptr) const;
  // How many owned rows of each kind (full, masked, listed), and the listed rows' springs.
  long rows(int kind) const { return counts_[kind]; }
  long listed_springs() const { return static_cast<long>(other_.size()); }

  enum Kind : std::uint8_t { kFull = 0, kMasked = 1, kListed = 2 };

private:
  struct Run {
    int begin;  // rows [begin, next run's begin)
    Kind kind;
    int at;       // masked: its first row's mask in masks_; listed: its first row's start in start_
    int variant;  // masked: its directions' a (variants_ + 3 D variant)
  };
  int owned_ = 0;
  int directions_ = 0;                   // the full pattern's
  std::vector<int> offset_;              // per direction: o_s > 0
  std::vector<double> pattern_a_;        // per direction: a_s (3 each)
  std::vector<Run> runs_;                // the owned rows in order, then a sentinel {owned}
  std::vector<std::uint32_t> masks_;     // masked rows: bit s forward spring s present, bit 16 + s backward
  std::vector<double> variants_;         // the masked rows' a's: 3 D a variant, variant 0 the pattern's
  std::vector<int> start_;               // listed rows: their springs [start_[r], start_[r + 1]) of other_ / which_
  std::vector<int> other_;               // the spring's other end (local)
  std::vector<std::uint32_t> which_;     // its a: table_[3 * which_ .. + 3]
  std::vector<double> table_;            // the distinct a of the rest springs (3 each)
  long counts_[3] = {0, 0, 0};
};

}  // namespace tissue
