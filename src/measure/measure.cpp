#include "src/measure/measure.hpp"

#include <array>
#include <cmath>
#include <utility>

namespace tissue {

namespace {

// Confined compression: four faces of the test's body normal to the other two axes, all held (the reader allows
// one fix per face).
bool confined(const Scene& scene, const Body& s, const TensionTest& test) {
  int held = 0;
  for (const auto& f : scene.fixes) {
    const NamedFace* face = f.body == test.body ? s.named_face(f.body, f.face) : nullptr;
    if (face && face->side >= 0 && face->axis != test.axis) ++held;
  }
  return held == 4;
}

// Simple shear: a clamped face and, on the face opposite, a load along the face (other loads, such as the
// complementary tractions on the side faces, may be present). Collective when the scene is one. x in either layout.
std::optional<double> shear_modulus(const Scene& scene, const LocalModel& model, Components x) {
  const Body& s = model.shape;
  for (const auto& load : scene.loads) {
    const NamedFace* lf = s.named_face(load.body, load.face);
    if (load.period > 0 || !lf || lf->side < 0) continue;
    const int axis = lf->axis;
    const Vec3& F = load.force;
    const double norm = std::sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2]);
    if (!(norm > 0) || std::fabs(F[axis]) > 1e-12 * norm) continue;
    const NamedFace* ff = nullptr;
    for (const auto& fix : scene.fixes) {
      const NamedFace* f = fix.body == load.body ? s.named_face(fix.body, fix.face) : nullptr;
      if (f && fix.mode == FixSpec::Mode::clamped && f->side >= 0 && f->axis == axis && f->side != lf->side) ff = f;
    }
    if (!ff) continue;
    std::array<double, 4> sum{}, total{};  // loaded face: sum along F, count; clamped face: the same
    for (int i = 0; i < model.owned; ++i) {
      if (model.body[i] != load.body) continue;
      double along = 0;
      for (int d = 0; d < 3; ++d) along += (x(i, d) - model.rest[3 * i + d]) * F[d] / norm;
      if (lf->contains(model.id[i])) sum[0] += along, sum[1] += 1;
      if (ff->contains(model.id[i])) sum[2] += along, sum[3] += 1;
    }
    MPI_Allreduce(sum.data(), total.data(), 4, MPI_DOUBLE, MPI_SUM, model.comm);
    const double gamma = (total[0] / total[1] - total[2] / total[3]) / std::fabs(lf->plane - ff->plane);
    if (gamma == 0.0) return std::nullopt;
    return norm / lf->total_area / gamma;
  }
  return std::nullopt;
}

}  // namespace

Measurements measure(const Scene& scene, const LocalModel& model, const TensionTest& test, const double* xs,
                     const double* vs, std::size_t x_streams, std::size_t v_streams, double time) {
  const Components x{xs, x_streams}, v{vs, v_streams};
  const Body& s = model.shape;
  // Sums reduced in one call: [0..2] m x, [3] m, [4] kinetic, [5..8] loaded/fixed sums and counts,
  // [9..16] lateral faces (u-, u+, v-, v+: sum of displacement along the axis, count).
  std::array<double, 17> sum{};
  const int u = (test.axis + 1) % 3, w = (test.axis + 2) % 3;
  const NamedFace* load_face = test.valid ? &s.faces[test.load_face] : nullptr;
  const NamedFace* fixed_face = test.valid ? &s.faces[test.fixed_face] : nullptr;
  // The Poisson ratio reads the four lateral faces (u-, u+, w-, w+) when they are planes named x- .. z+ free of
  // holds and loads: a lattice's, a random box's or a mesh's (their molecules lie on the plane; a mesh may have
  // none).
  std::array<const NamedFace*, 4> lateral{};
  bool free = test.valid && std::fabs(test.direction[test.axis]) > 0.5;  // not for a shear load
  const int axes[2] = {u, w};
  for (const auto& f : s.faces)
    if (test.valid && f.body == test.body && (f.lattice || f.side >= 0) && f.axis >= 0 && f.axis != test.axis)
      lateral[2 * (f.axis == w) + f.side] = &f;
  for (const NamedFace* f : lateral) free = free && f;
  auto touches = [&](int body, const std::string& name) {  // a hold or load on a face not normal to the axis
    const NamedFace* f = s.named_face(body, name);
    return !f || f->side < 0 || f->axis != test.axis;
  };
  for (const auto& f : scene.fixes) free = free && !touches(f.body, f.face);
  for (const auto& l : scene.loads) free = free && !touches(l.body, l.face);
  // Bits per owned molecule: 1 on the loaded face, 2 on the fixed face, 4 << (2 l + side) on lateral face (l, side).
  if (test.valid && test.face_bits.size() != static_cast<std::size_t>(model.owned)) {
    test.face_bits.assign(model.owned, 0);
    for (int i = 0; i < model.owned; ++i) {
      if (model.body[i] != test.body) continue;
      const std::int64_t g = model.id[i];
      std::uint8_t b = (load_face->contains(g) ? 1 : 0) | (fixed_face->contains(g) ? 2 : 0);
      for (int q = 0; q < 4; ++q)
        if (lateral[q] && lateral[q]->contains(g)) b |= 4 << q;
      test.face_bits[i] = b;
    }
  }
  for (int i = 0; i < model.owned; ++i) {
    const double xi[3] = {x(i, 0), x(i, 1), x(i, 2)};
    const double* x0 = model.rest.data() + 3 * i;
    for (int d = 0; d < 3; ++d) sum[d] += model.mass[i] * xi[d];
    sum[3] += model.mass[i];
    if (vs)
      for (int d = 0; d < 3; ++d) sum[4] += 0.5 * model.mass[i] * v(i, d) * v(i, d);
    if (!test.valid || model.body[i] != test.body) continue;
    double along = 0;
    for (int d = 0; d < 3; ++d) along += (xi[d] - x0[d]) * test.direction[d];
    const std::uint8_t bits = test.face_bits[i];
    if (bits & 1) sum[5] += along, sum[6] += 1;
    if (bits & 2) sum[7] += along, sum[8] += 1;
    if (!free) continue;
    for (int l = 0; l < 2; ++l)
      for (int side = 0; side < 2; ++side)
        if (bits & (4 << (2 * l + side))) {
          sum[9 + 4 * l + 2 * side] += xi[axes[l]] - x0[axes[l]];
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
    const double force = test.force_at(time);
    m.applied_force = force;
    if (dl != 0.0 && force != 0.0) m.youngs_modulus = force * test.rest_length / (dl * test.cross_section);
    auto lateral_length = [&](int l) { return std::fabs(lateral[2 * l + 1]->plane - lateral[2 * l]->plane); };
    if (free) {  // history.csv's lateral_strain: the mean strain of the two lateral axes
      double mean = 0;
      for (int l = 0; l < 2; ++l)
        mean += 0.5 * (total[11 + 4 * l] / total[12 + 4 * l] - total[9 + 4 * l] / total[10 + 4 * l]) / lateral_length(l);
      m.lateral_strain = mean;
    }
    if (free && dl != 0.0) {
      // Axial strain from the change of length (negative in compression), not from the displacement along the
      // load: a compressive load moves the loaded face toward the fixed one.
      const double outward = test.direction[test.axis] * (test.load_side == 1 ? 1.0 : -1.0);
      const double axial = (outward > 0 ? 1.0 : -1.0) * dl / test.rest_length;
      double contraction = 0;
      for (int l = 0; l < 2; ++l)
        contraction += 0.5 * (total[11 + 4 * l] / total[12 + 4 * l] - total[9 + 4 * l] / total[10 + 4 * l]) /
                       lateral_length(l);
      m.poisson_ratio = -contraction / axial;
      std::array<double, 2> each{};
      for (int l = 0; l < 2; ++l)
        each[l] = -(total[11 + 4 * l] / total[12 + 4 * l] - total[9 + 4 * l] / total[10 + 4 * l]) /
                  lateral_length(l) / axial;
      if (u > w) std::swap(each[0], each[1]);  // x, y, z order (../shared/interface.md)
      m.poisson_ratios = each;
    }
    if (confined(scene, s, test) && m.youngs_modulus) m.aggregate_modulus = m.youngs_modulus, m.youngs_modulus.reset();
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
