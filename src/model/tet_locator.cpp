#include "src/model/tet_locator.hpp"

#include <algorithm>
#include <cmath>

namespace tissue {
namespace {

struct Box {
  Vec3 lo, hi;
};

Box bounds(const std::vector<Vec3>& x) {
  Box b{x.empty() ? Vec3{} : x[0], x.empty() ? Vec3{} : x[0]};
  for (const auto& p : x)
    for (int d = 0; d < 3; ++d) b.lo[d] = std::min(b.lo[d], p[d]), b.hi[d] = std::max(b.hi[d], p[d]);
  return b;
}

// About one tetrahedron's size per cell: the mean volume per tetrahedron of the bounding box.
double cell_size(const TetMesh& m) {
  const Box b = bounds(m.nodes);
  double v = 1;
  for (int d = 0; d < 3; ++d) v *= std::max(b.hi[d] - b.lo[d], 1e-300);
  return std::cbrt(v / std::max<std::size_t>(m.tets.size(), 1));
}

}  // namespace

TetLocator::TetLocator(const TetMesh& mesh)
    : mesh_(mesh), grid_(bounds(mesh.nodes).lo, bounds(mesh.nodes).hi, cell_size(mesh)) {
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    std::vector<Vec3> corners;
    for (auto v : mesh.tets[t]) corners.push_back(mesh.nodes[v]);
    const Box b = bounds(corners);
    grid_.insert(static_cast<std::int64_t>(t), b.lo, b.hi);
  }
}

std::int64_t TetLocator::locate(const Vec3& p) const {
  std::int64_t best = -1;
  double deepest = -1e-10;
  for (auto t : grid_.candidates(p)) {
    const auto& T = mesh_.tets[t];
    const Vec3 &a = mesh_.nodes[T[0]], &b = mesh_.nodes[T[1]], &c = mesh_.nodes[T[2]], &d = mesh_.nodes[T[3]];
    const double vol = signed_volume(a, b, c, d);
    // Barycentric coordinates: each the volume with p in place of one corner over the whole.
    const double lambda = std::min({signed_volume(p, b, c, d), signed_volume(a, p, c, d), signed_volume(a, b, p, d),
                                    signed_volume(a, b, c, p)}) / vol;
    if (lambda > deepest) deepest = lambda, best = t;  // candidates come in index order: ties keep the lower
  }
  return best;
}

}  // namespace tissue
