#include "src/measure/measure.hpp"

#include <array>
#include <cmath>
#include <utility>

namespace tissue {

namespace {

// Confined compression: a box's four lateral faces (of the test's body) all held in their normal.
bool confined(const Scene& scene, const TensionTest& test) {
  if (!test.load_face.empty()) return false;
  int held = 0;
  for (const auto& f : scene.fixes) {
    int a, side;
    if (f.body == test.body && parse_face(f.face, a, side) && a != test.axis) ++held;
  }
  return held == 4;  // at most one fix per face (the reader checks)
}

// Simple shear on a box: a clamped face and, on the face opposite, a load along the face (other loads, such as
// the complementary tractions on the side faces, may be present). Collective when the scene is one.
std::optional<double> shear_modulus(const Scene& scene, const LocalModel& model, const double* x) {
  const Body& s = model.shape;
  for (const auto& load : scene.loads) {
    int axis, side;
    if (load.period > 0 || !parse_face(load.face, axis, side) || s.body(load.body).unstructured()) continue;
    const Vec3& F = load.force;
    const double norm = std::sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2]);
    if (!(norm > 0) || std::fabs(F[axis]) > 1e-12 * norm) continue;
    bool clamped = false;
    for (const auto& fix : scene.fixes) {
      int a, fs;
      if (fix.body == load.body && fix.mode == FixSpec::Mode::clamped && parse_face(fix.face, a, fs) && a == axis &&
          fs != side)
        clamped = true;
    }
    if (!clamped) continue;
    const BoxGeometry& box = s.body(load.body);
    std::array<double, 4> sum{}, total{};  // loaded face: sum along F, count; clamped face: the same
    for (int i = 0; i < model.owned; ++i) {
      if (model.body[i] != load.body) continue;
      double along = 0;
      for (int d = 0; d < 3; ++d) along += (x[3 * i + d] - model.rest[3 * i + d]) * F[d] / norm;
      if (box.on_face(model.id[i], axis, side)) sum[0] += along, sum[1] += 1;
      if (box.on_face(model.id[i], axis, 1 - side)) sum[2] += along, sum[3] += 1;
    }
    MPI_Allreduce(sum.data(), total.data(), 4, MPI_DOUBLE, MPI_SUM, model.comm);
    const double gamma = (total[0] / total[1] - total[2] / total[3]) / box.length(axis);
    const double area = box.length((axis + 1) % 3) * box.length((axis + 2) % 3);
    if (gamma == 0.0) return std::nullopt;
    return norm / area / gamma;
  }
  return std::nullopt;
}

}  // namespace

Measurements measure(const Scene& scene, const LocalModel& model, const TensionTest& test, const double* x,
                     const double* v) {
  const Body& s = model.shape;
  // Sums reduced in one call: [0..2] m x, [3] m, [4] kinetic, [5..8] loaded/fixed sums and counts,
  // [9..16] lateral faces (u-, u+, v-, v+: sum of displacement along the axis, count).
  std::array<double, 17> sum{};
  const int u = (test.axis + 1) % 3, w = (test.axis + 2) % 3;
  // Explicit topologies: the test's named faces (no Poisson ratio: their lateral faces have no lattice planes).
  const NamedFace* load_face = test.load_face.empty() ? nullptr : s.named_face(test.body, test.load_face);
  const NamedFace* fixed_face = test.fixed_face.empty() ? nullptr : s.named_face(test.body, test.fixed_face);
  for (int i = 0; i < model.owned; ++i) {
    const std::int64_t g = model.id[i];
    const double* xi = x + 3 * i;
    const double* x0 = model.rest.data() + 3 * i;
    for (int d = 0; d < 3; ++d) sum[d] += model.mass[i] * xi[d];
    sum[3] += model.mass[i];
    if (v)
      for (int d = 0; d < 3; ++d) sum[4] += 0.5 * model.mass[i] * v[3 * i + d] * v[3 * i + d];
    if (!test.valid || model.body[i] != test.body) continue;
    double along = 0;
    for (int d = 0; d < 3; ++d) along += (xi[d] - x0[d]) * test.direction[d];
    if (load_face || fixed_face) {
      if (load_face && load_face->contains(g)) sum[5] += along, sum[6] += 1;
      if (fixed_face && fixed_face->contains(g)) sum[7] += along, sum[8] += 1;
      continue;
    }
    if (s.on_face(g, test.axis, test.load_side)) sum[5] += along, sum[6] += 1;
    if (s.on_face(g, test.axis, test.fixed_side)) sum[7] += along, sum[8] += 1;
    const int lateral[2] = {u, w};
    for (int l = 0; l < 2; ++l)
      for (int side = 0; side < 2; ++side)
        if (s.on_face(g, lateral[l], side)) {
          sum[9 + 4 * l + 2 * side] += xi[lateral[l]] - x0[lateral[l]];
          sum[10 + 4 * l + 2 * side] += 1;
        }
  }
  std::array<double, 17> total{};
  MPI_Allreduce(sum.data(), total.data(), static_cast<int>(sum.size()), MPI_DOUBLE, MPI_SUM, model.comm);

  Measurements m;
  m.mass = total[3];
  for (int d = 0; d < 3; ++d) m.center_of_mass[d] = total[d] / total[3];
  m.kinetic_energy = total[4];
  if (test.valid) {
    const double dl = total[5] / total[6] - total[7] / total[8];
    m.elongation = dl;
    if (dl != 0.0) m.youngs_modulus = test.force * test.rest_length / (dl * test.cross_section);
    // The Poisson ratio needs the four lateral faces free of holds and loads.
    bool free = true;
    auto touches = [&](const std::string& face) {
      int a, side;
      return !parse_face(face, a, side) || a != test.axis;
    };
    for (const auto& f : scene.fixes) free = free && !touches(f.face);
    for (const auto& l : scene.loads) free = free && !touches(l.face);
    free = free && test.load_face.empty();
    const int lateral_axes[2] = {u, w};
    if (free && std::fabs(test.direction[test.axis]) > 0.5) {
      double mean = 0;
      for (int l = 0; l < 2; ++l)
        mean += 0.5 * (total[11 + 4 * l] / total[12 + 4 * l] - total[9 + 4 * l] / total[10 + 4 * l]) /
                s.length(lateral_axes[l]);
      m.lateral_strain = mean;
    }
    if (free && dl != 0.0 && std::fabs(test.direction[test.axis]) > 0.5) {  // not for a shear load
      // Axial strain from the change of length (negative in compression), not from the displacement along the
      // load: a compressive load moves the loaded face toward the fixed one.
      const double outward = test.direction[test.axis] * (test.load_side == 1 ? 1.0 : -1.0);
      const double axial = (outward > 0 ? 1.0 : -1.0) * dl / test.rest_length;
      double lateral = 0;
      const int axes[2] = {u, w};
      for (int l = 0; l < 2; ++l)
        lateral += 0.5 * (total[11 + 4 * l] / total[12 + 4 * l] - total[9 + 4 * l] / total[10 + 4 * l]) /
                   s.length(axes[l]);
      m.poisson_ratio = -lateral / axial;
      std::array<double, 2> each{};
      for (int l = 0; l < 2; ++l)
        each[l] = -(total[11 + 4 * l] / total[12 + 4 * l] - total[9 + 4 * l] / total[10 + 4 * l]) /
                  s.length(axes[l]) / axial;
      if (u > w) std::swap(each[0], each[1]);  // x, y, z order (../shared/interface.md)
      m.poisson_ratios = each;
    }
    if (confined(scene, test) && m.youngs_modulus) m.aggregate_modulus = m.youngs_modulus, m.youngs_modulus.reset();
  }
  m.shear_modulus = shear_modulus(scene, model, x);
  return m;
}

}  // namespace tissue

namespace tissue {

void measure_contact(const ForceModel& forces, Measurements& m) {
  const ForceModel::Contact c = forces.contact_totals();
  if (c.obstacles) m.contact_force = c.totals.obstacles;
  if (c.molecules)
    for (std::size_t b = 0; 3 * b < c.totals.bodies.size(); ++b)
      m.body_contact_force.push_back({c.totals.bodies[3 * b], c.totals.bodies[3 * b + 1], c.totals.bodies[3 * b + 2]});
}

}  // namespace tissue
