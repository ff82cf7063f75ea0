#include "tests/whole_body.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include "partition/ptscotch_partition.hpp"
#include "src/model/mesh_cloud.hpp"
#include "src/model/random_cloud.hpp"
#include "src/model/topology.hpp"
#include "src/model/unstructured.hpp"

namespace tissue {
namespace {

// One body of the scene, numbered from `first`: geometry, topology, per-molecule material and mass.
Body build_one(const BodySpec& spec, std::int64_t first) {
  Body b;
  static_cast<BoxGeometry&>(b) = body_geometry(spec, 0);
  find_topology(spec.topology)->build(b);  // the scene reader has checked the name
  std::sort(b.connections.begin(), b.connections.end(), [](const Connection& x, const Connection& y) {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  });
  const std::int64_t n = b.molecules();
  b.youngs_modulus.resize(n);
  b.mass.resize(n);
  for (std::int64_t m = 0; m < n; ++m) {
    const MoleculeMaterial mat = molecule_material(spec, b, m);
    b.youngs_modulus[m] = mat.youngs_modulus;
    b.mass[m] = mat.density * b.volume(m);
  }
  if (first != 0) {
    for (auto& c : b.connections) c.a += first, c.b += first;
    for (auto& t : b.tetrahedra)
      for (auto& v : t) v += first;
    b.first = first;
  }
  return b;
}

// Explicit topologies (a mesh file, a random cloud) go through a tetrahedral mesh; boxes through their stencil.
Body build_any(const Scene& scene, const MeshReader& read_mesh, const BodySpec& spec, std::size_t index,
               std::size_t count, std::int64_t first) {
  const std::string key = count > 1 ? "body[" + std::to_string(index) + "]" : "body";
  if (spec.shape == BodySpec::Shape::mesh && !read_mesh) throw std::logic_error("build_body: a mesh body and no mesh reader");
  if (spec.shape == BodySpec::Shape::mesh && spec.random)
    return build_unstructured(spec, random_in_mesh(read_mesh(spec), spec, scene.file, key), first, scene.file, key);
  if (spec.shape == BodySpec::Shape::mesh) return build_unstructured(spec, read_mesh(spec), first, scene.file, key);
  if (spec.random) return build_unstructured(spec, random_cloud(spec), first, scene.file, key);
  return build_one(spec, first);
}

std::vector<BodySpec> specs_of(const Scene& scene) {
  return scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
}

}  // namespace

Body build_body(const Scene& scene, const MeshReader& read_mesh) {
  const std::vector<BodySpec> specs = specs_of(scene);
  Body all = build_any(scene, read_mesh, specs[0], 0, specs.size(), 0);
  all.parts.push_back(all);
  all.parts.back().first = 0;
  for (std::size_t i = 1; i < specs.size(); ++i) {
    Body b = build_any(scene, read_mesh, specs[i], i, specs.size(), all.molecules());
    all.parts.push_back(static_cast<const BoxGeometry&>(b));
    all.connections.insert(all.connections.end(), b.connections.begin(), b.connections.end());
    all.tetrahedra.insert(all.tetrahedra.end(), b.tetrahedra.begin(), b.tetrahedra.end());
    all.youngs_modulus.insert(all.youngs_modulus.end(), b.youngs_modulus.begin(), b.youngs_modulus.end());
    all.mass.insert(all.mass.end(), b.mass.begin(), b.mass.end());
    if (!all.points.empty() || !b.points.empty()) {  // explicit positions for all once one body has them
      for (std::int64_t m = static_cast<std::int64_t>(all.points.size()); m < b.first; ++m)
        all.points.push_back(all.part(m).rest_position(m));
      for (std::int64_t m = b.first; m < b.first + b.molecules(); ++m)
        all.points.push_back(b.points.empty() ? b.rest_position(m) : b.points[m - b.first]);
    }
    for (auto& f : b.faces) f.body = static_cast<int>(i), all.faces.push_back(f);
  }
  for (std::size_t i = 0; i < specs.size(); ++i)  // a box's faces: its lattice planes
    if (!all.parts[i].unstructured())
      for (auto& f : lattice_faces(all.parts[i], static_cast<int>(i))) all.faces.push_back(std::move(f));
  std::stable_sort(all.faces.begin(), all.faces.end(),
                   [](const NamedFace& x, const NamedFace& y) { return x.body < y.body; });
  check_face_names(scene, all);
  return all;
}

std::vector<int> partition_molecules(const Body& body, MPI_Comm comm, PartitionStats& stats) {
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const std::int64_t n = body.molecules();
  std::vector<int> part(n, 0);
  stats = PartitionStats{};
  if (size == 1) return part;
  if (n < size) throw std::runtime_error("the body has fewer molecules than ranks");
  std::vector<int> xadj, adjncy;
  if (rank == 0) {
    // The connection graph in CSR form, both directions.
    xadj.assign(n + 1, 0), adjncy.resize(2 * body.connections.size());
    for (const auto& c : body.connections) ++xadj[c.a + 1], ++xadj[c.b + 1];
    for (std::int64_t m = 0; m < n; ++m) xadj[m + 1] += xadj[m];
    std::vector<int> fill(xadj.begin(), xadj.end() - 1);
    for (const auto& c : body.connections) {
      adjncy[fill[c.a]++] = static_cast<int>(c.b);
      adjncy[fill[c.b]++] = static_cast<int>(c.a);
    }
  }
  std::vector<int> all = partition_graph_on_rank0(std::move(xadj), std::move(adjncy), n, comm, stats);
  if (rank == 0) part = all;
  MPI_Bcast(part.data(), static_cast<int>(n), MPI_INT, 0, comm);
  return part;
}

std::vector<int> partition_molecules(const Body& body, MPI_Comm comm, PartitionStats& stats,
                                     PartitionSpec::Method method) {
  return method == PartitionSpec::Method::ptscotch ? partition_ptscotch(body, comm, stats) : partition_molecules(body, comm, stats);
}

std::vector<int> partition_ptscotch(const Body& body, MPI_Comm comm, PartitionStats& stats) {
  int rank, size;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const std::int64_t n = body.molecules();
  if (size == 1) {
    stats = PartitionStats{};
    return std::vector<int>(n, 0);
  }
  // Neighbour lists of this rank's even block, from the global connection list.
  const std::int64_t begin = n * rank / size, end = n * (rank + 1) / size;
  std::vector<std::vector<std::int64_t>> adjacency(end - begin);
  for (const auto& c : body.connections) {
    if (c.a >= begin && c.a < end) adjacency[c.a - begin].push_back(c.b);
    if (c.b >= begin && c.b < end) adjacency[c.b - begin].push_back(c.a);
  }
  std::vector<int> mine = ptscotch_block(
      begin, end, n, [&](std::int64_t g, std::vector<std::int64_t>& out) { out = adjacency[g - begin]; }, comm, stats);

  // distribute() reads the whole owner map: gather the blocks in rank order.
  std::vector<int> part(n), counts(size), displs(size);
  for (int r = 0; r < size; ++r) {
    displs[r] = static_cast<int>(n * r / size);
    counts[r] = static_cast<int>(n * (r + 1) / size) - displs[r];
  }
  MPI_Allgatherv(mine.data(), static_cast<int>(mine.size()), MPI_INT, part.data(), counts.data(), displs.data(),
                 MPI_INT, comm);
  for (const auto& c : body.connections) stats.edge_cut += part[c.a] != part[c.b];
  return part;
}

LocalModel distribute(const Body& body, const std::vector<int>& part, const PartitionStats& stats, MPI_Comm comm,
                      CalibrationInputs& in) {
  LocalModel m;
  in = CalibrationInputs();
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
  std::vector<std::int64_t> ids;
  for (std::int64_t g = 0; g < n; ++g)
    if (part[g] == m.rank) local_of[g] = static_cast<int>(ids.size()), ids.push_back(g);
  m.owned = static_cast<int>(ids.size());
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
  for (auto g : ghosts) local_of[g] = static_cast<int>(ids.size()), ids.push_back(g);
  m.local = static_cast<int>(ids.size());

  std::vector<PetscInt> blocks(m.local);
  std::vector<int> bodies(m.local);
  m.rest.resize(3 * m.local), m.mass.resize(m.local);
  in.youngs_modulus.resize(m.local), in.degree.resize(m.local);
  std::vector<std::int64_t> firsts(m.local);
  for (int i = 0; i < m.local; ++i) {
    std::int64_t g = ids[i];
    firsts[i] = first_forward[g];
    blocks[i] = block_of[g];
    Vec3 x = body.rest_position(g);
    for (int d = 0; d < 3; ++d) m.rest[3 * i + d] = x[d];
    m.mass[i] = body.mass[g];
    in.youngs_modulus[i] = body.youngs_modulus[g];
    in.degree[i] = degree[g];
    bodies[i] = body.body_of(g);
  }
  m.id.assign(ids), m.block.assign(blocks), m.body.assign(bodies), m.first_connection.assign(firsts);

  // Tetrahedra incident on each connection (Van Gelder's Eq. 5), summed per connection.
  std::unordered_map<std::int64_t, int> local_connection;  // key a * n + b
  const std::size_t nc = mine.size();
  std::vector<int> end_a(nc), end_b(nc);
  m.forward_rank.resize(nc), m.connection_class.resize(nc);
  std::vector<double> rest_length(nc);
  for (std::size_t l = 0; l < nc; ++l) {
    const auto& con = body.connections[mine[l]];
    end_a[l] = local_of[con.a], end_b[l] = local_of[con.b];
    m.forward_rank[l] = static_cast<std::uint16_t>(mine[l] - first_forward[con.a]);
    m.connection_class[l] = con.cls;
    rest_length[l] = body.rest_distance(con.a, con.b);
    if (part[con.a] == m.rank) ++m.written_count;
    if (!body.tetrahedra.empty()) local_connection[con.a * n + con.b] = static_cast<int>(l);
  }
  m.table.set_rest_lengths(std::move(rest_length));
  m.end_a.assign(std::move(end_a)), m.end_b.assign(std::move(end_b));
  if (!body.tetrahedra.empty()) {
    in.tetra_volume.assign(nc, 0.0);
    in.tetra_lloyd_sum.assign(nc, 0.0);  // Lloyd, Szekely & Harders 2007 (calibration/lloyd.cpp)
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
          in.tetra_volume[it->second] += vol;
          in.tetra_lloyd_sum[it->second] += l_equiv;
        }
    }
  }

  int ghosts_here = m.local - m.owned, owned = std::max(m.owned, 1);
  double ratio = static_cast<double>(ghosts_here) / owned, worst = 0;
  MPI_Allreduce(&ratio, &worst, 1, MPI_DOUBLE, MPI_MAX, comm);
  m.partition.surface_to_volume = worst;
  return m;
}

}  // namespace tissue
