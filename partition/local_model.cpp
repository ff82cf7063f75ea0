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

LocalModel distribute(const Body& body, const std::vector<int>& part, const PartitionStats& stats, MPI_Comm comm) {
  LocalModel m;
  m.comm = comm;
  MPI_Comm_rank(comm, &m.rank);
  MPI_Comm_size(comm, &m.size);
  static_cast<BoxGeometry&>(m.shape) = body;
  m.shape.parts = body.parts;
  m.shape.faces = body.faces;  // explicit topologies' named faces (O(surface)); points stay global-only
  m.global_molecules = body.molecules();
  m.global_connections = static_cast<std::int64_t>(body.connections.size());
  m.partition = stats;
  if (m.global_molecules * 3 > std::numeric_limits<PetscInt>::max())
    throw std::runtime_error("the body has more molecules than 32-bit PETSc indices can address");

  // Contiguous renumbering: part by part, original order within a part.
  const std::int64_t n = body.molecules();
  std::vector<PetscInt> first(m.size + 1, 0);
  for (int p : part) ++first[p + 1];
  for (int r = 0; r < m.size; ++r) first[r + 1] += first[r];
  std::vector<PetscInt> block_of(n);
  {
    std::vector<PetscInt> next(first.begin(), first.end() - 1);
    for (std::int64_t g = 0; g < n; ++g) block_of[g] = next[part[g]]++;
  }
  m.first_block = first[m.rank];

  std::vector<int> degree(n, 0);
  for (const auto& c : body.connections) ++degree[c.a], ++degree[c.b];
  // The global id of each molecule's first connection to a higher id (connections are sorted by (a, b)).
  std::vector<std::int64_t> first_forward(n + 1, 0);
  for (const auto& c : body.connections) ++first_forward[c.a + 1];
  for (std::int64_t g = 0; g < n; ++g) {
    first_forward[g + 1] += first_forward[g];
    if (first_forward[g + 1] - first_forward[g] > 65535)
      throw std::runtime_error("a molecule has more than 65535 connections");
  }

  // Owned molecules, then ghosts in original order.
  std::unordered_map<std::int64_t, int> local_of;
  for (std::int64_t g = 0; g < n; ++g)
    if (part[g] == m.rank) local_of[g] = static_cast<int>(m.id.size()), m.id.push_back(g);
  m.owned = static_cast<int>(m.id.size());
  std::vector<std::int64_t> ghosts;
  std::vector<std::size_t> mine;  // global indices of local connections
  for (std::size_t c = 0; c < body.connections.size(); ++c) {
    const auto& con = body.connections[c];
    bool a = part[con.a] == m.rank, b = part[con.b] == m.rank;
    if (!a && !b) continue;
    mine.push_back(c);
    if (!a) ghosts.push_back(con.a);
    if (!b) ghosts.push_back(con.b);
  }
  std::sort(ghosts.begin(), ghosts.end());
  ghosts.erase(std::unique(ghosts.begin(), ghosts.end()), ghosts.end());
  for (auto g : ghosts) local_of[g] = static_cast<int>(m.id.size()), m.id.push_back(g);
  m.local = static_cast<int>(m.id.size());

  m.block.resize(m.local), m.rest.resize(3 * m.local), m.mass.resize(m.local);
  m.youngs_modulus.resize(m.local), m.degree.resize(m.local), m.body.resize(m.local);
  m.first_connection.resize(m.local);
  for (int i = 0; i < m.local; ++i) {
    std::int64_t g = m.id[i];
    m.first_connection[i] = first_forward[g];
    m.block[i] = block_of[g];
    Vec3 x = body.rest_position(g);
    for (int d = 0; d < 3; ++d) m.rest[3 * i + d] = x[d];
    m.mass[i] = body.mass[g];
    m.youngs_modulus[i] = body.youngs_modulus[g];
    m.degree[i] = degree[g];
    m.body[i] = body.body_of(g);
  }

  // Tetrahedra incident on each connection (Van Gelder's Eq. 5), summed per connection.
  std::unordered_map<std::int64_t, int> local_connection;  // key a * n + b
  const std::size_t nc = mine.size();
  m.end_a.resize(nc), m.end_b.resize(nc), m.forward_rank.resize(nc), m.connection_class.resize(nc);
  m.rest_length.resize(nc), m.stiffness.assign(nc, 0.0);
  for (std::size_t l = 0; l < nc; ++l) {
    const auto& con = body.connections[mine[l]];
    m.end_a[l] = local_of[con.a], m.end_b[l] = local_of[con.b];
    m.forward_rank[l] = static_cast<std::uint16_t>(mine[l] - first_forward[con.a]);
    m.connection_class[l] = con.cls;
    m.rest_length[l] = body.rest_distance(con.a, con.b);
    if (part[con.a] == m.rank) ++m.written_count;
    if (!body.tetrahedra.empty()) local_connection[con.a * n + con.b] = static_cast<int>(l);
  }
  if (!body.tetrahedra.empty()) {
    m.tetra_volume.assign(nc, 0.0);
    m.tetra_lloyd_sum.assign(nc, 0.0);  // Lloyd, Szekely & Harders 2007 (calibration/lloyd.cpp)
    for (const auto& t : body.tetrahedra) {
      Vec3 p[4];
      for (int v = 0; v < 4; ++v) p[v] = body.rest_position(t[v]);
      double e[3][3];
      for (int v = 0; v < 3; ++v)
        for (int d = 0; d < 3; ++d) e[v][d] = p[v + 1][d] - p[0][d];
      double vol = std::fabs(e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                             e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                             e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0])) / 6.0;
      const double l_equiv = std::cbrt(6.0 * std::sqrt(2.0) * vol);
      for (int x = 0; x < 4; ++x)
        for (int y = x + 1; y < 4; ++y) {
          auto it = local_connection.find(std::min(t[x], t[y]) * n + std::max(t[x], t[y]));
          if (it == local_connection.end()) continue;
          m.tetra_volume[it->second] += vol;
          m.tetra_lloyd_sum[it->second] += l_equiv;
        }
    }
  }

  int ghosts_here = m.local - m.owned, owned = std::max(m.owned, 1);
  double ratio = static_cast<double>(ghosts_here) / owned, worst = 0;
  MPI_Allreduce(&ratio, &worst, 1, MPI_DOUBLE, MPI_MAX, comm);
  m.partition.surface_to_volume = worst;
  return m;
}

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
