// The cell term: one energy per lattice cell (its 8 corner molecules) of the cell-centre deformation gradient,
// which carries what central springs cannot (src/model/cell_law.hpp, docs/poisson.md): a Poisson ratio other
// than 1/4, and the shear of cells too far from cubic. Built only for bodies calibrated by homogenized that need
// it (body_has_cells); everything else pays nothing.
//
// F = sum_a x_a (x) g_a with g_a = (s_x / 4h_x, s_y / 4h_y, s_z / 4h_z), s in {-1, 1}^3 the corner's signs (the
// trilinear cell's gradient at its centre; F = I at rest). Per unit reference volume V0 = h_x h_y h_z:
//   W = mu_c/2 (J^(-2/3) tr C - 3) + kappa_c/4 (J^2 - 1 - 2 ln J) + sum_w alpha_w sum_(n = (e_a +- e_b)/sqrt 2) (|F n|^2 - 1)^2 / 4
// (isochoric neo-Hookean, a volumetric part that is convex and infinite as J -> 0, and the virtual 45-degree
// diagonals of each face plane w = (a, b)): objective (a function of C = F^T F), >= 0, zero at rest. Its
// small-strain tensor adds lambda_c + 2 mu_c to C11, lambda_c to C12, mu_c to C44 (lambda_c = kappa_c - 2 mu_c/3)
// and alpha_w to C_aaaa, C_bbbb, C_aabb and C_abab. Forces f_a = -V0 P g_a with P = dW/dF; the tangent is P's
// exact derivative, taken by forward-mode dual numbers through the same code (no second hand-written formula
// to drift from the force).
//
// Ranks: each rank evaluates every cell that has an owned corner (the lattice's ghost layer holds all 8 corners,
// partition/lattice_model.cpp) in increasing cell id and adds to its owned corners only, so each molecule sums its
// cells in the same order on any partition: results are bit for bit those of one rank. A cell's energy is
// counted by the rank owning its lowest corner.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include "src/model/cell_law.hpp"
#include "src/physics/term.hpp"

namespace tissue {

namespace {

// A value with one directional derivative: enough for the tangent, one direction of F at a time.
struct Dual {
  double v = 0, d = 0;
  Dual() = default;
  Dual(double value, double derivative = 0) : v(value), d(derivative) {}
};
inline Dual operator+(Dual a, Dual b) { return {a.v + b.v, a.d + b.d}; }
inline Dual operator-(Dual a, Dual b) { return {a.v - b.v, a.d - b.d}; }
inline Dual operator*(Dual a, Dual b) { return {a.v * b.v, a.d * b.v + a.v * b.d}; }
inline Dual operator/(Dual a, Dual b) { return {a.v / b.v, (a.d * b.v - a.v * b.d) / (b.v * b.v)}; }
inline double value(double x) { return x; }
inline double value(Dual x) { return x.v; }
inline double power(double x, double p) { return std::pow(x, p); }
inline Dual power(Dual x, double p) {
  const double y = std::pow(x.v, p);
  return {y, p * y / x.v * x.d};
}
inline double logarithm(double x) { return std::log(x); }
inline Dual logarithm(Dual x) { return {std::log(x.v), x.d / x.v}; }

struct Moduli {
  double mu = 0, kappa = 0, alpha[3] = {0, 0, 0};
};

// First Piola-Kirchhoff stress P = dW/dF (row-major 3 x 3) of the energy density above; returns false when
// J <= 0 (the energy is infinite there).
template <class T>
bool stress(const T F[9], const Moduli& m, T P[9]) {
  const T J = F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
              F[2] * (F[3] * F[7] - F[4] * F[6]);
  if (!(value(J) > 0)) return false;
  // cof = J F^-T
  const T cof[9] = {F[4] * F[8] - F[5] * F[7], F[5] * F[6] - F[3] * F[8], F[3] * F[7] - F[4] * F[6],
                    F[2] * F[7] - F[1] * F[8], F[0] * F[8] - F[2] * F[6], F[1] * F[6] - F[0] * F[7],
                    F[1] * F[5] - F[2] * F[4], F[2] * F[3] - F[0] * F[5], F[0] * F[4] - F[1] * F[3]};
  for (int q = 0; q < 9; ++q) P[q] = T(0.0);
  if (m.mu != 0) {
    T I1 = T(0.0);
    for (int q = 0; q < 9; ++q) I1 = I1 + F[q] * F[q];
    const T scale = T(m.mu) * power(J, -2.0 / 3.0);
    const T third = I1 / (T(3.0) * J);
    for (int q = 0; q < 9; ++q) P[q] = P[q] + scale * (F[q] - third * cof[q]);
  }
  if (m.kappa != 0) {
    const T vol = T(0.5 * m.kappa) * (J * J - T(1.0)) / J;
    for (int q = 0; q < 9; ++q) P[q] = P[q] + vol * cof[q];
  }
  for (int w = 0; w < 3; ++w) {
    if (m.alpha[w] == 0) continue;
    const int a = (w + 1) % 3, b = (w + 2) % 3;
    for (const double sign : {1.0, -1.0}) {
      // n = (e_a + sign e_b) / sqrt 2: F n = (F_{.a} + sign F_{.b}) / sqrt 2
      T Fn[3];
      for (int i = 0; i < 3; ++i) Fn[i] = (F[3 * i + a] + T(sign) * F[3 * i + b]) * T(M_SQRT1_2);
      const T stretch = Fn[0] * Fn[0] + Fn[1] * Fn[1] + Fn[2] * Fn[2] - T(1.0);
      const T c = T(m.alpha[w]) * stretch * T(M_SQRT1_2);
      for (int i = 0; i < 3; ++i) {
        P[3 * i + a] = P[3 * i + a] + c * Fn[i];
        P[3 * i + b] = P[3 * i + b] + c * T(sign) * Fn[i];
      }
    }
  }
  return true;
}

double energy_density(const double F[9], const Moduli& m) {
  const double J = F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
                   F[2] * (F[3] * F[7] - F[4] * F[6]);
  if (!(J > 0)) return std::numeric_limits<double>::infinity();
  double I1 = 0;
  for (int q = 0; q < 9; ++q) I1 += F[q] * F[q];
  double W = 0.5 * m.mu * (std::pow(J, -2.0 / 3.0) * I1 - 3.0) + 0.25 * m.kappa * (J * J - 1.0 - 2.0 * std::log(J));
  for (int w = 0; w < 3; ++w) {
    const int a = (w + 1) % 3, b = (w + 2) % 3;
    for (const double sign : {1.0, -1.0}) {
      double s = -1.0;
      for (int i = 0; i < 3; ++i) {
        const double Fn = (F[3 * i + a] + sign * F[3 * i + b]) * M_SQRT1_2;
        s += Fn * Fn;
      }
      W += 0.25 * m.alpha[w] * s * s;
    }
  }
  return W;
}

class CellElasticity final : public Term {
public:
  CellElasticity(const Scene& scene, const LocalModel& model) : m_(model) {
    const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
    std::unordered_map<std::int64_t, int> local;
    local.reserve(model.local);
    for (int i = 0; i < model.local; ++i) local.emplace(model.id[i], i);
    std::vector<std::int64_t> bases;
    for (int i = 0; i < model.owned; ++i) {
      const int b = model.body[i];
      if (!body_has_cells(specs[b], b < static_cast<int>(scene.calibrations.size()) ? scene.calibrations[b]
                                                                                    : scene.calibration))
        continue;
      const BoxGeometry& box = model.shape.body(b);
      const auto ijk = box.index(model.id[i]);
      for (int c = 0; c < 8; ++c) {
        const long q[3] = {ijk[0] - (c & 1), ijk[1] - ((c >> 1) & 1), ijk[2] - ((c >> 2) & 1)};
        bool inside = true;
        for (int d = 0; d < 3; ++d) inside = inside && q[d] >= 0 && q[d] <= box.n[d] - 2;
        if (inside) bases.push_back(box.id(q[0], q[1], q[2]));
      }
    }
    std::sort(bases.begin(), bases.end());
    bases.erase(std::unique(bases.begin(), bases.end()), bases.end());
    cells_ = static_cast<int>(bases.size());
    corner_.resize(8 * bases.size());
    moduli_.resize(bases.size());
    body_.resize(bases.size());
    for (int k = 0; k < cells_; ++k) {
      const std::int64_t base = bases[k];
      auto it = local.find(base);
      if (it == local.end()) throw std::runtime_error("cell term: a cell corner is not on this rank");
      const int b = model.body[it->second];
      const BoxGeometry& box = model.shape.body(b);
      const auto ijk = box.index(base);
      double E_s = 0, mu = 0, kappa = 0, modulus = 0, density = 0;
      for (int c = 0; c < 8; ++c) {
        const std::int64_t g = box.id(ijk[0] + (c & 1), ijk[1] + ((c >> 1) & 1), ijk[2] + ((c >> 2) & 1));
        auto at = local.find(g);
        if (at == local.end())
          throw std::runtime_error("cell term: the ghost layer lacks a cell corner (the cell term needs a box lattice "
                                   "built by partition/lattice_model.cpp)");
        corner_[8 * k + c] = at->second;
        const MoleculeMaterial mat = molecule_material(specs[b], box, g);
        const CellModuli cm = cell_moduli(mat.youngs_modulus, mat.poisson_ratio);
        E_s += cm.spring_modulus / 8, mu += cm.mu_c / 8, kappa += cm.kappa_c / 8;
        modulus += p_wave_modulus(mat.youngs_modulus, mat.poisson_ratio) / 8, density += mat.density / 8;
      }
      const CellSprings split = cell_springs(box.h, find_topology(box.topology)->cells);
      Moduli& md = moduli_[k];
      md.mu = mu, md.kappa = kappa;
      for (int w = 0; w < 3; ++w) md.alpha[w] = split.alpha[w] * E_s;
      body_[k] = b;
      owns_energy_.push_back(corner_[8 * k] < model.owned);
      const double h = std::min({box.h[0], box.h[1], box.h[2]});
      // 0.8 h / c_p: measured limits of dynamic runs are 0.85-1.1 h / c_p (docs/poisson.md), so this is a lower
      // bound within 1.4x of them.
      dt_ = std::min(dt_, 0.8 * h / std::sqrt(modulus / density));
    }
    // The gradient weights g_a and V0 per body.
    for (int b = 0; b < model.shape.bodies(); ++b) {
      const BoxGeometry& box = model.shape.body(b);
      Geometry geo;
      geo.volume = box.h[0] * box.h[1] * box.h[2];
      for (int c = 0; c < 8; ++c)
        for (int d = 0; d < 3; ++d) geo.g[c][d] = (((c >> d) & 1) ? 1.0 : -1.0) / (4.0 * box.h[d]);
      geometry_.push_back(geo);
    }
  }

  void add_forces(const double* x, const double*, double, double* f) override {
    for (int k = 0; k < cells_; ++k) {
      const int* corner = &corner_[8 * k];
      const Geometry& geo = geometry_[body_[k]];
      double F[9], P[9];
      gradient(x, corner, geo, F);
      if (!stress(F, moduli_[k], P)) {
        // An inverted cell: its energy is infinite; NaN forces make every solver's guard stop or cut back.
        for (int c = 0; c < 8; ++c)
          if (corner[c] < m_.owned)
            for (int i = 0; i < 3; ++i) f[3 * corner[c] + i] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      for (int c = 0; c < 8; ++c) {
        if (corner[c] >= m_.owned) continue;
        const double* g = geo.g[c];
        for (int i = 0; i < 3; ++i)
          f[3 * corner[c] + i] -= geo.volume * (P[3 * i] * g[0] + P[3 * i + 1] * g[1] + P[3 * i + 2] * g[2]);
      }
    }
  }

  double potential_energy(const double* x) const override {
    double e = 0;
    for (int k = 0; k < cells_; ++k) {
      if (!owns_energy_[k]) continue;
      const Geometry& geo = geometry_[body_[k]];
      double F[9];
      gradient(x, &corner_[8 * k], geo, F);
      e += geo.volume * energy_density(F, moduli_[k]);
    }
    return e;
  }

  PetscErrorCode add_tangent(const double* x, BlockAdd add, void* ctx) const override {
    for (int k = 0; k < cells_; ++k) {
      const int* corner = &corner_[8 * k];
      const Geometry& geo = geometry_[body_[k]];
      double F[9];
      gradient(x, corner, geo, F);
      // dP/dF_kl, one direction at a time: D[kl][ij].
      double D[9][9];
      for (int kl = 0; kl < 9; ++kl) {
        Dual Fd[9], Pd[9];
        for (int q = 0; q < 9; ++q) Fd[q] = Dual(F[q], q == kl ? 1.0 : 0.0);
        if (!stress(Fd, moduli_[k], Pd)) return 0;  // inverted: the residual is NaN already
        for (int q = 0; q < 9; ++q) D[kl][q] = Pd[q].d;
      }
      // Dg[kl][a][i] = sum_j D[kl][ij] g_a[j]
      double Dg[9][8][3];
      for (int kl = 0; kl < 9; ++kl)
        for (int a = 0; a < 8; ++a)
          for (int i = 0; i < 3; ++i)
            Dg[kl][a][i] = D[kl][3 * i] * geo.g[a][0] + D[kl][3 * i + 1] * geo.g[a][1] + D[kl][3 * i + 2] * geo.g[a][2];
      for (int a = 0; a < 8; ++a) {
        if (corner[a] >= m_.owned) continue;
        for (int b = 0; b < 8; ++b) {
          // K_ab[i][k] = V0 sum_l Dg[kl][a][i] g_b[l]: -d f_a / d x_b
          double K[9];
          for (int i = 0; i < 3; ++i)
            for (int kk = 0; kk < 3; ++kk)
              K[3 * i + kk] = geo.volume * (Dg[3 * kk][a][i] * geo.g[b][0] + Dg[3 * kk + 1][a][i] * geo.g[b][1] +
                                            Dg[3 * kk + 2][a][i] * geo.g[b][2]);
          const PetscErrorCode ierr = add(ctx, corner[a], corner[b], K);
          if (ierr) return ierr;
        }
      }
    }
    return 0;
  }

  void add_couplings(std::vector<std::vector<int>>& extra) const override {
    for (int k = 0; k < cells_; ++k)
      for (int a = 0; a < 8; ++a)
        if (corner_[8 * k + a] < m_.owned)
          for (int b = 0; b < 8; ++b) extra[corner_[8 * k + a]].push_back(corner_[8 * k + b]);
  }

  double critical_time_step() const override { return dt_; }

  void add_force_scale(std::vector<double>& scale) const override {
    // A corner's force at unit strain: V0 |g| times the cell's moduli.
    for (int k = 0; k < cells_; ++k) {
      const Moduli& md = moduli_[k];
      const Geometry& geo = geometry_[body_[k]];
      const double modulus = md.kappa + 2 * md.mu + 2 * (md.alpha[0] + md.alpha[1] + md.alpha[2]);
      for (int a = 0; a < 8; ++a) {
        const double* g = geo.g[a];
        scale[corner_[8 * k + a]] += geo.volume * modulus * std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
      }
    }
  }

private:
  struct Geometry {
    double volume = 0;
    double g[8][3];
  };
  // F = I + sum_a u_a (x) g_a, from displacements (positions far from the origin would cost digits of F - I).
  void gradient(const double* x, const int* corner, const Geometry& geo, double F[9]) const {
    double G[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    for (int c = 0; c < 8; ++c) {
      const double* xc = x + 3 * corner[c];
      const double* Xc = m_.rest.data() + 3 * corner[c];
      for (int i = 0; i < 3; ++i) {
        const double u = xc[i] - Xc[i];
        for (int j = 0; j < 3; ++j) G[3 * i + j] += u * geo.g[c][j];
      }
    }
    for (int q = 0; q < 9; ++q) F[q] = G[q] + (q % 4 == 0 ? 1.0 : 0.0);
  }

  const LocalModel& m_;
  int cells_ = 0;
  std::vector<int> corner_;  // 8 local indices per cell, corner c = (c & 1, c >> 1 & 1, c >> 2 & 1)
  std::vector<Moduli> moduli_;
  std::vector<int> body_;
  std::vector<char> owns_energy_;
  std::vector<Geometry> geometry_;
  double dt_ = std::numeric_limits<double>::infinity();
};

}  // namespace

std::unique_ptr<Term> make_cell_elasticity(const TermContext& c) {
  return std::make_unique<CellElasticity>(c.scene, c.model);
}

TISSUE_TERM(cell_elasticity, {"cell-elasticity", scene_has_cells, make_cell_elasticity,
                              "homogenized with poisson_ratio != 1/4 or flat cells: one energy per lattice cell of "
                              "its centre deformation gradient (docs/poisson.md)",
                              5, /*energy_never_grows=*/true});

}  // namespace tissue
