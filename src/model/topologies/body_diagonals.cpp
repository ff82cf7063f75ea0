// Topology "body-diagonals": face-diagonals plus the 4 diagonals of every cell (the paper's Fig. 5).
#include "src/model/topology.hpp"

namespace tissue {

std::vector<StencilOffset> with_body_diagonals(std::vector<StencilOffset> s) {
  for (int x : {-1, 1})
    for (int y : {-1, 1})
      for (int z : {-1, 1}) s.push_back({{x, y, z}});
  return s;
}

// Face diagonals plus the 4 diagonals of every cell (the paper's Fig. 5).
void build_body_diagonals(Body& b) {
  build_face_diagonals(b);
  for (long k = 0; k + 1 < b.n[2]; ++k)
    for (long j = 0; j + 1 < b.n[1]; ++j)
      for (long i = 0; i + 1 < b.n[0]; ++i) {
        add_connection(b, b.id(i, j, k), b.id(i + 1, j + 1, k + 1), ConnectionClass::body);
        add_connection(b, b.id(i + 1, j, k), b.id(i, j + 1, k + 1), ConnectionClass::body);
        add_connection(b, b.id(i, j + 1, k), b.id(i + 1, j, k + 1), ConnectionClass::body);
        add_connection(b, b.id(i, j, k + 1), b.id(i + 1, j + 1, k), ConnectionClass::body);
      }
}

TISSUE_TOPOLOGY(body_diagonals, {"body-diagonals", build_body_diagonals, "face-diagonals plus the 4 diagonals of every cell",
                                  with_body_diagonals(with_face_diagonals(axis_offsets())), false,
                                  CellFamilies::body_diagonals});

}  // namespace tissue
