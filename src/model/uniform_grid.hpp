// A uniform grid of cells over a bounding box that bins items (points, triangles, tetrahedra) by the box each
// covers: the candidates for a query point are the items binned in its cell. Used to keep random molecules apart
// (dart throwing) and to locate points in a mesh's tetrahedra. Cells are stored sparsely (a hash of the cell
// index), so a fine grid over a thin body costs only the cells its items touch.
#pragma once
#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "src/model/scene.hpp"

namespace tissue {

class UniformGrid {
public:
  // Cells of edge `cell` (at least one per axis) over [lo, hi]; points outside fall in the nearest cell.
  UniformGrid(const Vec3& lo, const Vec3& hi, double cell);
  // Bins `id` in every cell that the box [lo, hi] overlaps.
  void insert(std::int64_t id, const Vec3& lo, const Vec3& hi);
  // The items whose box may hold p (every item whose box does is among them), in insertion order.
  const std::vector<std::int64_t>& candidates(const Vec3& p) const;

private:
  long cell_of(double x, int d) const;
  std::int64_t key(long a, long b, long c) const { return a + cells_[0] * (b + static_cast<std::int64_t>(cells_[1]) * c); }
  Vec3 lo_{}, size_{};
  std::array<long, 3> cells_{};
  std::unordered_map<std::int64_t, std::vector<std::int64_t>> bins_;
  std::vector<std::int64_t> none_;
};

// Dart throwing: points[id] binned with the reach dmin, and whether x is at least dmin from every binned point.
void insert_point(UniformGrid& grid, const std::vector<Vec3>& points, std::int64_t id, double dmin);
bool clear_of_points(const UniformGrid& grid, const std::vector<Vec3>& points, const Vec3& x, double dmin);

}  // namespace tissue
