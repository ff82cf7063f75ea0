#include "partition/local_model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include "partition/explicit_model.hpp"
#include "partition/lattice_model.hpp"
#include "src/model/topology.hpp"

namespace tissue {

int MoleculeLayout::lattice_forward_rank(int c) const {
  // An owned end a has all its connections here, consecutive and in order: the position in its run.
  if (end_a[c] < owned) {
    int r = 0;
    while (r < c && end_a[c - r - 1] == end_a[c]) ++r;
    return r;
  }
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
    for (int c : m.written_here()) cut += m.end_b[c] >= m.owned;
    MPI_Allreduce(&cut, &m.partition.edge_cut, 1, MPI_LONG, MPI_SUM, comm);
  }
  return m;
}

}  // namespace tissue
