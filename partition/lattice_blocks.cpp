#include "partition/lattice_blocks.hpp"

#include "partition/agreement.hpp"

#include <metis.h>

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include "partition/natural_order.hpp"
#include "src/model/topology.hpp"

namespace tissue {

namespace {

// Blocks of every body in one numbering: body 0's blocks (x fastest), then body 1's, ...
class Blocks {
public:
  Blocks(const Body& shape, int b) : shape_(shape), b_(b) {
    for (int i = 0; i < shape.bodies(); ++i) {
      const BoxGeometry& box = shape.body(i);
      std::array<long, 3> c;
      for (int d = 0; d < 3; ++d) c[d] = (box.n[d] + b - 1) / b;
      count_.push_back(c);
      first_.push_back(total_);
      total_ += static_cast<std::int64_t>(c[0]) * c[1] * c[2];
    }
  }
  std::int64_t total() const { return total_; }
  std::int64_t of(int body, std::int64_t g) const {
    const auto ijk = shape_.body(body).index(g);
    const auto& c = count_[body];
    return first_[body] + ijk[0] / b_ + c[0] * (ijk[1] / b_ + static_cast<std::int64_t>(c[1]) * (ijk[2] / b_));
  }
  // Molecules in block v (edge blocks are cut short by the box).
  long molecules(std::int64_t v) const {
    int body = static_cast<int>(std::upper_bound(first_.begin(), first_.end(), v) - first_.begin()) - 1;
    std::int64_t r = v - first_[body];
    const auto& c = count_[body];
    const std::array<long, 3> ijk{static_cast<long>(r % c[0]), static_cast<long>((r / c[0]) % c[1]),
                                  static_cast<long>(r / (static_cast<std::int64_t>(c[0]) * c[1]))};
    long m = 1;
    for (int d = 0; d < 3; ++d) m *= std::min<long>(b_, shape_.body(body).n[d] - ijk[d] * b_);
    return m;
  }

private:
  const Body& shape_;
  long b_;
  std::vector<std::array<long, 3>> count_;
  std::vector<std::int64_t> first_;
  std::int64_t total_ = 0;
};

}  // namespace

int lattice_block_size(const Body& shape, int parts) {
  const std::int64_t target = std::max<std::int64_t>(32768, 128 * static_cast<std::int64_t>(parts));
  if (shape.molecules() <= target) return 1;
  for (int b = 2;; ++b)
    if (Blocks(shape, b).total() <= target || b >= 1024) return b;
}

std::vector<int> partition_lattice_blocks(const Body& shape, MPI_Comm comm, int parts, int block, PartitionStats& stats) {
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const std::int64_t n = shape.molecules();
  const std::int64_t begin = NaturalOrder::block_begin(n, size, rank), end = NaturalOrder::block_begin(n, size, rank + 1);
  const Blocks blocks(shape, block);
  const std::int64_t nv = blocks.total();
  if (nv < parts) throw std::runtime_error("the lattice has fewer blocks than parts: use a smaller block");
  if (nv > std::numeric_limits<idx_t>::max() / 32) throw std::runtime_error("too many lattice blocks for METIS's idx_t");

  // Edge weights: each rank counts the connections of its natural block's molecules (each once, from its lower
  // end) between different blocks, keyed by the ordered block pair.
  std::unordered_map<std::int64_t, std::int64_t> weight;
  std::vector<Neighbour> nb;
  std::vector<LatticeStencil> stencil;
  for (int b = 0; b < shape.bodies(); ++b) stencil.emplace_back(*find_topology(shape.body(b).topology), shape.body(b));
  for (std::int64_t g = begin; g < end; ++g) {
    const int body = shape.body_of(g);
    stencil[body].neighbours(g, nb);
    const std::int64_t u = blocks.of(body, g);
    for (const auto& x : nb) {
      if (x.id < g) continue;
      const std::int64_t v = blocks.of(body, x.id);
      if (u != v) ++weight[std::min(u, v) * nv + std::max(u, v)];
    }
  }
  std::vector<std::int64_t> mine;  // (key, weight) pairs
  mine.reserve(2 * weight.size());
  for (const auto& [key, w] : weight) mine.push_back(key), mine.push_back(w);
  weight = {};
  int count = static_cast<int>(mine.size());
  std::vector<int> counts(size), displs(size + 1, 0);
  MPI_Gather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, comm);
  for (int r = 0; r < size; ++r) displs[r + 1] = displs[r] + counts[r];
  std::vector<std::int64_t> all(rank == 0 ? displs[size] : 0);
  MPI_Gatherv(mine.data(), count, MPI_INT64_T, all.data(), counts.data(), displs.data(), MPI_INT64_T, 0, comm);
  mine = {};

  std::vector<int> block_part(nv, 0);
  long edge_cut = 0;
  // Rank 0 partitions alone, agreed (partition/agreement.hpp): its failure stops every rank here, not in a
  // broadcast.
  agree(comm, [&] {
    if (rank != 0) return;
    fault_point("partition", comm);
    // Merge the ranks' counts (a block pair split between two natural blocks arrives twice), then the CSR graph
    // with both directions of every edge.
    std::unordered_map<std::int64_t, std::int64_t> merged;
    for (std::size_t i = 0; i < all.size(); i += 2) merged[all[i]] += all[i + 1];
    all = {};
    std::vector<idx_t> xadj(nv + 1, 0), vwgt(nv);
    for (const auto& [key, w] : merged) ++xadj[key / nv + 1], ++xadj[key % nv + 1];
    for (std::int64_t v = 0; v < nv; ++v) xadj[v + 1] += xadj[v], vwgt[v] = static_cast<idx_t>(blocks.molecules(v));
    std::vector<idx_t> adjncy(xadj[nv]), adjwgt(xadj[nv]), fill(xadj.begin(), xadj.end() - 1);
    for (const auto& [key, w] : merged) {
      const idx_t u = static_cast<idx_t>(key / nv), v = static_cast<idx_t>(key % nv);
      adjncy[fill[u]] = v, adjwgt[fill[u]++] = static_cast<idx_t>(w);
      adjncy[fill[v]] = u, adjwgt[fill[v]++] = static_cast<idx_t>(w);
    }
    merged = {};
    // Neighbours in increasing order: the graph, and so METIS's answer, does not depend on the hash order.
    for (std::int64_t v = 0; v < nv; ++v) {
      std::vector<std::pair<idx_t, idx_t>> row;
      for (idx_t e = xadj[v]; e < xadj[v + 1]; ++e) row.emplace_back(adjncy[e], adjwgt[e]);
      std::sort(row.begin(), row.end());
      for (idx_t e = xadj[v]; e < xadj[v + 1]; ++e) adjncy[e] = row[e - xadj[v]].first, adjwgt[e] = row[e - xadj[v]].second;
    }
    idx_t nvtxs = static_cast<idx_t>(nv), ncon = 1, nparts = parts, objval = 0;
    idx_t options[METIS_NOPTIONS];
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_SEED] = 1;
    options[METIS_OPTION_UFACTOR] = kMetisImbalance;
    std::vector<idx_t> p(nv, 0);
    int status = METIS_OK;
    if (parts > 1)
      status = METIS_PartGraphKway(&nvtxs, &ncon, xadj.data(), adjncy.data(), vwgt.data(), nullptr, adjwgt.data(),
                                   &nparts, nullptr, nullptr, options, &objval, p.data());
    if (status != METIS_OK)
      throw std::runtime_error("METIS_PartGraphKway failed with status " + std::to_string(status));
    edge_cut = objval;
    std::copy(p.begin(), p.end(), block_part.begin());
  });
  MPI_Bcast(block_part.data(), static_cast<int>(nv), MPI_INT, 0, comm);
  MPI_Bcast(&edge_cut, 1, MPI_LONG, 0, comm);

  std::vector<int> part(end - begin);
  std::vector<long> molecules(parts, 0), total(parts, 0);
  for (std::int64_t g = begin; g < end; ++g) {
    part[g - begin] = block_part[blocks.of(shape.body_of(g), g)];
    ++molecules[part[g - begin]];
  }
  MPI_Allreduce(molecules.data(), total.data(), parts, MPI_LONG, MPI_SUM, comm);
  stats = PartitionStats{};
  stats.edge_cut = edge_cut;
  stats.imbalance = static_cast<double>(*std::max_element(total.begin(), total.end())) * parts / n;
  return part;
}

}  // namespace tissue
