// Rigid obstacles ([[obstacle]]): planes (point, normal) and spheres (center, radius). A molecule is a sphere of
// radius r (its body's `radius`, default half the smallest spacing); where it overlaps an obstacle by a depth
// delta > 0, the obstacle pushes it out along the surface normal n with the penalty force k delta n.
//
// Penalty stiffness k: the obstacle's `stiffness` (N/m) when given, else the molecule's body's support
// stiffness, the mean over the body's molecules of the summed stiffness of their connections (2 sum k / N): a
// molecule then sinks into the obstacle about as far as its springs stretch under the same force. The force
// balance at equilibrium does not depend on k (only the penetration does).
//
// Tangent: -dF/dx = k n n^T for a plane (exact) and for a sphere its normal part (the curvature part
// -k delta/d (I - n n^T) is left out; it is small and would make the tangent indefinite).
#include <algorithm>
#include <cmath>

#include "src/physics/term.hpp"

namespace tissue {

namespace {
class Obstacles final : public Term {
public:
  Obstacles(const Scene& scene, const LocalModel& m) : m_(m) {
    const std::vector<double> support = body_support_stiffness(m);
    for (const auto& o : scene.obstacles) {
      Shape s;
      s.sphere = o.kind == ObstacleSpec::Kind::sphere;
      if (s.sphere) {
        s.c = o.center, s.R = o.radius;
      } else {
        const double len = std::sqrt(o.normal[0] * o.normal[0] + o.normal[1] * o.normal[1] + o.normal[2] * o.normal[2]);
        for (int d = 0; d < 3; ++d) s.c[d] = o.point[d], s.n[d] = o.normal[d] / len;
      }
      s.k.resize(support.size());
      for (std::size_t b = 0; b < support.size(); ++b) s.k[b] = o.stiffness > 0 ? o.stiffness : support[b];
      shapes_.push_back(s);
    }
    radius_.resize(m.shape.bodies());
    for (int b = 0; b < m.shape.bodies(); ++b) radius_[b] = m.shape.body(b).radius;
  }

  void add_forces(const double* x, const double*, double, double* f) override {
    total_ = Vec3{0, 0, 0};
    for (int i = 0; i < m_.owned; ++i)
      for (const auto& s : shapes_) {
        double n[3], depth;
        if (!overlap(s, x + 3 * i, radius_[m_.body[i]], n, depth)) continue;
        const double k = s.k[m_.body[i]];
        for (int d = 0; d < 3; ++d) {
          f[3 * i + d] += k * depth * n[d];
          total_[d] += k * depth * n[d];
        }
      }
  }
  double potential_energy(const double* x) const override {
    double e = 0;
    for (int i = 0; i < m_.owned; ++i)
      for (const auto& s : shapes_) {
        double n[3], depth;
        if (overlap(s, x + 3 * i, radius_[m_.body[i]], n, depth)) e += 0.5 * s.k[m_.body[i]] * depth * depth;
      }
    return e;
  }
  void add_stiffness_bound(std::vector<double>& ksum) const override {
    for (int i = 0; i < m_.owned; ++i)
      for (const auto& s : shapes_) ksum[i] += 0.5 * s.k[m_.body[i]];  // row sum k, counted as 2 ksum
  }
  PetscErrorCode add_tangent(const double* x, BlockAdd add, void* ctx) const override {
    for (int i = 0; i < m_.owned; ++i)
      for (const auto& s : shapes_) {
        double n[3], depth;
        if (!overlap(s, x + 3 * i, radius_[m_.body[i]], n, depth)) continue;
        const double k = s.k[m_.body[i]];
        double K[9];
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) K[3 * r + c] = k * n[r] * n[c];
        PetscErrorCode ierr = add(ctx, i, i, K);
        if (ierr) return ierr;
      }
    return 0;
  }
  void add_totals(ContactTotals& t) const override {
    for (int d = 0; d < 3; ++d) t.obstacles[d] += total_[d];
  }

private:
  struct Shape {
    bool sphere = false;
    Vec3 c{}, n{};  // plane: point and unit normal; sphere: centre
    double R = 0;
    std::vector<double> k;  // penalty stiffness per body
  };
  // Overlap of a molecule (centre p, radius r) with an obstacle: the outward normal and the depth (> 0).
  static bool overlap(const Shape& s, const double* p, double r, double n[3], double& depth) {
    if (!s.sphere) {
      const double h = (p[0] - s.c[0]) * s.n[0] + (p[1] - s.c[1]) * s.n[1] + (p[2] - s.c[2]) * s.n[2];
      depth = r - h;
      if (!(depth > 0)) return false;
      n[0] = s.n[0], n[1] = s.n[1], n[2] = s.n[2];
      return true;
    }
    const double e[3] = {p[0] - s.c[0], p[1] - s.c[1], p[2] - s.c[2]};
    const double d2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2], reach = s.R + r;
    if (!(d2 < reach * reach) || d2 == 0.0) return false;
    const double d = std::sqrt(d2);
    depth = reach - d;
    for (int a = 0; a < 3; ++a) n[a] = e[a] / d;
    return true;
  }

  const LocalModel& m_;
  std::vector<Shape> shapes_;
  std::vector<double> radius_;  // per body
  Vec3 total_{0, 0, 0};
};
}  // namespace

std::unique_ptr<Term> make_obstacles(const TermContext& c) { return std::make_unique<Obstacles>(c.scene, c.model); }

TISSUE_TERM(obstacles, {"obstacles", [](const Scene& s) { return !s.obstacles.empty(); }, make_obstacles,
                        "[[obstacle]]: rigid planes and spheres pushing molecules (spheres) out by a penalty force", 40,
                        false, ContactReport::obstacles});

}  // namespace tissue
