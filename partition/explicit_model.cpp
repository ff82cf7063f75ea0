#include "partition/explicit_model.hpp"

#include <algorithm>
#include <array>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "partition/agreement.hpp"
#include "partition/exchange.hpp"
#include "partition/metis_partition.hpp"
#include "partition/ptscotch_partition.hpp"
#include "src/model/cell_law.hpp"
#include "src/model/mesh_cloud.hpp"
#include "src/model/random_cloud.hpp"
#include "src/model/topology.hpp"
#include "src/model/unstructured.hpp"

namespace tissue {
namespace {

// Tetrahedra handed out per round: 98,304 edge records (3 MB) in rank 0's send buffer at a time.
constexpr std::size_t kTetrahedraPerChunk = 1 << 14;

// The directory: rank r holds molecules [begin[r], begin[r + 1]) (PT-Scotch's even blocks, so its rows are the
// whole-body path's).
struct Blocks {
  std::vector<std::int64_t> begin;
  Blocks(std::int64_t n, int size) : begin(size + 1) {
    for (int r = 0; r <= size; ++r) begin[r] = n * r / size;
  }
  int owner(std::int64_t id) const {
    return static_cast<int>(std::upper_bound(begin.begin(), begin.end(), id) - begin.begin()) - 1;
  }
};

// What a molecule's directory rank knows of it: sent to its owner and to the ranks that hold it as a ghost.
struct Molecule {
  std::int64_t id = 0, first_connection = 0, block = 0;
  double x[3] = {0, 0, 0};
  double mass = 0, youngs_modulus = 0;
  std::int32_t degree = 0, body = 0, part = 0, unused = 0;
};

// A connection a < b with its incident tetrahedra's volume and Lloyd sums (Eq. 5).
struct Edge {
  std::int64_t a, b;
  double volume, lloyd;
};

// A connection on its way to an owner: its global id (the (a, b) order) and class too.
struct ConnectionRow {
  std::int64_t a, b, id;
  double volume, lloyd;
  std::int32_t cls, unused;
};

// A tetrahedron on its way to the ranks that need it (global tetrahedron id, global corner ids).
struct TetrahedronRow {
  std::int64_t id, v[4];
  std::int32_t region, unused;  // the scene region (-1: the body's own material)
};

bool explicit_spec(const BodySpec& spec) { return spec.unstructured(); }



// Rows of a trivially copyable type through an exchange plan, as bytes.
template <typename Row>
std::vector<Row> forward_rows(const ExchangePlan& plan, const std::vector<Row>& rows) {
  std::vector<Row> in(plan.received());
  plan.forward(reinterpret_cast<const char*>(rows.data()), reinterpret_cast<char*>(in.data()),
               static_cast<int>(sizeof(Row)));
  return in;
}

// The directory rows of `ids` (sorted, distinct; any rank's molecules). Collective.
std::vector<Molecule> ask(MPI_Comm comm, const Blocks& blocks, const std::vector<Molecule>& mine,
                          const std::vector<std::int64_t>& ids) {
  const int size = static_cast<int>(blocks.begin.size()) - 1;
  std::vector<int> counts(size, 0);
  for (auto g : ids) ++counts[blocks.owner(g)];
  const ExchangePlan plan(comm, std::move(counts));
  const std::vector<std::int64_t> questions = plan.forward(ids);
  std::vector<Molecule> answers(questions.size());
  const std::int64_t lo = mine.empty() ? 0 : mine.front().id;
  for (std::size_t q = 0; q < questions.size(); ++q) answers[q] = mine[questions[q] - lo];
  std::vector<Molecule> out(ids.size());
  plan.backward(reinterpret_cast<const char*>(answers.data()), reinterpret_cast<char*>(out.data()),
                static_cast<int>(sizeof(Molecule)));
  return out;
}

// Sorted, distinct.
void sort_unique(std::vector<std::int64_t>& v) {
  std::sort(v.begin(), v.end());
  v.erase(std::unique(v.begin(), v.end()), v.end());
}

// Routes each row to the distinct ranks dest(row) names (at most 4), through one exchange. Collective.
template <typename Dest>
std::vector<TetrahedronRow> route_tetrahedra(MPI_Comm comm, int size, const std::vector<TetrahedronRow>& rows, Dest dest) {
  std::vector<std::vector<TetrahedronRow>> out(size);
  for (const auto& t : rows) {
    int to[4], n = 0;
    for (int v = 0; v < 4; ++v) {
      const int r = dest(t.v[v]);
      if (r >= 0 && std::find(to, to + n, r) == to + n) to[n++] = r;
    }
    for (int k = 0; k < n; ++k) out[to[k]].push_back(t);
  }
  std::vector<int> counts(size);
  std::vector<TetrahedronRow> send;
  for (int r = 0; r < size; ++r) counts[r] = static_cast<int>(out[r].size()), send.insert(send.end(), out[r].begin(), out[r].end());
  const ExchangePlan plan(comm, std::move(counts));
  return forward_rows(plan, send);
}

// Faces from rank 0 to every rank (O(surface)).
void broadcast_faces(std::vector<NamedFace>& faces, MPI_Comm comm, int rank) {
  std::vector<char> buf;
  auto put = [&](const void* p, std::size_t n) { buf.insert(buf.end(), static_cast<const char*>(p), static_cast<const char*>(p) + n); };
  if (rank == 0) {
    const std::uint64_t count = faces.size();
    put(&count, 8);
    for (const auto& f : faces) {
      const std::uint64_t name = f.name.size(), ids = f.molecules.size();
      put(&f.body, sizeof f.body), put(&name, 8), put(f.name.data(), name), put(&ids, 8);
      put(f.molecules.data(), ids * 8), put(f.area.data(), ids * 8);
      put(&f.total_area, 8), put(f.centroid.data(), 24), put(&f.axis, sizeof f.axis), put(&f.side, sizeof f.side);
      put(&f.plane, 8);
      put(&f.anchor, 8), put(&f.anchor2, 8), put(&f.anchor2_component, sizeof f.anchor2_component);
    }
  }
  std::uint64_t bytes = buf.size();
  MPI_Bcast(&bytes, 1, MPI_UINT64_T, 0, comm);
  buf.resize(bytes);
  MPI_Bcast(buf.data(), static_cast<int>(bytes), MPI_CHAR, 0, comm);
  if (rank == 0) return;
  const char* p = buf.data();
  auto get = [&](void* q, std::size_t n) { std::memcpy(q, p, n), p += n; };
  std::uint64_t count;
  get(&count, 8);
  faces.assign(count, NamedFace{});
  for (auto& f : faces) {
    std::uint64_t name, ids;
    get(&f.body, sizeof f.body), get(&name, 8), f.name.assign(p, name), p += name, get(&ids, 8);
    f.molecules.resize(ids), f.area.resize(ids);
    get(f.molecules.data(), ids * 8), get(f.area.data(), ids * 8);
    get(&f.total_area, 8), get(f.centroid.data(), 24), get(&f.axis, sizeof f.axis), get(&f.side, sizeof f.side);
    get(&f.plane, 8);
    get(&f.anchor, 8), get(&f.anchor2, 8), get(&f.anchor2_component, sizeof f.anchor2_component);
  }
}

// Merges a chunk of edge records (in tetrahedron order) into `edges` (sorted by (a, b), distinct): the sums
// of a connection's tetrahedra stay in tetrahedron order (earlier chunks first, then the chunk in order).
void merge_edges(std::vector<Edge>& edges, std::vector<Edge>& chunk) {
  auto less = [](const Edge& x, const Edge& y) { return x.a != y.a ? x.a < y.a : x.b < y.b; };
  std::stable_sort(chunk.begin(), chunk.end(), less);
  std::vector<Edge> out;
  out.reserve(edges.size() + chunk.size());
  auto add = [&](const Edge& e) {
    if (!out.empty() && out.back().a == e.a && out.back().b == e.b)
      out.back().volume += e.volume, out.back().lloyd += e.lloyd;
    else
      out.push_back(e);
  };
  std::size_t i = 0, j = 0;
  while (i < edges.size() || j < chunk.size()) {
    if (j == chunk.size() || (i < edges.size() && !less(chunk[j], edges[i]))) add(edges[i++]);
    else add(chunk[j++]);
  }
  out.shrink_to_fit();
  edges = std::move(out);
  chunk = std::vector<Edge>();
}

}  // namespace

LocalModel build_explicit_model(const Scene& scene, MPI_Comm comm, CalibrationInputs& inputs,
                                const MeshReader& read_mesh) {
  LocalModel m;
  inputs = CalibrationInputs();
  m.comm = comm;
  MPI_Comm_rank(comm, &m.rank);
  MPI_Comm_size(comm, &m.size);
  const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
  const int nbodies = static_cast<int>(specs.size());

  // 1. Rank 0 reads every explicit body (the counts number the bodies one after another).
  struct Read {
    std::vector<std::array<std::int32_t, 4>> tets;  // the mesh's, as 4-byte ints: rank 0 holds them until handed out
    std::vector<std::int32_t> region;  // kept tetrahedra of a body with regions: each one's scene region (or -1)
    MeshMolecules molecules;
  };
  std::vector<Read> read(nbodies);
  // Bodies whose per-tetrahedron term needs their tetrahedra on the ranks (homogenized on a mesh or a cloud);
  // the others' tetrahedra are handed out as edges only.
  std::vector<char> keep_tetrahedra(nbodies, 0);
  bool any_tetrahedra = false;
  for (int i = 0; i < nbodies; ++i) {
    const CalibrationSpec& c = i < static_cast<int>(scene.calibrations.size()) ? scene.calibrations[i] : scene.calibration;
    keep_tetrahedra[i] = body_has_tetrahedra(specs[i], c);
    any_tetrahedra = any_tetrahedra || keep_tetrahedra[i];
  }
  std::vector<std::int64_t> count(nbodies, 0), tetrahedra(nbodies, 0);
  std::vector<double> total_volume(nbodies, 0.0);
  std::vector<NamedFace> faces;
  agree(comm, [&] {
    if (m.rank != 0) return;
    std::int64_t first = 0;
    for (int i = 0; i < nbodies; ++i) {
      const BodySpec& spec = specs[i];
      if (explicit_spec(spec)) {
        const std::string key = nbodies > 1 ? "body[" + std::to_string(i) + "]" : "body";
        if (spec.shape == BodySpec::Shape::mesh && !read_mesh) throw std::logic_error("build_explicit_model: a mesh body and no mesh reader");
        TetMesh mesh;
        if (spec.shape == BodySpec::Shape::mesh && spec.random)
          mesh = random_in_mesh(read_mesh(spec), spec, scene.file, key);
        else
          mesh = spec.shape == BodySpec::Shape::mesh ? read_mesh(spec) : random_cloud(spec);
        read[i].molecules = mesh_molecules(spec, mesh, first, scene.file, key);
        if (keep_tetrahedra[i] && !spec.regions.empty() && !mesh.tet_region.empty()) {
          // Each kept tetrahedron's scene region (the last naming its physical volume), for its material.
          std::vector<std::int32_t> spec_of(mesh.region_names.size(), -1);
          for (std::size_t r = 0; r < spec.regions.size(); ++r)
            for (std::size_t k = 0; k < mesh.region_names.size(); ++k)
              if (mesh.region_names[k] == spec.regions[r].name) spec_of[k] = static_cast<std::int32_t>(r);
          read[i].region.resize(mesh.tets.size());
          for (std::size_t t = 0; t < mesh.tets.size(); ++t)
            read[i].region[t] = mesh.tet_region[t] < 0 ? -1 : spec_of[mesh.tet_region[t]];
        }
        decltype(mesh.nodes)().swap(mesh.nodes), decltype(mesh.tet_region)().swap(mesh.tet_region);  // not `= {}`:
        decltype(mesh.surfaces)().swap(mesh.surfaces);  // that keeps the capacity
        count[i] = static_cast<std::int64_t>(read[i].molecules.points.size());
        if (count[i] > std::numeric_limits<std::int32_t>::max())
          throw std::runtime_error("the body has more molecules than 32-bit PETSc indices can address");
        tetrahedra[i] = static_cast<std::int64_t>(mesh.tets.size());
        read[i].tets.resize(mesh.tets.size());
        for (std::size_t t = 0; t < mesh.tets.size(); ++t)
          for (int v = 0; v < 4; ++v) read[i].tets[t][v] = static_cast<std::int32_t>(mesh.tets[t][v]);
        mesh = TetMesh();
        total_volume[i] = read[i].molecules.total_volume;
        for (auto& f : read[i].molecules.faces) f.body = i, faces.push_back(std::move(f));
        decltype(read[i].molecules.faces)().swap(read[i].molecules.faces);
      } else {
        count[i] = static_cast<std::int64_t>(spec.molecules[0]) * spec.molecules[1] * spec.molecules[2];
      }
      first += count[i];
    }
  });
  MPI_Bcast(count.data(), nbodies, MPI_INT64_T, 0, comm);
  MPI_Bcast(tetrahedra.data(), nbodies, MPI_INT64_T, 0, comm);
  MPI_Bcast(total_volume.data(), nbodies, MPI_DOUBLE, 0, comm);
  broadcast_faces(faces, comm, m.rank);

  // The bodies' geometry on every rank (explicit bodies' nominal size once the connections are known).
  m.shape = scene_shape(scene);
  std::int64_t first = 0;
  for (int i = 0; i < nbodies; ++i) {
    if (explicit_spec(specs[i])) {
      BoxGeometry g;
      g.count = count[i];
      g.topology = specs[i].topology;
      g.offset = specs[i].offset;
      g.total_volume = total_volume[i];
      m.shape.parts[i] = g;
    }
    m.shape.parts[i].first = first;
    first += count[i];
  }
  // The boxes' lattice faces (made again: a box after an explicit body starts where that body's count ends),
  // then the explicit bodies', ordered by body.
  m.shape.faces.clear();
  for (int i = 0; i < nbodies; ++i)
    if (!explicit_spec(specs[i]))
      for (auto& f : lattice_faces(m.shape.parts[i], i)) m.shape.faces.push_back(std::move(f));
  for (auto& f : faces) m.shape.faces.push_back(std::move(f));
  std::stable_sort(m.shape.faces.begin(), m.shape.faces.end(),
                   [](const NamedFace& x, const NamedFace& y) { return x.body < y.body; });
  check_face_names(scene, m.shape);
  const std::int64_t n = first;
  m.global_molecules = n;
  if (n * 3 > std::numeric_limits<PetscInt>::max())
    throw std::runtime_error("the body has more molecules than 32-bit PETSc indices can address");
  const Blocks blocks(n, m.size);
  const std::int64_t lo = blocks.begin[m.rank], hi = blocks.begin[m.rank + 1];
  std::vector<Molecule> mol(hi - lo);
  for (std::int64_t g = lo; g < hi; ++g) mol[g - lo].id = g, mol[g - lo].body = m.shape.body_of(g);

  // 2. Molecules to their directory ranks: box bodies' from their geometry, explicit bodies' from rank 0.
  std::vector<const TopologyStyle*> style(nbodies, nullptr);
  for (int i = 0; i < nbodies; ++i)
    if (!explicit_spec(specs[i])) style[i] = find_topology(specs[i].topology);  // checked by the scene reader
  for (auto& x : mol) {
    const BoxGeometry& box = m.shape.body(x.body);
    if (box.unstructured()) continue;
    const Vec3 p = box.rest_position(x.id);
    for (int d = 0; d < 3; ++d) x.x[d] = p[d];
    const MoleculeMaterial mat = molecule_material(specs[x.body], box, x.id);
    x.mass = mat.density * box.volume(x.id);
    x.youngs_modulus = mat.youngs_modulus;
  }
  for (int i = 0; i < nbodies; ++i) {
    if (!m.shape.body(i).unstructured()) continue;
    const std::int64_t b0 = m.shape.body(i).first, b1 = b0 + count[i];
    std::vector<int> counts(m.size), displs(m.size);
    for (int r = 0; r < m.size; ++r) {
      const std::int64_t s = std::clamp(blocks.begin[r], b0, b1), e = std::clamp(blocks.begin[r + 1], b0, b1);
      displs[r] = static_cast<int>(s - b0), counts[r] = static_cast<int>(e - s);
    }
    const int here = counts[m.rank];
    std::vector<double> x(3 * static_cast<std::size_t>(here)), mass(here), modulus(here);
    std::vector<int> counts3(m.size), displs3(m.size);
    for (int r = 0; r < m.size; ++r) counts3[r] = 3 * counts[r], displs3[r] = 3 * displs[r];
    const MeshMolecules& src = read[i].molecules;
    MPI_Scatterv(m.rank == 0 ? src.points.data() : nullptr, counts3.data(), displs3.data(), MPI_DOUBLE, x.data(),
                 3 * here, MPI_DOUBLE, 0, comm);
    MPI_Scatterv(m.rank == 0 ? src.mass.data() : nullptr, counts.data(), displs.data(), MPI_DOUBLE, mass.data(), here,
                 MPI_DOUBLE, 0, comm);
    MPI_Scatterv(m.rank == 0 ? src.youngs_modulus.data() : nullptr, counts.data(), displs.data(), MPI_DOUBLE,
                 modulus.data(), here, MPI_DOUBLE, 0, comm);
    const std::int64_t s = std::max(lo, b0);
    for (int k = 0; k < here; ++k) {
      Molecule& y = mol[s + k - lo];
      for (int d = 0; d < 3; ++d) y.x[d] = x[3 * k + d];
      y.mass = mass[k], y.youngs_modulus = modulus[k];
    }
  }

  //    Tetrahedra's edges to the directory rank of their lower end, chunk by chunk (and, for bodies that keep
  //    them, the tetrahedra themselves to the directory ranks of their corners).
  std::vector<Edge> edges;  // explicit bodies' connections with a in this block, sorted by (a, b)
  std::vector<TetrahedronRow> held;  // kept tetrahedra with a corner in this block
  std::int64_t first_tetrahedron = 0;
  for (int i = 0; i < nbodies; ++i) {
    if (!m.shape.body(i).unstructured()) continue;
    const std::int64_t b0 = m.shape.body(i).first, t_first = first_tetrahedron;
    first_tetrahedron += keep_tetrahedra[i] ? tetrahedra[i] : 0;  // dense ids over the kept bodies
    for (std::int64_t t0 = 0; t0 < tetrahedra[i]; t0 += kTetrahedraPerChunk) {
      const std::int64_t t1 = std::min<std::int64_t>(t0 + kTetrahedraPerChunk, tetrahedra[i]);
      std::vector<int> bytes(m.size, 0), displs(m.size, 0);
      std::vector<Edge> send;
      if (m.rank == 0) {
        const auto& tets = read[i].tets;
        const auto& x = read[i].molecules.points;
        std::vector<int> per(m.size, 0);
        for (std::int64_t t = t0; t < t1; ++t)
          for (int v = 0; v < 4; ++v)
            for (int w = v + 1; w < 4; ++w) ++per[blocks.owner(std::min(tets[t][v], tets[t][w]) + b0)];
        std::vector<std::size_t> next(m.size, 0);
        for (int r = 1; r < m.size; ++r) next[r] = next[r - 1] + per[r - 1];
        send.resize(6 * static_cast<std::size_t>(t1 - t0));
        for (int r = 0; r < m.size; ++r)
          bytes[r] = per[r] * static_cast<int>(sizeof(Edge)), displs[r] = static_cast<int>(next[r] * sizeof(Edge));
        for (std::int64_t t = t0; t < t1; ++t) {
          const auto& T = tets[t];
          const double volume = tetrahedron_volume(x[T[0]], x[T[1]], x[T[2]], x[T[3]]);
          const double lloyd = lloyd_edge(volume);
          for (int v = 0; v < 4; ++v)
            for (int w = v + 1; w < 4; ++w) {
              const std::int64_t a = std::min(T[v], T[w]) + b0, b = std::max(T[v], T[w]) + b0;
              send[next[blocks.owner(a)]++] = {a, b, volume, lloyd};
            }
        }
      }
      int mine = 0;
      MPI_Scatter(bytes.data(), 1, MPI_INT, &mine, 1, MPI_INT, 0, comm);
      std::vector<Edge> chunk(mine / sizeof(Edge));
      MPI_Scatterv(send.data(), bytes.data(), displs.data(), MPI_BYTE, chunk.data(), mine, MPI_BYTE, 0, comm);
      if (keep_tetrahedra[i]) {
        std::vector<TetrahedronRow> rows;
        if (m.rank == 0)
          for (std::int64_t t = t0; t < t1; ++t) {
            const auto& T = read[i].tets[t];
            rows.push_back({t_first + t, {T[0] + b0, T[1] + b0, T[2] + b0, T[3] + b0},
                            read[i].region.empty() ? -1 : read[i].region[t], 0});
          }
        const std::vector<TetrahedronRow> in =
            route_tetrahedra(comm, m.size, rows, [&](std::int64_t g) { return blocks.owner(g); });
        held.insert(held.end(), in.begin(), in.end());
      }
      send = std::vector<Edge>();
      merge_edges(edges, chunk);
    }
    read[i] = Read{};  // rank 0 frees this body's mesh
  }

  //    Each block molecule's connections to higher ids (box bodies' from the stencil), and their global ids.
  std::vector<std::int64_t> forward_start(hi - lo + 1, 0);
  std::vector<Edge> forward;
  std::vector<ConnectionClass> forward_class;
  bool all_explicit = true;
  for (const auto& spec : specs) all_explicit = all_explicit && explicit_spec(spec);
  if (all_explicit) forward = std::move(edges), forward_class.assign(forward.size(), ConnectionClass::edge);
  const std::vector<Edge>& merged = all_explicit ? forward : edges;
  agree(comm, [&] {
    std::vector<Neighbour> nb;
    std::size_t e = 0;  // the next of `merged`
    for (std::int64_t g = lo; g < hi; ++g) {
      const int b = mol[g - lo].body;
      const BoxGeometry& box = m.shape.body(b);
      if (box.unstructured()) {
        for (; e < merged.size() && merged[e].a == g; ++e)
          if (!all_explicit) forward.push_back(merged[e]), forward_class.push_back(ConnectionClass::edge);
      } else {
        lattice_neighbours(*style[b], box, g, nb);
        mol[g - lo].degree = static_cast<int>(nb.size());
        for (const auto& x : nb) {
          if (x.id < g) continue;
          double volume = 0, lloyd = 0;  // Kuhn tetrahedra, summed one by one as the whole-body path sums them
          if (style[b]->tetrahedra) {
            const double v = kuhn_tetrahedron_volume(box), l_equiv = lloyd_edge(v);
            for (int t = kuhn_tetrahedra_on(box, g, x.id); t > 0; --t) volume += v, lloyd += l_equiv;
          }
          forward.push_back({g, x.id, volume, lloyd}), forward_class.push_back(x.cls);
        }
      }
      forward_start[g - lo + 1] = static_cast<std::int64_t>(all_explicit ? e : forward.size());
      if (forward_start[g - lo + 1] - forward_start[g - lo] > 65535)
        throw std::runtime_error("a molecule has more than 65535 connections");
    }
  });
  edges = std::vector<Edge>();
  std::int64_t forward_total = static_cast<std::int64_t>(forward.size()), offset = 0;
  MPI_Exscan(&forward_total, &offset, 1, MPI_INT64_T, MPI_SUM, comm);
  if (m.rank == 0) offset = 0;
  for (std::int64_t g = lo; g < hi; ++g) mol[g - lo].first_connection = offset + forward_start[g - lo];
  MPI_Allreduce(&forward_total, &m.global_connections, 1, MPI_INT64_T, MPI_SUM, comm);

  //    The lower neighbours: each connection (a, b) told to b's directory, which then has whole rows.
  std::vector<std::int64_t> backward_start(hi - lo + 1, 0), backward;
  {
    std::vector<std::vector<std::int64_t>> out(m.size);
    for (const auto& c : forward) out[blocks.owner(c.b)].push_back(c.b), out[blocks.owner(c.b)].push_back(c.a);
    std::vector<std::int64_t> in = exchange(comm, std::move(out));
    std::vector<std::pair<std::int64_t, std::int64_t>> pairs(in.size() / 2);
    for (std::size_t k = 0; k < pairs.size(); ++k) pairs[k] = {in[2 * k], in[2 * k + 1]};
    in = std::vector<std::int64_t>();
    std::sort(pairs.begin(), pairs.end());
    backward.resize(pairs.size());
    for (std::size_t k = 0; k < pairs.size(); ++k) backward[k] = pairs[k].second, ++backward_start[pairs[k].first - lo + 1];
    for (std::int64_t k = 0; k < hi - lo; ++k) backward_start[k + 1] += backward_start[k];
  }
  for (std::int64_t g = lo; g < hi; ++g)
    if (m.shape.body(mol[g - lo].body).unstructured())
      mol[g - lo].degree = static_cast<int>(forward_start[g - lo + 1] - forward_start[g - lo] +
                                            backward_start[g - lo + 1] - backward_start[g - lo]);
  // Row g of the graph, ascending: lower neighbours, then higher ones.
  auto row = [&](std::int64_t g, std::vector<std::int64_t>& out) {
    out.clear();
    for (auto k = backward_start[g - lo]; k < backward_start[g - lo + 1]; ++k) out.push_back(backward[k]);
    for (auto k = forward_start[g - lo]; k < forward_start[g - lo + 1]; ++k) out.push_back(forward[k].b);
  };

  // 3. The partition.
  std::vector<int> part(hi - lo, 0);
  if (m.size > 1) {
    if (n < m.size) throw std::runtime_error("the body has fewer molecules than ranks");
    if (scene.partition.method == PartitionSpec::Method::ptscotch) {
      part = ptscotch_block(lo, hi, n, row, comm, m.partition);
    } else {
      // The graph on rank 0 as 4-byte ints, for the METIS call alone.
      std::vector<int> degree(hi - lo), adjncy_here;
      std::vector<std::int64_t> r;
      for (std::int64_t g = lo; g < hi; ++g) {
        row(g, r);
        degree[g - lo] = static_cast<int>(r.size());
        for (auto x : r) adjncy_here.push_back(static_cast<int>(x));
      }
      std::vector<int> rows(m.size), row_displs(m.size), entries(m.size), entry_displs(m.size);
      for (int q = 0; q < m.size; ++q)
        rows[q] = static_cast<int>(blocks.begin[q + 1] - blocks.begin[q]), row_displs[q] = static_cast<int>(blocks.begin[q]);
      const int here = static_cast<int>(adjncy_here.size());
      MPI_Gather(&here, 1, MPI_INT, entries.data(), 1, MPI_INT, 0, comm);
      std::vector<int> xadj, adjncy;
      if (m.rank == 0) {
        xadj.assign(n + 1, 0);
        std::int64_t total = 0;
        for (int q = 0; q < m.size; ++q) entry_displs[q] = static_cast<int>(total), total += entries[q];
        if (total > std::numeric_limits<int>::max()) throw std::runtime_error("the connection graph is too large for METIS's 32-bit indices");
        adjncy.resize(total);
      }
      MPI_Gatherv(degree.data(), static_cast<int>(degree.size()), MPI_INT, m.rank == 0 ? xadj.data() + 1 : nullptr,
                  rows.data(), row_displs.data(), MPI_INT, 0, comm);
      MPI_Gatherv(adjncy_here.data(), here, MPI_INT, adjncy.data(), entries.data(), entry_displs.data(), MPI_INT, 0, comm);
      degree = adjncy_here = std::vector<int>();
      if (m.rank == 0)
        for (std::int64_t g = 0; g < n; ++g) xadj[g + 1] += xadj[g];
      std::vector<int> all = partition_graph_on_rank0(std::move(xadj), std::move(adjncy), n, comm, m.partition);
      MPI_Scatterv(all.data(), rows.data(), row_displs.data(), MPI_INT, part.data(), static_cast<int>(hi - lo), MPI_INT,
                   0, comm);
    }
  }
  backward = std::vector<std::int64_t>(), backward_start = std::vector<std::int64_t>();
  for (std::int64_t g = lo; g < hi; ++g) mol[g - lo].part = part[g - lo];
  part = std::vector<int>();

  // 4. Molecules to their owners (blocks in rank order, ascending within: owned ids arrive sorted); the owners'
  //    PETSc block ids back to the directory.
  std::vector<Molecule> owned_rows;
  {
    std::vector<int> counts(m.size, 0);
    for (const auto& x : mol) ++counts[x.part];
    std::vector<std::size_t> order(mol.size());
    {
      std::vector<std::size_t> next(m.size, 0);
      for (int r = 1; r < m.size; ++r) next[r] = next[r - 1] + counts[r - 1];
      for (std::size_t k = 0; k < mol.size(); ++k) order[next[mol[k].part]++] = k;
    }
    std::vector<Molecule> send(mol.size());
    for (std::size_t k = 0; k < order.size(); ++k) send[k] = mol[order[k]];
    const ExchangePlan plan(comm, std::move(counts));
    owned_rows = forward_rows(plan, send);
    m.owned = static_cast<int>(owned_rows.size());
    long long owned = m.owned, before = 0;
    MPI_Exscan(&owned, &before, 1, MPI_LONG_LONG, MPI_SUM, comm);
    if (m.rank == 0) before = 0;
    m.first_block = static_cast<PetscInt>(before);
    std::vector<std::int64_t> block(m.owned), back(order.size());
    for (int i = 0; i < m.owned; ++i) block[i] = m.first_block + i, owned_rows[i].block = block[i];
    plan.backward(block.data(), back.data());
    for (std::size_t k = 0; k < order.size(); ++k) mol[order[k]].block = back[k];
  }

  //    Kept tetrahedra to the owners of their corners (a tetrahedron with corners in several blocks arrives more
  //    than once: kept once, in increasing id).
  std::vector<TetrahedronRow> mine_tetrahedra;
  if (any_tetrahedra) {
    mine_tetrahedra = route_tetrahedra(comm, m.size, held, [&](std::int64_t g) {
      return g >= lo && g < hi ? mol[g - lo].part : -1;
    });
    held = std::vector<TetrahedronRow>();
    std::sort(mine_tetrahedra.begin(), mine_tetrahedra.end(),
              [](const TetrahedronRow& x, const TetrahedronRow& y) { return x.id < y.id; });
    mine_tetrahedra.erase(std::unique(mine_tetrahedra.begin(), mine_tetrahedra.end(),
                                      [](const TetrahedronRow& x, const TetrahedronRow& y) { return x.id == y.id; }),
                          mine_tetrahedra.end());
  }

  //    The directory's view of its connections' upper ends (part; position for the nominal size).
  std::vector<std::int64_t> outside;
  for (const auto& c : forward)
    if (c.b >= hi) outside.push_back(c.b);
  sort_unique(outside);
  const std::vector<Molecule> outside_rows = ask(comm, blocks, mol, outside);
  auto upper = [&](std::int64_t b) -> const Molecule& {
    if (b < hi) return mol[b - lo];
    return outside_rows[std::lower_bound(outside.begin(), outside.end(), b) - outside.begin()];
  };
  //    Explicit bodies' nominal size: the connection lengths summed in the global order, rank after rank.
  {
    std::vector<double> sum(nbodies, 0.0);
    std::vector<std::int64_t> connections(nbodies, 0), all(nbodies, 0);
    if (m.rank > 0) MPI_Recv(sum.data(), nbodies, MPI_DOUBLE, m.rank - 1, 0, comm, MPI_STATUS_IGNORE);
    for (const auto& c : forward) {
      const Molecule& a = mol[c.a - lo];
      if (!m.shape.body(a.body).unstructured()) continue;
      const Molecule& b = upper(c.b);
      sum[a.body] += edge_length({a.x[0], a.x[1], a.x[2]}, {b.x[0], b.x[1], b.x[2]});
      ++connections[a.body];
    }
    if (m.rank + 1 < m.size) MPI_Send(sum.data(), nbodies, MPI_DOUBLE, m.rank + 1, 0, comm);
    MPI_Bcast(sum.data(), nbodies, MPI_DOUBLE, m.size - 1, comm);
    MPI_Allreduce(connections.data(), all.data(), nbodies, MPI_INT64_T, MPI_SUM, comm);
    for (int i = 0; i < nbodies; ++i)
      if (m.shape.body(i).unstructured()) set_nominal_size(m.shape.parts[i], specs[i], sum[i], all[i]);
    static_cast<BoxGeometry&>(m.shape) = m.shape.parts[0];
  }

  //    Connections to the owners of their ends (once when both ends have one owner).
  std::vector<ConnectionRow> rows;
  {
    std::vector<int> counts(m.size, 0);
    for (const auto& c : forward) {
      const int pa = mol[c.a - lo].part, pb = upper(c.b).part;
      ++counts[pa];
      if (pb != pa) ++counts[pb];
    }
    std::vector<std::size_t> next(m.size, 0);
    for (int r = 1; r < m.size; ++r) next[r] = next[r - 1] + counts[r - 1];
    std::vector<ConnectionRow> send(next[m.size - 1] + counts[m.size - 1]);
    for (std::size_t k = 0; k < forward.size(); ++k) {
      const Edge& c = forward[k];
      const Molecule& a = mol[c.a - lo];
      const ConnectionRow r{c.a, c.b, a.first_connection + static_cast<std::int64_t>(k) - forward_start[c.a - lo],
                            c.volume, c.lloyd, static_cast<std::int32_t>(forward_class[k]), 0};
      const int pb = upper(c.b).part;
      send[next[a.part]++] = r;
      if (pb != a.part) send[next[pb]++] = r;
    }
    forward = std::vector<Edge>(), forward_class = std::vector<ConnectionClass>();
    const ExchangePlan plan(comm, std::move(counts));
    rows = forward_rows(plan, send);
  }
  std::sort(rows.begin(), rows.end(), [](const ConnectionRow& x, const ConnectionRow& y) { return x.id < y.id; });

  //    Ghosts: the ends another rank owns; their rows from the directory.
  std::vector<std::int64_t> owned_ids(m.owned), ghosts;
  for (int i = 0; i < m.owned; ++i) owned_ids[i] = owned_rows[i].id;
  auto owned_index = [&](std::int64_t g) {
    auto it = std::lower_bound(owned_ids.begin(), owned_ids.end(), g);
    return it != owned_ids.end() && *it == g ? static_cast<long>(it - owned_ids.begin()) : -1L;
  };
  for (const auto& c : rows) {
    if (owned_index(c.a) < 0) ghosts.push_back(c.a);
    if (owned_index(c.b) < 0) ghosts.push_back(c.b);
  }
  sort_unique(ghosts);
  std::vector<Molecule> local_rows = ask(comm, blocks, mol, ghosts);
  mol = std::vector<Molecule>();
  local_rows.insert(local_rows.begin(), owned_rows.begin(), owned_rows.end());
  owned_rows = std::vector<Molecule>();

  // The rank's LocalModel: owned molecules, then ghosts; connections in the global order.
  m.local = static_cast<int>(local_rows.size());
  {
    std::vector<std::int64_t> id(m.local);
    std::vector<PetscInt> block(m.local);
    std::vector<int> body(m.local);
    m.rest.resize(3 * m.local), m.mass.resize(m.local);
    inputs.youngs_modulus.resize(m.local), inputs.degree.resize(m.local);
    std::vector<std::int64_t> first(m.local);
    for (int i = 0; i < m.local; ++i) {
      const Molecule& x = local_rows[i];
      id[i] = x.id, block[i] = static_cast<PetscInt>(x.block);
      for (int d = 0; d < 3; ++d) m.rest[3 * i + d] = x.x[d];
      m.mass[i] = x.mass, inputs.youngs_modulus[i] = x.youngs_modulus, inputs.degree[i] = x.degree, body[i] = x.body;
      first[i] = x.first_connection;
    }
    m.id.assign(id), m.block.assign(block), m.body.assign(body), m.first_connection.assign(first);
  }
  local_rows = std::vector<Molecule>();
  auto local_index = [&](std::int64_t g) {
    const long o = owned_index(g);
    return static_cast<int>(o >= 0 ? o : m.owned + (std::lower_bound(ghosts.begin(), ghosts.end(), g) - ghosts.begin()));
  };
  const std::size_t nc = rows.size();
  std::vector<int> end_a(nc), end_b(nc);
  m.forward_rank.resize(nc), m.connection_class.resize(nc);
  std::vector<double> rest_length(nc);
  inputs.tetra_volume.resize(nc), inputs.tetra_lloyd_sum.resize(nc);
  for (std::size_t l = 0; l < nc; ++l) {
    const ConnectionRow& c = rows[l];
    const int a = local_index(c.a), b = local_index(c.b);
    end_a[l] = a, end_b[l] = b;
    m.forward_rank[l] = static_cast<std::uint16_t>(c.id - m.first_connection[a]);
    m.connection_class[l] = static_cast<ConnectionClass>(c.cls);
    const BoxGeometry& box = m.shape.part(c.a);
    rest_length[l] = box.unstructured()
                           ? Body::point_distance({m.rest[3 * a], m.rest[3 * a + 1], m.rest[3 * a + 2]},
                                                  {m.rest[3 * b], m.rest[3 * b + 1], m.rest[3 * b + 2]})
                           : box.rest_distance(c.a, c.b);
    inputs.tetra_volume[l] = c.volume, inputs.tetra_lloyd_sum[l] = c.lloyd;
    if (a < m.owned) ++m.written_count;
  }
  m.table.set_rest_lengths(std::move(rest_length));
  m.end_a.assign(std::move(end_a)), m.end_b.assign(std::move(end_b));
  //    The kept tetrahedra in local indices: every corner is an end of a connection of the owned corner (the
  //    tetrahedron's edges are connections), hence local.
  agree(comm, [&] {
    for (const auto& t : mine_tetrahedra) {
      int v[4];
      for (int c = 0; c < 4; ++c) {
        v[c] = local_index(t.v[c]);
        if (v[c] >= m.local || m.id[v[c]] != t.v[c])
          throw std::logic_error("build_explicit_model: a tetrahedron's corner is not local");
      }
      m.tetrahedron_id.push_back(t.id);
      m.tetrahedron_region.push_back(t.region);
      m.tetrahedra.insert(m.tetrahedra.end(), v, v + 4);
    }
  });

  m.partition.surface_to_volume = largest_ghost_ratio(m);
  return m;
}

}  // namespace tissue
