#include "src/model/topology.hpp"

#include <algorithm>
#include <iterator>

namespace tissue {
namespace {

// Stencils: the offsets of each topology's neighbours.
std::vector<StencilOffset> axis_offsets() {
  return {{{1, 0, 0}}, {{-1, 0, 0}}, {{0, 1, 0}}, {{0, -1, 0}}, {{0, 0, 1}}, {{0, 0, -1}}};
}
std::vector<StencilOffset> with_face_diagonals(std::vector<StencilOffset> s) {
  for (int axis = 0; axis < 3; ++axis) {  // both diagonals of the faces normal to `axis`
    int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (int su : {-1, 1})
      for (int sv : {-1, 1}) {
        StencilOffset o{{0, 0, 0}};
        o.d[u] = su, o.d[v] = sv;
        s.push_back(o);
      }
  }
  return s;
}
std::vector<StencilOffset> with_body_diagonals(std::vector<StencilOffset> s) {
  for (int x : {-1, 1})
    for (int y : {-1, 1})
      for (int z : {-1, 1}) s.push_back({{x, y, z}});
  return s;
}
// Kuhn's split around the (0,0,0)-(1,1,1) diagonal: every edge of every tetrahedron steps forward along one,
// two or three axes, so the diagonals are the all-positive ones (and their opposites).
std::vector<StencilOffset> kuhn_offsets() {
  auto s = axis_offsets();
  for (int sign : {-1, 1}) {
    s.push_back({{sign, sign, 0}}), s.push_back({{sign, 0, sign}}), s.push_back({{0, sign, sign}});
    s.push_back({{sign, sign, sign}});
  }
  return s;
}

const int kuhn_perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};

void add(Body& b, std::int64_t p, std::int64_t q, ConnectionClass c) {
  b.connections.push_back({std::min(p, q), std::max(p, q), c});
}

// The 6 axis neighbours: cell edges.
void rectangular(Body& b) {
  for (long k = 0; k < b.n[2]; ++k)
    for (long j = 0; j < b.n[1]; ++j)
      for (long i = 0; i < b.n[0]; ++i) {
        if (i + 1 < b.n[0]) add(b, b.id(i, j, k), b.id(i + 1, j, k), ConnectionClass::edge);
        if (j + 1 < b.n[1]) add(b, b.id(i, j, k), b.id(i, j + 1, k), ConnectionClass::edge);
        if (k + 1 < b.n[2]) add(b, b.id(i, j, k), b.id(i, j, k + 1), ConnectionClass::edge);
      }
}

// Both diagonals of every cell face (the paper's Fig. 4).
void face_diagonals(Body& b) {
  rectangular(b);
  for (int axis = 0; axis < 3; ++axis) {  // faces normal to `axis`
    int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (long k = 0; k < b.n[2]; ++k)
      for (long j = 0; j < b.n[1]; ++j)
        for (long i = 0; i < b.n[0]; ++i) {
          long ijk[3] = {i, j, k};
          if (ijk[u] + 1 >= b.n[u] || ijk[v] + 1 >= b.n[v]) continue;
          long p[3] = {i, j, k}, q[3] = {i, j, k}, r[3] = {i, j, k}, s[3] = {i, j, k};
          q[u] += 1, q[v] += 1;  // (0,0)-(1,1)
          r[u] += 1;             // (1,0)-(0,1)
          s[v] += 1;
          add(b, b.id(p[0], p[1], p[2]), b.id(q[0], q[1], q[2]), ConnectionClass::face);
          add(b, b.id(r[0], r[1], r[2]), b.id(s[0], s[1], s[2]), ConnectionClass::face);
        }
  }
}

// Face diagonals plus the 4 diagonals of every cell (the paper's Fig. 5).
void body_diagonals(Body& b) {
  face_diagonals(b);
  for (long k = 0; k + 1 < b.n[2]; ++k)
    for (long j = 0; j + 1 < b.n[1]; ++j)
      for (long i = 0; i + 1 < b.n[0]; ++i) {
        add(b, b.id(i, j, k), b.id(i + 1, j + 1, k + 1), ConnectionClass::body);
        add(b, b.id(i + 1, j, k), b.id(i, j + 1, k + 1), ConnectionClass::body);
        add(b, b.id(i, j + 1, k), b.id(i + 1, j, k + 1), ConnectionClass::body);
        add(b, b.id(i, j, k + 1), b.id(i + 1, j + 1, k), ConnectionClass::body);
      }
}

// Every cell split into the 6 Kuhn tetrahedra around its (0,0,0)-(1,1,1) diagonal; the same split in every
// cell makes the mesh conforming. Connections are the tetrahedra's edges.
void tetrahedral(Body& b) {
  for (long k = 0; k + 1 < b.n[2]; ++k)
    for (long j = 0; j + 1 < b.n[1]; ++j)
      for (long i = 0; i + 1 < b.n[0]; ++i)
        for (const auto& p : kuhn_perms) {
          long c[3] = {i, j, k};
          Tetrahedron t;
          t[0] = b.id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            c[p[s]] += 1;
            t[s + 1] = b.id(c[0], c[1], c[2]);
          }
          b.tetrahedra.push_back(t);
          for (int x = 0; x < 4; ++x)
            for (int y = x + 1; y < 4; ++y) {
              auto ix = b.index(t[x]), iy = b.index(t[y]);
              int differ = (ix[0] != iy[0]) + (ix[1] != iy[1]) + (ix[2] != iy[2]);
              add(b, t[x], t[y], static_cast<ConnectionClass>(differ - 1));
            }
        }
  auto& c = b.connections;
  std::sort(c.begin(), c.end(), [](const Connection& x, const Connection& y) {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  });
  c.erase(std::unique(c.begin(), c.end(),
                      [](const Connection& x, const Connection& y) { return x.a == y.a && x.b == y.b; }),
          c.end());
}

}  // namespace

const std::vector<TopologyStyle>& topology_styles() {
  static const std::vector<TopologyStyle> styles = [] {
    std::vector<TopologyStyle> s = {
        {"rectangular", rectangular, "the 6 axis neighbours (cell edges)", axis_offsets()},
        {"face-diagonals", face_diagonals, "cell edges and both diagonals of every cell face",
         with_face_diagonals(axis_offsets())},
        {"body-diagonals", body_diagonals, "face-diagonals plus the 4 diagonals of every cell",
         with_body_diagonals(with_face_diagonals(axis_offsets()))},
        {"tetrahedral", tetrahedral, "every cell split into 6 tetrahedra; their edges", kuhn_offsets(), true},
    };
    // Stencils by (dk, dj, di): the order of the neighbours' ids in any box whose sides hold more molecules than
    // an offset spans, so lattice_neighbours() finds them already sorted (the set-up calls it 5 times a molecule).
    for (auto& style : s)
      std::sort(style.stencil.begin(), style.stencil.end(), [](const StencilOffset& x, const StencilOffset& y) {
        return std::lexicographical_compare(std::rbegin(x.d), std::rend(x.d), std::rbegin(y.d), std::rend(y.d));
      });
    return s;
  }();
  return styles;
}

void lattice_neighbours(const TopologyStyle& style, const BoxGeometry& box, std::int64_t g, std::vector<Neighbour>& out) {
  out.clear();
  const auto ijk = box.index(g);
  for (const auto& o : style.stencil) {
    long q[3];
    bool inside = true;
    for (int d = 0; d < 3; ++d) q[d] = ijk[d] + o.d[d], inside = inside && q[d] >= 0 && q[d] < box.n[d];
    if (!inside) continue;
    const int nonzero = (o.d[0] != 0) + (o.d[1] != 0) + (o.d[2] != 0);
    out.push_back({box.id(q[0], q[1], q[2]), static_cast<ConnectionClass>(nonzero - 1)});
  }
  auto by_id = [](const Neighbour& x, const Neighbour& y) { return x.id < y.id; };
  if (!std::is_sorted(out.begin(), out.end(), by_id)) std::sort(out.begin(), out.end(), by_id);
}

int kuhn_tetrahedra_on(const BoxGeometry& box, std::int64_t a, std::int64_t b) {
  const auto ia = box.index(a), ib = box.index(b);
  long lo[3], hi[3];  // the cells (by their (0,0,0) corner) that hold both molecules
  for (int d = 0; d < 3; ++d) {
    lo[d] = std::max({std::max(ia[d], ib[d]) - 1, 0L});
    hi[d] = std::min({std::min(ia[d], ib[d]), box.n[d] - 2});
  }
  int count = 0;
  for (long k = lo[2]; k <= hi[2]; ++k)
    for (long j = lo[1]; j <= hi[1]; ++j)
      for (long i = lo[0]; i <= hi[0]; ++i)
        for (const auto& p : kuhn_perms) {
          long c[3] = {i, j, k};
          bool has_a = box.id(c[0], c[1], c[2]) == a, has_b = box.id(c[0], c[1], c[2]) == b;
          for (int s = 0; s < 3; ++s) {
            c[p[s]] += 1;
            const std::int64_t v = box.id(c[0], c[1], c[2]);
            has_a = has_a || v == a, has_b = has_b || v == b;
          }
          count += has_a && has_b;
        }
  return count;
}

double kuhn_tetrahedron_volume(const BoxGeometry& box) { return box.h[0] * box.h[1] * box.h[2] / 6.0; }

const TopologyStyle* find_topology(const std::string& name) {
  for (const auto& s : topology_styles())
    if (name == s.name) return &s;
  return nullptr;
}

std::vector<std::string> topology_names() {
  std::vector<std::string> names;
  for (const auto& s : topology_styles()) names.emplace_back(s.name);
  return names;
}

}  // namespace tissue
