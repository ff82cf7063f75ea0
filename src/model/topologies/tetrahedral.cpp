// Topology "tetrahedral": every cell split into the 6 Kuhn tetrahedra; connections are their edges (Eq. 5
// needs the tetrahedra).
#include <algorithm>

#include "src/model/topology.hpp"

namespace tissue {
namespace {

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

// Every cell split into the 6 Kuhn tetrahedra around its (0,0,0)-(1,1,1) diagonal; the same split in every
// cell makes the mesh conforming. Connections are the tetrahedra's edges.
void build_tetrahedral(Body& b) {
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
              add_connection(b, t[x], t[y], static_cast<ConnectionClass>(differ - 1));
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

TISSUE_TOPOLOGY(tetrahedral, {"tetrahedral", build_tetrahedral, "every cell split into 6 tetrahedra; their edges",
                               kuhn_offsets(), true});

}  // namespace tissue
