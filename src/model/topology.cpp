#include "src/model/topology.hpp"

#include <algorithm>

namespace tissue {
namespace {

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
  static const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (long k = 0; k + 1 < b.n[2]; ++k)
    for (long j = 0; j + 1 < b.n[1]; ++j)
      for (long i = 0; i + 1 < b.n[0]; ++i)
        for (const auto& p : perms) {
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
  static const std::vector<TopologyStyle> styles = {
      {"rectangular", rectangular, "the 6 axis neighbours (cell edges)"},
      {"face-diagonals", face_diagonals, "cell edges and both diagonals of every cell face"},
      {"body-diagonals", body_diagonals, "face-diagonals plus the 4 diagonals of every cell"},
      {"tetrahedral", tetrahedral, "every cell split into 6 tetrahedra; their edges"},
  };
  return styles;
}

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
