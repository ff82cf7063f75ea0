#include "partition/local_model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <unordered_map>

#include "partition/explicit_model.hpp"
#include "partition/lattice_model.hpp"
#include "src/model/topology.hpp"

namespace tissue {

bool ConnectionEnd::to_runs(ConnectionEnd& a, ConnectionEnd& b) {
  if (!a.plain() || !b.plain() || a.size_ != b.size_) return false;
  const int n = static_cast<int>(a.size_);
  const int* ea = a.plain_.data();
  const int* eb = b.plain_.data();
  const std::size_t budget = a.size_ * sizeof(int) / 4;  // bytes each end may take
  ConnectionEnd runs;
  std::map<std::vector<int>, int> known;  // pattern (offsets) -> index
  std::vector<int> row;
  int last_pattern = -1, next_molecule = 0;
  for (int c = 0; c < n;) {
    int e = c + 1;
    while (e < n && ea[e] == ea[c]) ++e;
    row.assign(eb + c, eb + e);
    for (int& o : row) o -= ea[c];
    const bool same = last_pattern >= 0 && ea[c] == next_molecule &&
                      std::equal(row.begin(), row.end(), runs.offsets_.begin() + runs.pattern_start_[last_pattern],
                                 runs.offsets_.begin() + runs.pattern_start_[last_pattern + 1]);
    if (!same) {
      auto [it, added] = known.try_emplace(row, static_cast<int>(known.size()));
      if (added) {
        if (runs.pattern_start_.empty()) runs.pattern_start_.push_back(0);
        runs.offsets_.insert(runs.offsets_.end(), row.begin(), row.end());
        runs.pattern_start_.push_back(static_cast<int>(runs.offsets_.size()));
      }
      last_pattern = it->second;
      runs.runs_.push_back({c, ea[c], last_pattern});
      if ((runs.runs_.size() * sizeof(Run) + (runs.offsets_.size() + runs.pattern_start_.size()) * sizeof(int)) > budget)
        return false;  // a mesh's rows: no runs worth keeping
    }
    next_molecule = ea[c] + 1;
    c = e;
  }
  runs.size_ = a.size_;
  runs.runs_.shrink_to_fit(), runs.pattern_start_.shrink_to_fit(), runs.offsets_.shrink_to_fit();
  ConnectionEnd run_b = runs;
  run_b.is_b_ = true;
  // Every value back, or nothing changes: decoded a window at a time (no run search and division a value).
  std::vector<int> back_a(4096), back_b(4096);
  for (int c0 = 0; c0 < n; c0 += 4096) {
    const int c1 = std::min(n, c0 + 4096);
    runs.decode(c0, c1, back_a.data()), run_b.decode(c0, c1, back_b.data());
    if (!std::equal(ea + c0, ea + c1, back_a.begin()) || !std::equal(eb + c0, eb + c1, back_b.begin())) return false;
  }
  a = std::move(runs), b = std::move(run_b);
  return true;
}

int MoleculeLayout::lattice_forward_rank(int c) const {
  // An owned end a has all its connections here, consecutive and in order: the position in its run.
  if (end_a[c] < owned) return end_a.row_position(c);
  // A ghost end a keeps only its connections to owned molecules: count in its stencil.
  const std::int64_t a = id[end_a[c]], b = id[end_b[c]];
  const BoxGeometry& box = shape.body(shape.body_of(a));
  thread_local std::vector<Neighbour> nb;
  lattice_neighbours(*find_topology(box.topology), box, a, nb);
  int rank = 0;
  for (const auto& x : nb) rank += x.id > a && x.id < b;
  return rank;
}

double largest_ghost_ratio(const MoleculeLayout& m) {
  const int ghosts_here = m.local - m.owned, owned_count = std::max(m.owned, 1);
  double ratio = static_cast<double>(ghosts_here) / owned_count, worst = 0;
  MPI_Allreduce(&ratio, &worst, 1, MPI_DOUBLE, MPI_MAX, m.comm);
  return worst;
}

LocalModel build_local_model(const Scene& scene, MPI_Comm comm, CalibrationInputs& inputs, const MeshReader& read_mesh) {
  // Explicit topologies (meshes, random clouds) are handed out by rank 0 in blocks; box lattices come from their
  // stencils. Either way each rank builds only its share.
  const std::vector<BodySpec>& specs = scene.bodies;
  const bool is_explicit = std::any_of(specs.begin(), specs.end(), [](const BodySpec& b) { return b.unstructured(); }) ||
                           scene.body.unstructured();
  LocalModel m = is_explicit ? build_explicit_model(scene, comm, inputs, read_mesh) : build_lattice_model(scene, comm, inputs);
  if (scene.partition.method == PartitionSpec::Method::ptscotch) {
    // PT-Scotch's blocks cannot see their neighbours' parts: count the cut connections here, each once (by the
    // rank writing it, which owns end a; it is cut when end b is a ghost).
    long cut = 0;
    m.for_each_written([&](int, int, int b) { cut += b >= m.owned; });
    MPI_Allreduce(&cut, &m.partition.edge_cut, 1, MPI_LONG, MPI_SUM, comm);
  }
  return m;
}

}  // namespace tissue
