// Topology "face-diagonals": cell edges plus both diagonals of every cell face (the paper's Fig. 4).
#include "src/model/topology.hpp"

namespace tissue {

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

// Both diagonals of every cell face (the paper's Fig. 4).
void build_face_diagonals(Body& b) {
  build_rectangular(b);
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
          add_connection(b, b.id(p[0], p[1], p[2]), b.id(q[0], q[1], q[2]), ConnectionClass::face);
          add_connection(b, b.id(r[0], r[1], r[2]), b.id(s[0], s[1], s[2]), ConnectionClass::face);
        }
  }
}

TISSUE_TOPOLOGY(face_diagonals, {"face-diagonals", build_face_diagonals, "cell edges and both diagonals of every cell face",
                                  with_face_diagonals(axis_offsets()), false, CellFamilies::face_diagonals});

}  // namespace tissue
