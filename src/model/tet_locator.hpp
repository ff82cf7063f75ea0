// Point location in a tetrahedral mesh: which tetrahedron holds a point (a uniform grid over the tetrahedra's
// bounding boxes, then barycentric coordinates). Carves a random cloud's Delaunay tetrahedra to a mesh volume.
#pragma once
#include <cstdint>

#include "src/model/uniform_grid.hpp"
#include "src/model/unstructured.hpp"

namespace tissue {

class TetLocator {
public:
  explicit TetLocator(const TetMesh& mesh);  // keeps a reference: the mesh must outlive the locator
  // The tetrahedron holding p, or -1 when none does. A point on a face shared by two takes the one it is deeper
  // in (the larger smallest barycentric coordinate; the lower index on a tie), so the answer is the same
  // wherever the query comes from. Coordinates down to -1e-10 count as inside (round-off on a face).
  std::int64_t locate(const Vec3& p) const;

private:
  const TetMesh& mesh_;
  UniformGrid grid_;
};

}  // namespace tissue
