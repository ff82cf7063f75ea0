#include "partition/local_model.hpp"

#include <algorithm>
#include <cstring>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include "partition/explicit_model.hpp"
#include "partition/lattice_model.hpp"
#include "src/model/topology.hpp"

namespace tissue {

int LocalModel::lattice_forward_rank(int c) const {
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

void release_calibration_inputs(LocalModel& m) {
  m.youngs_modulus = std::vector<double>();
  m.degree = std::vector<int>();
}

bool compact_connection_types(LocalModel& m) {
  if (m.typed() || m.connections() == 0) return m.typed();
  struct PairHash {
    std::size_t operator()(const std::pair<std::uint64_t, std::uint64_t>& p) const {
      return std::hash<std::uint64_t>()(p.first * 0x9E3779B97F4A7C15ULL ^ p.second);
    }
  };
  std::unordered_map<std::pair<std::uint64_t, std::uint64_t>, std::uint16_t, PairHash> types;
  std::vector<double> tk, tl;
  auto type_of = [&](int c) {  // by bits: two different doubles are two types, -0.0 and 0.0 included
    std::uint64_t kb, lb;
    const double l0 = m.l0(c);
    std::memcpy(&kb, &m.stiffness[c], 8), std::memcpy(&lb, &l0, 8);
    auto [it, added] = types.try_emplace({kb, lb}, static_cast<std::uint16_t>(std::min<std::size_t>(tk.size(), 65535)));
    if (added) tk.push_back(m.stiffness[c]), tl.push_back(l0);
    return it->second;
  };
  // First the table alone: past 65,536 types nothing changes.
  for (int c = 0; c < m.connections(); ++c) {
    type_of(c);
    if (tk.size() > 65536) return false;
  }
  // Then each connection's type, 2 bytes at the front of the stiffness array's own storage (byte 2c lies in
  // entry c / 4, already read), so no third per-connection array exists while both 8-byte ones do: that was
  // the set-up's peak (docs/benchmarks.md).
  const int nc = m.connections();
  unsigned char* packed = reinterpret_cast<unsigned char*>(m.stiffness.data());
  for (int c = 0; c < nc; ++c) {
    const std::uint16_t t = type_of(c);
    std::memcpy(packed + 2 * static_cast<std::size_t>(c), &t, 2);
  }
  m.rest_length = std::vector<double>();
  m.length_type = std::vector<std::uint16_t>(), m.length_table = std::vector<double>();
  m.connection_type.resize(nc);
  std::memcpy(m.connection_type.data(), packed, 2 * static_cast<std::size_t>(nc));
  m.stiffness = std::vector<double>();
  m.type_stiffness = std::move(tk), m.type_rest_length = std::move(tl);
  return true;
}

LocalModel build_local_model(const Scene& scene, MPI_Comm comm, const MeshReader& read_mesh) {
  // Explicit topologies (meshes, random clouds) are handed out by rank 0 in blocks; box lattices come from their
  // stencils. Either way each rank builds only its share.
  const std::vector<BodySpec>& specs = scene.bodies;
  const bool is_explicit = std::any_of(specs.begin(), specs.end(), [](const BodySpec& b) { return b.unstructured(); }) ||
                           scene.body.unstructured();
  LocalModel m = is_explicit ? build_explicit_model(scene, comm, read_mesh) : build_lattice_model(scene, comm);
  if (scene.partition.method == "ptscotch") {
    // PT-Scotch's blocks cannot see their neighbours' parts: count the cut connections here, each once (by the
    // rank writing it, which owns end a; it is cut when end b is a ghost).
    long cut = 0;
    for (int c : m.written_here()) cut += m.end_b[c] >= m.owned;
    MPI_Allreduce(&cut, &m.partition.edge_cut, 1, MPI_LONG, MPI_SUM, comm);
  }
  return m;
}

}  // namespace tissue
