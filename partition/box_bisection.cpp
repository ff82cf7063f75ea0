#include "partition/box_bisection.hpp"

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <string>

#include "partition/agreement.hpp"
#include "partition/natural_order.hpp"
#include "src/model/topology.hpp"

namespace tissue {
namespace {

// The bisection as a tree: a node cuts `axis` at plane `cut` (below: indices < cut), or is the leaf of `part`.
struct Node {
  int axis = -1;
  long cut = 0;
  int below = -1, above = -1;
  int part = -1;
};

int bisect(const IndexBox& box, int first, int k, std::vector<IndexBox>& leaves, std::vector<Node>& tree) {
  const int self = static_cast<int>(tree.size());
  tree.emplace_back();
  if (k == 1) {
    leaves[first] = box;
    tree[self].part = first;
    return self;
  }
  // The longest axis; ties to the slower-varying one (z, then y), so that cuts keep ids contiguous.
  int axis = 2;
  for (int d = 1; d >= 0; --d)
    if (box.hi[d] - box.lo[d] > box.hi[axis] - box.lo[axis]) axis = d;
  const long planes = box.hi[axis] - box.lo[axis];
  const int k1 = k / 2, k2 = k - k1;
  if (planes < 2 || box.molecules() < k)
    throw std::runtime_error("partition.method = \"blocks\": the lattice is too small to cut into " +
                             std::to_string(k) + " parts");
  // Planes below the cut: the whole number next to planes * k1 / k whose larger half (per part) is smaller.
  const long down = std::clamp<long>(planes * k1 / k, 1, planes - 1), up = std::clamp<long>(down + 1, 1, planes - 1);
  auto load = [&](long c) { return std::max(static_cast<double>(c) / k1, static_cast<double>(planes - c) / k2); };
  const long c = load(up) < load(down) ? up : down;
  IndexBox lower = box, upper = box;
  lower.hi[axis] = upper.lo[axis] = box.lo[axis] + c;
  tree[self].axis = axis;
  tree[self].cut = box.lo[axis] + c;
  const int below = bisect(lower, first, k1, leaves, tree);
  const int above = bisect(upper, first + k1, k2, leaves, tree);
  tree[self].below = below, tree[self].above = above;
  return self;
}

int part_of(const std::vector<Node>& tree, const std::array<long, 3>& ijk) {
  int v = 0;
  while (tree[v].part < 0) v = ijk[tree[v].axis] < tree[v].cut ? tree[v].below : tree[v].above;
  return tree[v].part;
}

}  // namespace

std::vector<IndexBox> bisect_box(const std::array<long, 3>& n, int parts) {
  if (parts < 1) throw std::runtime_error("partition.method = \"blocks\": no parts");
  std::vector<IndexBox> leaves(parts);
  std::vector<Node> tree;
  IndexBox whole;
  whole.hi = n;
  bisect(whole, 0, parts, leaves, tree);
  return leaves;
}

bool box_bisection_applies(const Body& shape) { return shape.bodies() == 1 && !shape.body(0).unstructured(); }

double box_bisection_imbalance(const Body& shape, int parts) {
  const std::int64_t n = shape.molecules();
  if (!box_bisection_applies(shape) || n < parts) return std::numeric_limits<double>::infinity();
  try {
    std::int64_t largest = 0;
    for (const IndexBox& b : bisect_box(shape.body(0).n, parts)) largest = std::max(largest, b.molecules());
    return static_cast<double>(largest) * parts / static_cast<double>(n);
  } catch (const std::runtime_error&) {
    return std::numeric_limits<double>::infinity();
  }
}

bool box_bisection_chosen(const Body& shape, PartitionSpec::Method method, int parts) {
  if (method == PartitionSpec::Method::blocks) return true;
  return method == PartitionSpec::Method::automatic && box_bisection_applies(shape) &&
         box_bisection_imbalance(shape, parts) <= kBisectionImbalance;
}

std::vector<int> partition_box_bisection(const Body& shape, MPI_Comm comm, int parts, PartitionStats& stats) {
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  if (!box_bisection_applies(shape))
    throw std::runtime_error("partition.method = \"blocks\" cuts one box lattice; use \"metis\"");
  const BoxGeometry& box = shape.body(0);
  const std::int64_t n = shape.molecules();
  const std::int64_t begin = NaturalOrder::block_begin(n, size, rank), end = NaturalOrder::block_begin(n, size, rank + 1);
  std::vector<IndexBox> leaves(parts);
  std::vector<Node> tree;
  IndexBox whole;
  whole.hi = box.n;
  bisect(whole, 0, parts, leaves, tree);

  // This rank's local work (its parts and its share of the edge cut) is agreed before the reduction
  // (partition/agreement.hpp): a failure here (memory) stops every rank instead of leaving the others in it.
  std::vector<int> part;
  long cut = 0;
  agree(comm, [&] {
    fault_point("partition", comm);
    // Each part's rows (runs of x) that lie in this rank's block of ids.
    part.assign(end - begin, -1);
    const std::int64_t plane = static_cast<std::int64_t>(box.n[0]) * box.n[1];
    const long z_first = static_cast<long>((begin - box.first) / plane);
    const long z_last = end > begin ? static_cast<long>((end - 1 - box.first) / plane) : z_first - 1;
    for (int p = 0; p < parts; ++p) {
      const IndexBox& b = leaves[p];
      for (long z = std::max(b.lo[2], z_first); z < std::min(b.hi[2], z_last + 1); ++z)
        for (long y = b.lo[1]; y < b.hi[1]; ++y) {
          const std::int64_t row = box.id(b.lo[0], y, z);
          const std::int64_t lo = std::max(row, begin), hi = std::min(row + (b.hi[0] - b.lo[0]), end);
          if (lo < hi) std::fill(part.begin() + (lo - begin), part.begin() + (hi - begin), p);
        }
    }

    // The edge cut: each connection once, from its lower end, checked only for molecules within the stencil's
    // reach of an inner face of their box (no other molecule has a neighbour in another part).
    std::vector<std::array<int, 3>> forward;
    long reach = 0;
    for (const auto& o : find_topology(box.topology)->stencil) {
      if (o.d[0] + box.n[0] * (o.d[1] + static_cast<std::int64_t>(box.n[1]) * o.d[2]) <= 0) continue;
      forward.push_back({o.d[0], o.d[1], o.d[2]});
      for (int d = 0; d < 3; ++d) reach = std::max<long>(reach, std::abs(o.d[d]));
    }
    auto count = [&](const std::array<long, 3>& ijk, int p) {
      for (const auto& o : forward) {
        const std::array<long, 3> q{ijk[0] + o[0], ijk[1] + o[1], ijk[2] + o[2]};
        bool inside = true;
        for (int d = 0; d < 3; ++d) inside = inside && q[d] >= 0 && q[d] < box.n[d];
        if (inside && part_of(tree, q) != p) ++cut;
      }
    };
    auto near = [&](const IndexBox& b, int d, long i) {
      return (b.lo[d] > 0 && i - b.lo[d] < reach) || (b.hi[d] < box.n[d] && b.hi[d] - 1 - i < reach);
    };
    for (int p = 0; p < parts; ++p) {
      const IndexBox& b = leaves[p];
      for (long z = std::max(b.lo[2], z_first); z < std::min(b.hi[2], z_last + 1); ++z)
        for (long y = b.lo[1]; y < b.hi[1]; ++y) {
          const bool whole_row = near(b, 2, z) || near(b, 1, y);
          for (long x = b.lo[0]; x < b.hi[0]; ++x) {
            if (!whole_row && !near(b, 0, x)) {
              x = std::max(x, b.hi[0] - reach - 1);  // skip to the row's last molecules within reach of its end
              if (!near(b, 0, x)) continue;
            }
            const std::int64_t g = box.id(x, y, z);
            if (g >= begin && g < end) count({x, y, z}, p);
          }
        }
    }
  });
  stats = PartitionStats{};
  MPI_Allreduce(&cut, &stats.edge_cut, 1, MPI_LONG, MPI_SUM, comm);
  std::int64_t largest = 0;
  for (const auto& b : leaves) largest = std::max(largest, b.molecules());
  stats.imbalance = static_cast<double>(largest) * parts / static_cast<double>(n);
  return part;
}

}  // namespace tissue
