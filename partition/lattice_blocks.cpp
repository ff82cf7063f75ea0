#include "partition/lattice_blocks.hpp"

#include "partition/agreement.hpp"

#include <metis.h>

#include <algorithm>
#include <array>
#include <cstdlib>
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
  std::int64_t of(int body, std::int64_t g) const { return at(body, shape_.body(body).index(g)); }
  // The block of the molecule at lattice indices ijk of `body`.
  std::int64_t at(int body, const std::array<long, 3>& ijk) const {
    const auto& c = count_[body];
    return first_[body] + ijk[0] / b_ + c[0] * (ijk[1] / b_ + static_cast<std::int64_t>(c[1]) * (ijk[2] / b_));
  }
  // The block e = (e_x, e_y, e_z) blocks away from block v of `body`.
  std::int64_t shifted(int body, std::int64_t v, const int* e) const {
    const auto& c = count_[body];
    return v + e[0] + c[0] * (e[1] + static_cast<std::int64_t>(c[1]) * e[2]);
  }
  int body_of_block(std::int64_t v) const {
    return static_cast<int>(std::upper_bound(first_.begin(), first_.end(), v) - first_.begin()) - 1;
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

// f(g, body, ijk) for every molecule g in [begin, end) in increasing order, its lattice indices stepped (no
// division a molecule).
template <class F>
void for_each_molecule(const Body& shape, std::int64_t begin, std::int64_t end, F&& f) {
  for (int body = 0; body < shape.bodies() && begin < end; ++body) {
    const BoxGeometry& box = shape.body(body);
    const std::int64_t last = std::min(end, box.first + box.molecules());
    if (last <= begin) continue;
    std::array<long, 3> ijk = box.index(begin);
    for (std::int64_t g = begin; g < last; ++g) {
      f(g, body, ijk);
      if (++ijk[0] == box.n[0]) {
        ijk[0] = 0;
        if (++ijk[1] == box.n[1]) ijk[1] = 0, ++ijk[2];
      }
    }
    begin = last;
  }
}

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
  // end) between different blocks, by the lower end's block u and the other's offset in blocks e (within
  // [-R, R] per axis, R = the stencil's reach in blocks): a dense count for the blocks the natural block
  // touches, with no hash and no division a connection.
  struct Forward {
    int d[3];
  };
  std::vector<std::vector<Forward>> forward(shape.bodies());  // per body: the stencil's offsets to higher ids
  long reach = 0;
  for (int b = 0; b < shape.bodies(); ++b) {
    const BoxGeometry& box = shape.body(b);
    for (const auto& o : find_topology(box.topology)->stencil) {
      if (o.d[0] + box.n[0] * (o.d[1] + static_cast<std::int64_t>(box.n[1]) * o.d[2]) <= 0) continue;
      forward[b].push_back({{o.d[0], o.d[1], o.d[2]}});
      for (int d = 0; d < 3; ++d) reach = std::max<long>(reach, std::abs(o.d[d]));
    }
  }
  const int R = static_cast<int>((reach + block - 1) / block), W = 2 * R + 1, directions = W * W * W;
  std::int64_t u_lo = 0, u_hi = -1;  // blocks hold (body, z, y, x) in order, so the range's lie in [u_lo, u_hi]
  if (begin < end) {
    const int b0 = shape.body_of(begin), b1 = shape.body_of(end - 1);
    const BoxGeometry &box0 = shape.body(b0), &box1 = shape.body(b1);
    u_lo = blocks.at(b0, {0, 0, box0.index(begin)[2]});
    u_hi = blocks.at(b1, {box1.n[0] - 1, box1.n[1] - 1, box1.index(end - 1)[2]});
  }
  std::vector<std::int64_t> dense(static_cast<std::size_t>(u_hi - u_lo + 1) * directions, 0);
  for_each_molecule(shape, begin, end, [&](std::int64_t, int body, const std::array<long, 3>& ijk) {
    const BoxGeometry& box = shape.body(body);
    const long r[3] = {ijk[0] % block, ijk[1] % block, ijk[2] % block};  // place inside the block
    std::int64_t* row = nullptr;
    for (const Forward& o : forward[body]) {
      int e[3];
      bool inside = true, other = false;
      for (int d = 0; d < 3; ++d) {
        const long q = ijk[d] + o.d[d], p = r[d] + o.d[d];
        inside = inside && q >= 0 && q < box.n[d];
        e[d] = static_cast<int>(p < 0 ? -((-p + block - 1) / block) : p / block);
        other = other || e[d] != 0;
      }
      if (!inside || !other) continue;
      if (!row) row = dense.data() + (blocks.at(body, ijk) - u_lo) * directions;
      ++row[((e[2] + R) * W + (e[1] + R)) * W + (e[0] + R)];
    }
  });
  std::vector<std::int64_t> mine;  // (key, weight) pairs; rank 0 sums a pair that arrives twice
  for (std::int64_t u = u_lo; u <= u_hi; ++u) {
    const std::int64_t* row = dense.data() + (u - u_lo) * directions;
    for (int k = 0; k < directions; ++k) {
      if (row[k] == 0) continue;
      const int e[3] = {k % W - R, (k / W) % W - R, k / (W * W) - R};
      const std::int64_t v = blocks.shifted(blocks.body_of_block(u), u, e);
      mine.push_back(std::min(u, v) * nv + std::max(u, v)), mine.push_back(row[k]);
    }
  }
  decltype(dense)().swap(dense);
  int count = static_cast<int>(mine.size());
  std::vector<int> counts(size), displs(size + 1, 0);
  MPI_Gather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, comm);
  for (int r = 0; r < size; ++r) displs[r + 1] = displs[r] + counts[r];
  std::vector<std::int64_t> all(rank == 0 ? displs[size] : 0);
  MPI_Gatherv(mine.data(), count, MPI_INT64_T, all.data(), counts.data(), displs.data(), MPI_INT64_T, 0, comm);
  decltype(mine)().swap(mine);

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
    decltype(all)().swap(all);
    std::vector<idx_t> xadj(nv + 1, 0), vwgt(nv);
    for (const auto& [key, w] : merged) ++xadj[key / nv + 1], ++xadj[key % nv + 1];
    for (std::int64_t v = 0; v < nv; ++v) xadj[v + 1] += xadj[v], vwgt[v] = static_cast<idx_t>(blocks.molecules(v));
    std::vector<idx_t> adjncy(xadj[nv]), adjwgt(xadj[nv]), fill(xadj.begin(), xadj.end() - 1);
    for (const auto& [key, w] : merged) {
      const idx_t u = static_cast<idx_t>(key / nv), v = static_cast<idx_t>(key % nv);
      adjncy[fill[u]] = v, adjwgt[fill[u]++] = static_cast<idx_t>(w);
      adjncy[fill[v]] = u, adjwgt[fill[v]++] = static_cast<idx_t>(w);
    }
    decltype(merged)().swap(merged);
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
  for_each_molecule(shape, begin, end, [&](std::int64_t g, int body, const std::array<long, 3>& ijk) {
    part[g - begin] = block_part[blocks.at(body, ijk)];
    ++molecules[part[g - begin]];
  });
  MPI_Allreduce(molecules.data(), total.data(), parts, MPI_LONG, MPI_SUM, comm);
  stats = PartitionStats{};
  stats.edge_cut = edge_cut;
  stats.imbalance = static_cast<double>(*std::max_element(total.begin(), total.end())) * parts / n;
  return part;
}

}  // namespace tissue
