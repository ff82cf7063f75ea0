#include "partition/lattice_model.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include "partition/exchange.hpp"
#include "partition/metis_partition.hpp"
#include "partition/natural_order.hpp"
#include "src/model/cell_law.hpp"
#include "src/model/topology.hpp"

namespace tissue {
namespace {

// The directory's exchanges: int64 items, `width` values each, grouped by destination rank; returns what arrives
// grouped by source rank, and the item count per source.
std::vector<std::int64_t> exchange_items(MPI_Comm comm, const std::vector<std::vector<std::int64_t>>& out, int width,
                                         std::vector<int>& received) {
  std::vector<std::int64_t> in = exchange(comm, out, &received);
  for (int& r : received) r /= width;
  return in;
}

// The index of id in the sorted range [begin, begin + n), or -1.
long find_sorted(const std::int64_t* begin, long n, std::int64_t id) {
  const std::int64_t* it = std::lower_bound(begin, begin + n, id);
  return (it != begin + n && *it == id) ? static_cast<long>(it - begin) : -1;
}
long find_sorted(const std::vector<std::int64_t>& v, std::int64_t id) {
  return find_sorted(v.data(), static_cast<long>(v.size()), id);
}

// The same, searched outward from v[hint] in doubling steps: a lattice neighbour's id is close to its molecule's,
// so this touches a few nearby entries where a binary search over the whole rank touches ~log2(n) far ones (at
// 10^6 molecules the binary searches were most of the set-up's time).
long find_sorted_near(const std::int64_t* v, long n, long hint, std::int64_t id) {
  if (n == 0) return -1;
  hint = std::min(std::max(hint, 0L), n - 1);
  // Ids are distinct integers, so v[hint + d] >= v[hint] + d: where the rank owns every id in between (one rank,
  // or inside a partition block), id sits exactly id - v[hint] entries further on; otherwise before that.
  // Likewise below: v[hint - d] <= v[hint] - d, so id sits no further back than id - v[hint] entries.
  if (v[hint] < id) {
    const long guess = hint + static_cast<long>(std::min<std::int64_t>(id - v[hint], n - 1 - hint));
    if (v[guess] == id) return guess;
    hint = guess;
  } else if (v[hint] > id) {
    const long guess = hint - static_cast<long>(std::min<std::int64_t>(v[hint] - id, hint));
    if (v[guess] == id) return guess;
    hint = guess;
  }
  long lo, hi;  // id, if present, lies in [lo, hi)
  if (v[hint] < id) {
    long q = hint + 1, step = 1;
    lo = q;
    while (q < n && v[q] < id) lo = q + 1, q += step, step *= 2;
    hi = std::min(q + 1, n);
  } else {
    long q = hint, step = 1;
    hi = hint + 1;
    while (q >= 0 && v[q] > id) hi = q, q -= step, step *= 2;
    lo = std::max(q, 0L);
  }
  if (lo >= hi) return -1;
  const long k = find_sorted(v + lo, hi - lo, id);
  return k < 0 ? -1 : lo + k;
}

bool any_viscoelastic(const Scene& s) {
  auto body = [](const BodySpec& b) {
    if (!b.viscoelastic.empty()) return true;
    for (const auto& r : b.regions)
      if (!r.viscoelastic.empty()) return true;
    return false;
  };
  if (body(s.body)) return true;
  for (const auto& b : s.bodies)
    if (body(b)) return true;
  return false;
}

// Whether the lattice's connection ends are kept as runs of rows (ConnectionEnd, 71 B a molecule less, the same
// values). The dynamic solver's step reads them through the kernel's stencil segments and every other reader of
// a dynamic run (guards, output, calibration) in connection order, where a run is found at once. Not for the
// other solvers, whose tangent reads connections out of order (a binary search each), nor with the terms that
// read every connection's ends each step (viscoelastic, contact), nor the calibration methods that follow
// molecules' neighbours (angles) or run the solver (iterative): they would pay the lookups.
bool ends_as_runs(const Scene& s) {
  if (s.solver.kind != "dynamic" || s.physics.contact || any_viscoelastic(s)) return false;
  auto out_of_order = [](const CalibrationSpec& c) {
    return c.method == "angles" || c.method == "angles-update" || c.method == "iterative";
  };
  if (out_of_order(s.calibration)) return false;
  for (const auto& c : s.calibrations)
    if (out_of_order(c)) return false;
  return true;
}

}  // namespace

LocalModel build_lattice_model(const Scene& scene, MPI_Comm comm, CalibrationInputs& inputs) {
  LocalModel m;
  inputs = CalibrationInputs();
  m.comm = comm;
  MPI_Comm_rank(comm, &m.rank);
  MPI_Comm_size(comm, &m.size);
  m.shape = scene_shape(scene);
  const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
  const int nbodies = m.shape.bodies();
  std::vector<const TopologyStyle*> style(nbodies);
  for (int b = 0; b < nbodies; ++b) style[b] = find_topology(m.shape.body(b).topology);  // checked by the reader
  const std::int64_t n = m.shape.molecules();
  m.global_molecules = n;
  if (n * 3 > std::numeric_limits<PetscInt>::max())
    throw std::runtime_error("the body has more molecules than 32-bit PETSc indices can address");
  std::vector<LatticeStencil> stencil;
  for (int b = 0; b < nbodies; ++b) stencil.emplace_back(*style[b], m.shape.body(b));
  std::vector<Neighbour> nb;
  auto neighbours = [&](std::int64_t g) {
    const int b = m.shape.body_of(g);
    stencil[b].neighbours(g, nb);
    return b;
  };
  // The counting passes need the numbers alone: no list for a molecule the whole stencil fits around.
  auto counts = [&](std::int64_t g, int& degree, int& forward) {
    const int b = m.shape.body_of(g);
    stencil[b].counts(g, nb, degree, forward);
    return b;
  };

  // 1-2. This rank's block of the natural order, and the part (owning rank) of each of its molecules.
  const std::int64_t begin = NaturalOrder::block_begin(n, m.size, m.rank);
  const std::int64_t end = NaturalOrder::block_begin(n, m.size, m.rank + 1);
  std::vector<int> part = partition_lattice(m.shape, comm, m.partition, scene.partition.method);

  // The global connection order is (a, b) with a < b: molecule g's connections to higher ids come right after
  // those of every lower id. A prefix sum of these forward counts over the blocks gives each molecule's first
  // connection id.
  std::vector<std::int64_t> first_connection(end - begin);
  std::int64_t forward_total = 0;
  for (std::int64_t g = begin; g < end; ++g) {
    int degree, forward;
    counts(g, degree, forward);
    first_connection[g - begin] = forward_total;
    forward_total += forward;
  }
  std::int64_t offset = 0;
  MPI_Exscan(&forward_total, &offset, 1, MPI_INT64_T, MPI_SUM, comm);
  if (m.rank == 0) offset = 0;
  for (auto& f : first_connection) f += offset;
  MPI_Allreduce(&forward_total, &m.global_connections, 1, MPI_INT64_T, MPI_SUM, comm);

  // 3. Molecules to their owners, with their first connection id. Blocks arrive in rank order and ascend within,
  //    so the owned ids arrive sorted.
  //    Placed straight into one send buffer by destination (lists per rank were copied into it, and grew by
  //    doubling: every byte written two or three times, each a first touch of fresh pages).
  std::vector<int> from;
  std::vector<std::int64_t> in;
  {
    std::vector<int> going(m.size, 0);
    for (int p : part) ++going[p];
    std::vector<std::size_t> at(m.size, 0);
    for (int r = 1; r < m.size; ++r) at[r] = at[r - 1] + 2 * static_cast<std::size_t>(going[r - 1]);
    std::vector<std::int64_t> send(2 * static_cast<std::size_t>(end - begin));
    for (std::int64_t g = begin; g < end; ++g) {
      std::size_t& k = at[part[g - begin]];
      send[k] = g, send[k + 1] = first_connection[g - begin];
      k += 2;
    }
    const ExchangePlan plan(comm, std::move(going));  // items of two values
    from = plan.recv_counts();
    in.resize(2 * plan.received());
    plan.forward(send.data(), in.data(), 2);
  }
  m.owned = static_cast<int>(in.size() / 2);
  std::vector<std::int64_t> owned_ids(m.owned), owned_first(m.owned);
  for (int i = 0; i < m.owned; ++i) owned_ids[i] = in[2 * i], owned_first[i] = in[2 * i + 1];
  in = std::vector<std::int64_t>();
  long long owned = m.owned, before = 0;
  MPI_Exscan(&owned, &before, 1, MPI_LONG_LONG, MPI_SUM, comm);
  if (m.rank == 0) before = 0;
  m.first_block = static_cast<PetscInt>(before);

  // 4. The directory: each block rank learns the PETSc block id of its molecules (owners answer in the order
  //    they received them).
  std::vector<PetscInt> directory_block(end - begin);
  {
    std::vector<std::vector<std::int64_t>> back(m.size);
    int i = 0;
    for (int r = 0; r < m.size; ++r) {
      back[r].reserve(from[r]);
      for (int k = 0; k < from[r]; ++k, ++i) back[r].push_back(m.first_block + i);
    }
    std::vector<int> got;
    std::vector<std::int64_t> blocks = exchange_items(comm, back, 1, got);
    std::vector<std::size_t> next(m.size + 1, 0);  // where each owner's answers start
    for (int r = 0; r < m.size; ++r) next[r + 1] = next[r] + got[r];
    for (std::int64_t g = begin; g < end; ++g) directory_block[g - begin] = static_cast<PetscInt>(blocks[next[part[g - begin]]++]);
  }

  // Ghosts: the neighbours of owned molecules that another rank owns. A body with the cell term
  // (src/model/cell_law.hpp) needs every corner of every cell an owned molecule is in: its whole 3 x 3 x 3
  // neighbourhood, which the face-diagonals stencil lacks the body-diagonal corners of.
  std::vector<char> cells(nbodies, 0);
  for (int b = 0; b < nbodies; ++b)
    cells[b] = body_has_cells(specs[b], b < static_cast<int>(scene.calibrations.size()) ? scene.calibrations[b]
                                                                                           : scene.calibration);
  // Owned ids that are one run (every rank of a box bisection's slabs, one rank): owned is a range test.
  const bool contiguous = m.owned > 0 && owned_ids.back() - owned_ids.front() == m.owned - 1;
  const std::int64_t first_owned = m.owned > 0 ? owned_ids.front() : 0;
  auto is_owned = [&](std::int64_t id, long near) {
    if (contiguous) return id >= first_owned && id - first_owned < m.owned;
    return find_sorted_near(owned_ids.data(), m.owned, near, id) >= 0;
  };
  std::vector<std::int64_t> ghosts;
  for (long i = 0; i < m.owned; ++i) {
    if (contiguous) {  // a whole stencil inside the owned run has no ghost: no list
      const int b = m.shape.body_of(owned_ids[i]);
      std::int64_t lowest, highest;
      if (!cells[b] && stencil[b].interior(owned_ids[i], lowest, highest) && lowest >= first_owned &&
          highest - first_owned < m.owned)
        continue;
    }
    const int b = neighbours(owned_ids[i]);
    for (const auto& x : nb)
      if (!is_owned(x.id, i)) ghosts.push_back(x.id);
    if (!cells[b]) continue;
    const BoxGeometry& box = m.shape.body(b);
    const auto ijk = box.index(owned_ids[i]);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const long q[3] = {ijk[0] + dx, ijk[1] + dy, ijk[2] + dz};
          if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= box.n[0] || q[1] >= box.n[1] || q[2] >= box.n[2]) continue;
          const std::int64_t g = box.id(q[0], q[1], q[2]);
          if (!is_owned(g, i)) ghosts.push_back(g);
        }
  }
  std::sort(ghosts.begin(), ghosts.end());
  ghosts.erase(std::unique(ghosts.begin(), ghosts.end()), ghosts.end());

  // Ask the directory for each ghost's block id and first connection id.
  std::vector<std::int64_t> ghost_first(ghosts.size());
  std::vector<PetscInt> ghost_block(ghosts.size());
  {
    std::vector<std::vector<std::int64_t>> ask(m.size);
    for (std::int64_t g : ghosts) ask[NaturalOrder::block_owner(n, m.size, g)].push_back(g);
    std::vector<int> asked;
    std::vector<std::int64_t> questions = exchange_items(comm, ask, 1, asked);
    std::vector<std::vector<std::int64_t>> answer(m.size);
    std::size_t q = 0;
    for (int r = 0; r < m.size; ++r) {
      answer[r].reserve(2 * asked[r]);
      for (int k = 0; k < asked[r]; ++k, ++q) {
        const std::int64_t g = questions[q];
        answer[r].push_back(directory_block[g - begin]);
        answer[r].push_back(first_connection[g - begin]);
      }
    }
    std::vector<int> answered;
    std::vector<std::int64_t> answers = exchange_items(comm, answer, 2, answered);
    // Answers come back grouped by directory rank, in the order asked; ghosts are sorted, and so are blocks.
    std::vector<std::size_t> next(m.size + 1, 0);
    for (int r = 0; r < m.size; ++r) next[r + 1] = next[r] + 2 * answered[r];
    for (std::size_t i = 0; i < ghosts.size(); ++i) {
      std::size_t& k = next[NaturalOrder::block_owner(n, m.size, ghosts[i])];
      ghost_block[i] = static_cast<PetscInt>(answers[k]), ghost_first[i] = answers[k + 1];
      k += 2;
    }
  }
  part = std::vector<int>(), directory_block = std::vector<PetscInt>(), first_connection = std::vector<std::int64_t>();

  // Per-molecule arrays: owned, then ghosts.
  m.local = m.owned + static_cast<int>(ghosts.size());
  // The ids as a plain array while the connections are built (searched by address), stored as runs after.
  std::vector<std::int64_t> ids = owned_ids;
  ids.insert(ids.end(), ghosts.begin(), ghosts.end());
  std::vector<PetscInt> block(m.local);
  std::vector<int> body(m.local);
  m.rest.resize(3 * m.local), m.mass.resize(m.local);
  inputs.youngs_modulus.resize(m.local), inputs.degree.resize(m.local);
  std::vector<std::int64_t> first(m.local);
  // The connection arrays below are reserved once for every local molecule's forward connections (no doubling at
  // the peak): a bound, not the count (a ghost's connections to other ghosts are not kept), counted here from the
  // stencil alone, without the owner searches of the walk; the pages of the unused rest are never touched.
  std::size_t count = 0;
  for (int i = 0; i < m.local; ++i) {
    first[i] = i < m.owned ? owned_first[i] : ghost_first[i - m.owned];
    const std::int64_t g = ids[i];
    block[i] = i < m.owned ? m.first_block + i : ghost_block[i - m.owned];
    int degree, forward;
    const int b = counts(g, degree, forward);
    count += forward;
    const BoxGeometry& box = m.shape.body(b);
    const Vec3 x = box.rest_position(g);
    for (int d = 0; d < 3; ++d) m.rest[3 * i + d] = x[d];
    const MoleculeMaterial mat = molecule_material(specs[b], box, g);
    m.mass[i] = mat.density * box.volume(g);
    inputs.youngs_modulus[i] = mat.youngs_modulus;
    inputs.degree[i] = degree;
    body[i] = b;
  }
  m.block.assign(block), m.body.assign(body), m.first_connection.assign(first);
  block = std::vector<PetscInt>(), body = std::vector<int>(), first = std::vector<std::int64_t>();
  owned_ids = owned_first = ghost_first = std::vector<std::int64_t>();  // ids and m.first_connection hold them
  // Owned molecule g's local index, searched from `near` (an owned index next to g in id order).
  auto owned_index = [&](std::int64_t g, long near) -> long {
    if (contiguous) return g >= first_owned && g - first_owned < m.owned ? static_cast<long>(g - first_owned) : -1;
    return find_sorted_near(ids.data(), m.owned, near, g);
  };

  // 5. Connections with at least one owned end: walk the local molecules in increasing id and emit each one's
  //    forward connections, which yields the global (a, b) order directly.
  std::vector<int> order(m.local);  // local indices by increasing id (owned and ghosts interleave)
  {
    std::vector<int> sequence(m.local);
    for (int i = 0; i < m.local; ++i) sequence[i] = i;
    std::merge(sequence.begin(), sequence.begin() + m.owned, sequence.begin() + m.owned, sequence.end(),
               order.begin(), [&](int x, int y) { return ids[x] < ids[y]; });
  }
  bool any_tetrahedra = false;
  for (int b = 0; b < nbodies; ++b) any_tetrahedra = any_tetrahedra || style[b]->tetrahedra;
  // Rest lengths by type (LocalModel::length_type): the distinct lengths by their bits, with the last length
  // seen at each forward position as a shortcut (neighbouring molecules repeat their stencil's lengths).
  std::vector<std::uint16_t> length_types;  // per connection
  std::vector<double> length_table;
  std::unordered_map<std::uint64_t, std::uint16_t> length_index;
  std::vector<std::pair<std::uint64_t, int>> recent;  // per forward position: (bits, type), type -1: none yet
  // Each body's stencil direction has one rest length: its type, once found, is kept by direction (-1: not yet).
  std::vector<std::vector<int>> direction_type(nbodies);
  for (int b = 0; b < nbodies; ++b) direction_type[b].assign(stencil[b].directions(), -1);
  auto length_type = [&](int forward, double l) {
    std::uint64_t bits;
    std::memcpy(&bits, &l, 8);
    if (forward >= static_cast<int>(recent.size())) recent.resize(forward + 1, {0, -1});
    if (recent[forward].second >= 0 && recent[forward].first == bits)
      return static_cast<std::uint16_t>(recent[forward].second);
    auto [it, added] = length_index.try_emplace(bits, static_cast<std::uint16_t>(length_table.size()));
    if (added) {
      if (length_table.size() == 65536) throw std::runtime_error("more than 65,536 distinct rest lengths in a lattice");
      length_table.push_back(l);
    }
    recent[forward] = {bits, static_cast<int>(it->second)};
    return it->second;
  };
  std::vector<int> end_a, end_b;
  auto walk = [&]() {
    long owned_before = 0;  // owned molecules with ids below a: where a sits among them
    // A molecule's forward connections gathered here, then appended in one go per array (not a push_back each).
    std::size_t widest = 0;
    for (int b = 0; b < nbodies; ++b) widest = std::max(widest, stencil[b].directions());
    std::vector<int> row_b(widest);
    std::vector<ConnectionClass> row_class(widest);
    std::vector<std::uint16_t> row_type(widest);
    // Per body, once every forward direction's length type is known: the forward rows' classes and types, the
    // same for every interior molecule (empty: not yet).
    std::vector<std::vector<ConnectionClass>> forward_class(nbodies);
    std::vector<std::vector<std::uint16_t>> forward_type(nbodies);
    auto forward_rows_known = [&](int b) {
      if (!forward_type[b].empty()) return true;
      const LatticeStencil& st = stencil[b];
      for (std::size_t s = st.forward_begin(); s < st.directions(); ++s)
        if (direction_type[b][s] < 0) return false;
      for (std::size_t s = st.forward_begin(); s < st.directions(); ++s)
        forward_class[b].push_back(st.connection_class(s)),
            forward_type[b].push_back(static_cast<std::uint16_t>(direction_type[b][s]));
      return !forward_type[b].empty();
    };
    for (int i : order) {
      const std::int64_t a = ids[i];
      const bool a_owned = i < m.owned;
      const long near = a_owned ? i : owned_before;
      owned_before += a_owned;
      if (contiguous && a_owned && !any_tetrahedra) {
        // An owned molecule with its whole stencil and its highest neighbour in the owned run: every forward
        // neighbour is owned, at local index i + step (owned index = id - first owned id), in stencil order:
        // the rows the list below would give, without the list or a lookup a neighbour.
        const int b = m.shape.body_of(a);
        std::int64_t lowest, highest;
        if (stencil[b].interior(a, lowest, highest) && highest - first_owned < m.owned && forward_rows_known(b)) {
          const LatticeStencil& st = stencil[b];
          const std::size_t f0 = st.forward_begin(), nf = forward_type[b].size();
          for (std::size_t s = f0; s < f0 + nf; ++s) end_a.push_back(i), end_b.push_back(static_cast<int>(i + st.step(s)));
          m.connection_class.insert(m.connection_class.end(), forward_class[b].begin(), forward_class[b].end());
          length_types.insert(length_types.end(), forward_type[b].begin(), forward_type[b].end());
          m.written_count += nf;
          continue;
        }
      }
      const int b = neighbours(a);
      const BoxGeometry& box = m.shape.body(b);
      int rank_of_b = 0;  // position of the connection among a's forward ones
      int row = 0;
      for (const auto& x : nb) {
        if (x.id < a) continue;
        const int forward = rank_of_b++;
        const long owned_j = owned_index(x.id, near);
        if (!a_owned && owned_j < 0) continue;
        const int j = static_cast<int>(owned_j >= 0 ? owned_j : m.owned + find_sorted(ghosts, x.id));
        int& known = direction_type[b][x.direction];
        if (known < 0) known = length_type(forward, stencil[b].rest_distance(x));
        row_b[row] = j, row_class[row] = x.cls, row_type[row] = static_cast<std::uint16_t>(known);
        ++row;
        if (any_tetrahedra) {
          // Tetrahedra incident on the connection (Van Gelder's Eq. 5, Lloyd's sum): every Kuhn tetrahedron of
          // a box has the same volume; summed one by one, as the explicit path sums them.
          double volume = 0, lloyd = 0;
          if (style[b]->tetrahedra) {
            const double v = kuhn_tetrahedron_volume(box), l_equiv = std::cbrt(6.0 * std::sqrt(2.0) * v);
            for (int t = kuhn_tetrahedra_on(box, a, x.id); t > 0; --t) volume += v, lloyd += l_equiv;
          }
          inputs.tetra_volume.push_back(volume), inputs.tetra_lloyd_sum.push_back(lloyd);
        }
      }
      end_a.insert(end_a.end(), row, i);
      end_b.insert(end_b.end(), row_b.begin(), row_b.begin() + row);
      m.connection_class.insert(m.connection_class.end(), row_class.begin(), row_class.begin() + row);
      length_types.insert(length_types.end(), row_type.begin(), row_type.begin() + row);
      if (a_owned) m.written_count += row;
    }
  };
  end_a.reserve(count), end_b.reserve(count);
  m.connection_class.reserve(count), length_types.reserve(count);
  if (any_tetrahedra) inputs.tetra_volume.reserve(count), inputs.tetra_lloyd_sum.reserve(count);
  walk();
  m.end_a.assign(std::move(end_a)), m.end_b.assign(std::move(end_b));
  // Before the per-connection k (8 B a connection, set below) joins them at the set-up peak.
  if (ends_as_runs(scene)) ConnectionEnd::to_runs(m.end_a, m.end_b);
  m.table.set_rest_lengths(std::move(length_types), std::move(length_table));
  m.id.assign(ids);

  m.partition.surface_to_volume = largest_ghost_ratio(m);
  return m;
}

}  // namespace tissue
