#include "src/model/uniform_grid.hpp"

#include <algorithm>
#include <cmath>

namespace tissue {

UniformGrid::UniformGrid(const Vec3& lo, const Vec3& hi, double cell) : lo_(lo) {
  for (int d = 0; d < 3; ++d) {
    size_[d] = std::max(hi[d] - lo[d], 0.0);
    // At most 2^20 cells per axis: a cell far smaller than the body only costs hash entries, but the index must fit.
    const double count = cell > 0 ? std::floor(size_[d] / cell) : 1.0;
    cells_[d] = static_cast<long>(std::clamp(count, 1.0, 1048576.0));
  }
}

long UniformGrid::cell_of(double x, int d) const {
  if (!(size_[d] > 0)) return 0;
  const double c = std::floor((x - lo_[d]) / size_[d] * static_cast<double>(cells_[d]));
  return static_cast<long>(std::clamp(c, 0.0, static_cast<double>(cells_[d] - 1)));
}

void UniformGrid::insert(std::int64_t id, const Vec3& lo, const Vec3& hi) {
  const long a0 = cell_of(lo[0], 0), a1 = cell_of(hi[0], 0), b0 = cell_of(lo[1], 1), b1 = cell_of(hi[1], 1),
             c0 = cell_of(lo[2], 2), c1 = cell_of(hi[2], 2);
  for (long c = c0; c <= c1; ++c)
    for (long b = b0; b <= b1; ++b)
      for (long a = a0; a <= a1; ++a) bins_[key(a, b, c)].push_back(id);
}

const std::vector<std::int64_t>& UniformGrid::candidates(const Vec3& p) const {
  auto it = bins_.find(key(cell_of(p[0], 0), cell_of(p[1], 1), cell_of(p[2], 2)));
  return it == bins_.end() ? none_ : it->second;
}

void insert_point(UniformGrid& grid, const std::vector<Vec3>& points, std::int64_t id, double dmin) {
  const Vec3& x = points[id];
  grid.insert(id, {x[0] - dmin, x[1] - dmin, x[2] - dmin}, {x[0] + dmin, x[1] + dmin, x[2] + dmin});
}

bool clear_of_points(const UniformGrid& grid, const std::vector<Vec3>& points, const Vec3& x, double dmin) {
  for (auto id : grid.candidates(x)) {
    double d2 = 0;
    for (int d = 0; d < 3; ++d) d2 += (points[id][d] - x[d]) * (points[id][d] - x[d]);
    if (d2 < dmin * dmin) return false;
  }
  return true;
}

}  // namespace tissue
