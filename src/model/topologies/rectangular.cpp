// Topology "rectangular": the 6 axis neighbours, the cell edges.
#include "src/model/topology.hpp"

namespace tissue {

std::vector<StencilOffset> axis_offsets() {
  return {{{1, 0, 0}}, {{-1, 0, 0}}, {{0, 1, 0}}, {{0, -1, 0}}, {{0, 0, 1}}, {{0, 0, -1}}};
}

// The 6 axis neighbours: cell edges.
void build_rectangular(Body& b) {
  for (long k = 0; k < b.n[2]; ++k)
    for (long j = 0; j < b.n[1]; ++j)
      for (long i = 0; i < b.n[0]; ++i) {
        if (i + 1 < b.n[0]) add_connection(b, b.id(i, j, k), b.id(i + 1, j, k), ConnectionClass::edge);
        if (j + 1 < b.n[1]) add_connection(b, b.id(i, j, k), b.id(i, j + 1, k), ConnectionClass::edge);
        if (k + 1 < b.n[2]) add_connection(b, b.id(i, j, k), b.id(i, j, k + 1), ConnectionClass::edge);
      }
}

TISSUE_TOPOLOGY(rectangular, {"rectangular", build_rectangular, "the 6 axis neighbours (cell edges)", axis_offsets(),
                                false, CellFamilies::edges});

}  // namespace tissue
