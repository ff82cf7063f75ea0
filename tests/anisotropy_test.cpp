// Anisotropic tissue (issue 17, docs/anisotropy.md): [body.fibres] with homogenized on box lattices against
// closed forms, each reference computed here independently of src/model/cell_law.cpp (the TI stiffness by
// inverting the engineering compliance, rotated by hand):
//  - fibres along x, y, z: tension along z on rollers reads E_L (fibres along z) or E_T (across), both lateral
//    Poisson ratios (nu_LT, nu_TT, nu_TL = nu_LT E_T / E_L), simple shear reads G_L or G_T, to 1e-6 at 1e-7 strain;
//  - fibres along (1, 2, 2)/3: the lattice's homogenized tensor from the model's own energy under affine strains
//    equals the rotated TI tensor to 1e-6 (cubic and flat cells);
//  - tension_only: compression along the fibres reads the matrix's E_m, nu_m; tension still E_L;
//  - a toe-law bar follows the one-cell Cauchy-Born response of the same energy (lateral stretch solved by a
//    Newton here) to 1e-6 along the whole curve; the static Newton converges quadratically through the toe;
//  - the fibre terms' force against a finite difference of the energy, the tangent against one of the force;
//  - quasi-linear viscoelastic fibres: the instantaneous and relaxed moduli;
//  - the snapshot's fibre field (direction, stretch) against the affine stretch;
//  - bad input: exit-2 errors naming the key.
#include <gtest/gtest.h>
#include <petscsys.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "tests/derivative_check.hpp"
#include "tests/pipeline.hpp"

using namespace tissue;
using namespace tissue::test_pipeline;

namespace {

// The material of most tests: fibres 20 times stiffer than the matrix, G_L above G_T.
struct Material {
  double E_L = 20000.0, E_T = 1000.0, nu_LT = 0.35, nu_TT = 0.3, G_L = 800.0;
  double G_T() const { return E_T / (2 * (1 + nu_TT)); }
};

using Mat6 = std::array<std::array<double, 6>, 6>;

// 6 x 6 inverse by Gauss-Jordan with partial pivoting.
Mat6 invert(Mat6 a) {
  Mat6 b{};
  for (int i = 0; i < 6; ++i) b[i][i] = 1;
  for (int c = 0; c < 6; ++c) {
    int p = c;
    for (int r = c + 1; r < 6; ++r)
      if (std::fabs(a[r][c]) > std::fabs(a[p][c])) p = r;
    std::swap(a[c], a[p]), std::swap(b[c], b[p]);
    const double d = a[c][c];
    for (int k = 0; k < 6; ++k) a[c][k] /= d, b[c][k] /= d;
    for (int r = 0; r < 6; ++r) {
      if (r == c) continue;
      const double f = a[r][c];
      for (int k = 0; k < 6; ++k) a[r][k] -= f * a[c][k], b[r][k] -= f * b[c][k];
    }
  }
  return b;
}

// Voigt index of (i, j): 11 22 33 23 13 12.
int voigt(int i, int j) {
  if (i == j) return i;
  return i + j == 3 ? 3 : i + j == 2 ? 4 : 5;
}

// The TI stiffness C_ijkl in the global frame, fibres along unit a: the fibre-frame compliance (axis 0 = fibre)
// inverted, then rotated by the frame (a, b, c).
std::array<double, 81> ti_tensor(const Material& m, const Vec3& a) {
  Mat6 S{};
  S[0][0] = 1 / m.E_L;
  S[1][1] = S[2][2] = 1 / m.E_T;
  S[0][1] = S[1][0] = S[0][2] = S[2][0] = -m.nu_LT / m.E_L;
  S[1][2] = S[2][1] = -m.nu_TT / m.E_T;
  S[3][3] = 1 / m.G_T();  // engineering shear strains: S44 = 1 / G
  S[4][4] = S[5][5] = 1 / m.G_L;
  const Mat6 C = invert(S);
  auto c_local = [&](int i, int j, int k, int l) { return C[voigt(i, j)][voigt(k, l)]; };
  // Frame: e0 = a, e1 perpendicular, e2 = a x e1.
  Vec3 t = std::fabs(a[0]) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  const double ta = t[0] * a[0] + t[1] * a[1] + t[2] * a[2];
  Vec3 b{t[0] - ta * a[0], t[1] - ta * a[1], t[2] - ta * a[2]};
  const double nb = std::sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
  for (double& x : b) x /= nb;
  const Vec3 c{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  const Vec3 R[3] = {a, b, c};  // R[p][i]: component i of frame vector p
  std::array<double, 81> out{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l) {
          double s = 0;
          for (int p = 0; p < 3; ++p)
            for (int q = 0; q < 3; ++q)
              for (int r = 0; r < 3; ++r)
                for (int u = 0; u < 3; ++u) s += R[p][i] * R[q][j] * R[r][k] * R[u][l] * c_local(p, q, r, u);
          out[27 * i + 9 * j + 3 * k + l] = s;
        }
  return out;
}

struct Case {
  std::array<long, 3> n{4, 4, 4};
  Vec3 h{1, 1, 1};
  Material mat;
  Vec3 direction{0, 0, 1};
  std::string topology = "face-diagonals";
  std::string test = "tension";  // tension | shear | none
  double stress = 0;             // Pa: the load (tension: along z; shear: tau)
  std::string fibre_extra;       // more lines of [body.fibres]
  std::string solver_extra;
};

std::string scene_text(const Case& c) {
  const double Lx = (c.n[0] - 1) * c.h[0], Ly = (c.n[1] - 1) * c.h[1], Lz = (c.n[2] - 1) * c.h[2];
  std::string s;
  char buf[2048];
  std::snprintf(buf, sizeof buf,
                "title = \"anisotropy test\"\n[body]\nshape = \"box\"\nmolecules = [%ld, %ld, %ld]\n"
                "spacing = [%.17g, %.17g, %.17g]\ntopology = \"%s\"\nyoungs_modulus = %.17g\npoisson_ratio = %.17g\n"
                "[body.fibres]\ndirection = [%.17g, %.17g, %.17g]\nyoungs_modulus = %.17g\npoisson_ratio = %.17g\n"
                "shear_modulus = %.17g\n%s"
                "[calibration]\nmethod = \"homogenized\"\n",
                c.n[0], c.n[1], c.n[2], c.h[0], c.h[1], c.h[2], c.topology.c_str(), c.mat.E_T, c.mat.nu_TT,
                c.direction[0], c.direction[1], c.direction[2], c.mat.E_L, c.mat.nu_LT, c.mat.G_L,
                c.fibre_extra.c_str());
  s += buf;
  auto fix = [&](const char* face, const char* mode) {
    s += std::string("[[fix]]\nface = \"") + face + "\"\nmode = \"" + mode + "\"\n";
  };
  auto load = [&](const char* face, double fx, double fy, double fz) {
    std::snprintf(buf, sizeof buf, "[[load]]\nface = \"%s\"\nforce = [%.17g, %.17g, %.17g]\n", face, fx, fy, fz);
    s += buf;
  };
  if (c.test == "tension") {
    fix("z-", "roller");
    load("z+", 0, 0, c.stress * Lx * Ly);
  } else if (c.test == "shear") {
    fix("z-", "clamped");
    load("z+", c.stress * Lx * Ly, 0, 0);
    load("x+", 0, 0, c.stress * Ly * Lz);
    load("x-", 0, 0, -c.stress * Ly * Lz);
  } else {
    fix("z-", "roller");
  }
  std::snprintf(buf, sizeof buf,
                "[solver]\nkind = \"static\"\ntolerance = 1e-9\n%s[output]\n"
                "directory = \"/tmp/tissue_anisotropy_test\"\n"
                "progress = false\n",
                c.solver_extra.c_str());
  s += buf;
  return s;
}

// Fibres along x, y, z; tension along z and simple shear in x-z against the engineering constants.
TEST(Anisotropy, AxisFibresMeasureFiveConstants) {
  const Material m;
  const double strain = 1e-7;
  const double nu_TL = m.nu_LT * m.E_T / m.E_L;
  for (int axis = 0; axis < 3; ++axis) {
    for (const Vec3 h : {Vec3{1, 1, 1}, Vec3{1, 1, 0.5}}) {
      Case c;
      c.h = h;
      c.direction = {0, 0, 0};
      c.direction[axis] = 1;
      // Tension along z: along the fibres (axis z) E_L, nu_LT on both lateral axes; across them E_T, nu_TL on
      // the fibre axis and nu_TT on the other.
      const bool along = axis == 2;
      const double E = along ? m.E_L : m.E_T;
      c.stress = E * strain;
      auto r = run(scene_text(c), PETSC_COMM_WORLD);
      ASSERT_TRUE(r->report.converged);
      ASSERT_TRUE(r->measured.youngs_modulus && r->measured.poisson_ratios);
      EXPECT_NEAR(*r->measured.youngs_modulus / E, 1.0, 1e-6) << "fibres along " << axis;
      const double nu_x = along ? m.nu_LT : axis == 0 ? nu_TL : m.nu_TT;
      const double nu_y = along ? m.nu_LT : axis == 1 ? nu_TL : m.nu_TT;
      EXPECT_NEAR((*r->measured.poisson_ratios)[0], nu_x, 1e-6) << "fibres along " << axis;
      EXPECT_NEAR((*r->measured.poisson_ratios)[1], nu_y, 1e-6) << "fibres along " << axis;
      // Simple shear of the x-z plane: G_L when the fibres lie in it (x or z), G_T when they are along y.
      const double G = axis == 1 ? m.G_T() : m.G_L;
      c.test = "shear", c.stress = G * strain;
      auto s = run(scene_text(c), PETSC_COMM_WORLD);
      ASSERT_TRUE(s->measured.shear_modulus);
      EXPECT_NEAR(*s->measured.shear_modulus / G, 1.0, 1e-6) << "fibres along " << axis;
    }
  }
}

// The lattice's small-strain tensor from the model's own energy: under the affine displacement u = eps e X of a
// unit strain e, every cell (springs and cell term) holds V_cell e:C:e / 2, so the block's energy is
// V e:C:e eps^2 / 2 + O(eps^4) after averaging +eps and -eps. Polarization gives every C_pq.
double energy(RunResult& r, const std::array<double, 9>& grad, double eps) {
  const LocalModel& m = r.model;
  std::vector<double> x(m.rest.begin(), m.rest.end());
  for (int i = 0; i < m.local; ++i)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) x[3 * i + a] += eps * grad[3 * a + b] * m.rest[3 * i + b];
  double e = r.forces->potential_energy(x.data()), total = 0;
  MPI_Allreduce(&e, &total, 1, MPI_DOUBLE, MPI_SUM, PETSC_COMM_WORLD);
  return total;
}

TEST(Anisotropy, ObliqueFibresHomogenizedTensor) {
  const Vec3 a{1.0 / 3, 2.0 / 3, 2.0 / 3};
  for (const Vec3 h : {Vec3{1, 1, 1}, Vec3{1, 1, 0.5}}) {
    for (const char* topology : {"face-diagonals", "body-diagonals"}) {
      Case c;
      c.n = {3, 3, 3}, c.h = h, c.direction = a, c.test = "none", c.topology = topology;
      auto r = run(scene_text(c), PETSC_COMM_WORLD, {}, /*do_solve=*/false);
      const double V = 2 * h[0] * 2 * h[1] * 2 * h[2];
      const auto C = ti_tensor(c.mat, a);
      // The six unit strains (symmetric gradients): e_p.
      std::array<std::array<double, 9>, 6> e{};
      const int I[6] = {0, 1, 2, 1, 0, 0}, J[6] = {0, 1, 2, 2, 2, 1};
      for (int p = 0; p < 6; ++p) e[p][3 * I[p] + J[p]] = 1, e[p][3 * J[p] + I[p]] = 1;
      const double eps = 1e-4;
      auto Q = [&](const std::array<double, 9>& g) {
        return (energy(*r, g, eps) + energy(*r, g, -eps)) / (eps * eps * V);  // g:C:g
      };
      double scale = 0;
      for (double x : C) scale = std::max(scale, std::fabs(x));
      for (int p = 0; p < 6; ++p)
        for (int q = p; q < 6; ++q) {
          std::array<double, 9> plus{}, minus{};
          for (int k = 0; k < 9; ++k) plus[k] = e[p][k] + e[q][k], minus[k] = e[p][k] - e[q][k];
          const double got = (Q(plus) - Q(minus)) / 4;  // e_p:C:e_q
          double want = 0;
          for (int k = 0; k < 9; ++k)
            for (int l = 0; l < 9; ++l) want += e[p][k] * C[9 * k + l] * e[q][l];
          EXPECT_NEAR(got / scale, want / scale, 1e-6) << topology << " h_z " << h[2] << " p " << p << " q " << q;
        }
    }
  }
}

// Tension-only fibres: the fibre and coupling terms are off while I4 < 1, so compression along the fibres reads
// the matrix (E_m, nu_m) with lambda_m = C23 and mu_m = G_T of the TI tensor; tension still reads E_L.
TEST(Anisotropy, TensionOnlyCompressionReadsMatrix) {
  const Material m;
  const auto C = ti_tensor(m, {1, 0, 0});  // fibre frame = global frame
  const double mu = C[27 * 1 + 9 * 2 + 3 * 1 + 2], lambda = C[27 * 1 + 9 * 1 + 3 * 2 + 2];  // C_1212 (y-z), C_1122
  EXPECT_NEAR(mu / m.G_T(), 1.0, 1e-12);
  const double E_m = mu * (3 * lambda + 2 * mu) / (lambda + mu), nu_m = lambda / (2 * (lambda + mu));
  Case c;
  c.fibre_extra = "tension_only = true\n";
  const double strain = 1e-7;
  c.stress = -E_m * strain;
  auto r = run(scene_text(c), PETSC_COMM_WORLD);
  ASSERT_TRUE(r->measured.youngs_modulus && r->measured.poisson_ratios);
  EXPECT_NEAR(*r->measured.youngs_modulus / E_m, 1.0, 1e-6);
  EXPECT_NEAR((*r->measured.poisson_ratios)[0], nu_m, 1e-6);
  EXPECT_NEAR((*r->measured.poisson_ratios)[1], nu_m, 1e-6);
  EXPECT_LT(E_m, 0.5 * m.E_L);
  c.stress = m.E_L * strain;
  auto t = run(scene_text(c), PETSC_COMM_WORLD);
  ASSERT_TRUE(t->measured.youngs_modulus);
  EXPECT_NEAR(*t->measured.youngs_modulus / m.E_L, 1.0, 1e-6);
}

// The one-cell Cauchy-Born response of the same energy: a 2 x 2 x 2 body (one cell: every spring in one cell,
// the cell term once) stretched by F = diag(l) has energy V W(l); its nominal stress is P_aa = dW/dl_a. The
// lateral stretches solve P_xx = P_yy = 0 and l_z solves P_zz = the load (Newton here, finite differences of the
// model's own energy).
struct OneCell {
  std::unique_ptr<RunResult> r;
  Vec3 h;
  double energy(const Vec3& l) const {
    const LocalModel& m = r->model;
    std::vector<double> x(m.rest.begin(), m.rest.end());
    for (int i = 0; i < m.local; ++i)
      for (int a = 0; a < 3; ++a) x[3 * i + a] = l[a] * m.rest[3 * i + a];
    return r->forces->potential_energy(x.data()) / (h[0] * h[1] * h[2]);
  }
  std::array<double, 3> residual(const Vec3& l, double target) const {
    std::array<double, 3> out{};
    const double d = 1e-6;
    for (int a = 0; a < 3; ++a) {
      Vec3 lp = l, lm = l;
      lp[a] += d, lm[a] -= d;
      out[a] = (energy(lp) - energy(lm)) / (2 * d) - (a == 2 ? target : 0.0);
    }
    return out;
  }
  Vec3 solve(double target, Vec3 l) const {
    for (int it = 0; it < 50; ++it) {
      const auto r0 = residual(l, target);
      if (std::fabs(r0[0]) + std::fabs(r0[1]) + std::fabs(r0[2]) < 1e-10 * (1 + std::fabs(target))) break;
      double J[3][3];
      for (int b = 0; b < 3; ++b) {
        Vec3 lp = l, lm = l;
        lp[b] += 1e-5, lm[b] -= 1e-5;
        const auto rp = residual(lp, target), rm = residual(lm, target);
        for (int a = 0; a < 3; ++a) J[a][b] = (rp[a] - rm[a]) / 2e-5;
      }
      // Cramer.
      auto det3 = [](double M[3][3]) {
        return M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
               M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]);
      };
      const double d = det3(J);
      Vec3 step{};
      for (int k = 0; k < 3; ++k) {
        double M[3][3];
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) M[a][b] = b == k ? -r0[a] : J[a][b];
        step[k] = det3(M) / d;
      }
      for (int a = 0; a < 3; ++a) l[a] += step[a];
    }
    return l;
  }
};

TEST(Anisotropy, ToeBarFollowsCauchyBorn) {
  const std::string toe = "toe = { law = \"exp-linear\", stretch = 1.03, exponent = 60.0 }\n";
  Case cell;
  cell.n = {2, 2, 2}, cell.test = "none", cell.fibre_extra = toe;
  OneCell one{run(scene_text(cell), MPI_COMM_SELF, {}, /*do_solve=*/false), cell.h};
  Vec3 l{1, 1, 1};
  // Loads from the toe (strain < 3 %) into the linear part; each a static solve with load steps.
  for (const double stress : {2.0, 10.0, 50.0, 200.0, 600.0, 1200.0}) {
    l = one.solve(stress, l);
    Case bar;
    bar.n = {3, 3, 6}, bar.fibre_extra = toe, bar.stress = stress, bar.solver_extra = "load_steps = 4\n";
    auto r = run(scene_text(bar), PETSC_COMM_WORLD);
    ASSERT_TRUE(r->report.converged) << stress;
    ASSERT_TRUE(r->measured.elongation);
    const double strain = *r->measured.elongation / 5.0;
    EXPECT_NEAR(strain / (l[2] - 1), 1.0, 1e-6) << "stress " << stress << " one-cell stretch " << l[2];
  }
  EXPECT_GT(l[2], 1.03);  // the last load is past the toe
}

// Force = -dE/dx and tangent = -df/dx by central differences at a large strain, for the quadratic fibre law,
// tension-only, and the toe (below and beyond its stretch), oblique fibres so every term is on.
TEST(Anisotropy, FibreTermDerivatives) {
  struct D {
    std::string extra;
    double stretch;
  };
  for (const D d : {D{"", 0.0}, D{"tension_only = true\n", 0.02},
                    D{"toe = { law = \"exp-linear\", stretch = 1.03, exponent = 60.0 }\n", 0.0},
                    D{"toe = { law = \"exp-linear\", stretch = 1.03, exponent = 60.0 }\n", 0.06}}) {
    Case c;
    c.n = {3, 3, 3}, c.direction = {1.0 / 3, 2.0 / 3, 2.0 / 3}, c.test = "none", c.fibre_extra = d.extra;
    auto r = run(scene_text(c), MPI_COMM_SELF, {}, /*do_solve=*/false);
    std::vector<double> x;
    deform(r->model, x, d.stretch);
    EXPECT_GT(expect_consistent_derivatives(r->model, *r->forces, x, d.extra), 30);
  }
}

// The fibre field of the snapshots: under tension along the fibres (affine state) every molecule's fibre stretch
// is 1 + the measured strain and its direction stays along z; across the fibres the stretch is 1 - nu_TL strain.
TEST(Anisotropy, FibreFieldIsTheAffineStretch) {
  const Material m;
  for (const int axis : {2, 0}) {
    Case c;
    c.direction = {0, 0, 0};
    c.direction[axis] = 1;
    c.stress = 1e-4 * (axis == 2 ? m.E_L : m.E_T);
    auto r = run(scene_text(c), PETSC_COMM_WORLD);
    ASSERT_TRUE(r->measured.elongation);
    const double strain = *r->measured.elongation / 3.0;
    const double want = axis == 2 ? 1 + strain : 1 - m.nu_LT * m.E_T / m.E_L * strain;
    const int n = r->model.owned;
    std::vector<double> direction(3 * n), stretch(n);
    ASSERT_TRUE(r->forces->fibre_field(r->state->x.array(), direction.data(), stretch.data()));
    for (int i = 0; i < n; ++i) {
      EXPECT_NEAR(stretch[i] - 1, want - 1, 1e-6 * 1e-4) << "molecule " << r->model.id[i];
      EXPECT_NEAR(direction[3 * i + axis], 1.0, 1e-9);
    }
  }
}

// Quasi-linear viscoelastic fibres: with nu_TT chosen so that the matrix is nu_m = 1/4 (3 nu_TT + 4 nu_LT^2
// E_T / E_L = 1: no isotropic cell part), the springs and the fibre terms carry the whole TI tensor and both
// follow the Prony series E(t) = E (1 + gamma exp(-t / tau)), so the block's affine response is the scalar one.
// A load held from t = 0: the instantaneous modulus (1 + gamma) E just after it (t = 1e-9 s), and after N steps
// of dt the exact exponential update's creep, eps_N = (sigma / E)(1 - gamma / (1 + gamma) r^N) with
// r = (exp(-dt/tau) + gamma beta) / (1 + gamma beta), beta = (1 - exp(-dt/tau)) tau / dt; each to 1e-6, along
// (E_L) and across (E_T) the fibres.
TEST(Anisotropy, ViscoelasticFibres) {
  Material m;
  m.nu_LT = 0.5;
  m.nu_TT = (1 - 4 * m.nu_LT * m.nu_LT * m.E_T / m.E_L) / 3;
  const double gamma = 1.5, tau = 1.0;
  for (const int axis : {2, 0}) {
    for (const bool instantaneous : {true, false}) {
      Case c;
      c.mat = m;
      c.direction = {0, 0, 0};
      c.direction[axis] = 1;
      const double E = axis == 2 ? m.E_L : m.E_T;
      const double dt = instantaneous ? 1e-9 : 1.0, steps = instantaneous ? 1 : 10;
      const double beta = -std::expm1(-dt / tau) * tau / dt;
      const double r = (std::exp(-dt / tau) + gamma * beta) / (1 + gamma * beta);
      const double want = instantaneous ? (1 + gamma) * E : E / (1 - gamma / (1 + gamma) * std::pow(r, steps));
      c.stress = 1e-7 * E;
      char solver[128];
      std::snprintf(solver, sizeof solver, "kind = \"quasi-static\"\ntime_step = %.17g\nend_time = %.17g\n", dt,
                    dt * steps);
      c.solver_extra = solver;
      std::string text = scene_text(c);
      text.replace(text.find("kind = \"static\"\n"), 16, "");
      text.replace(text.find("[calibration]"), 13, "[body.viscoelastic]\ngamma = [1.5]\ntau = [1.0]\n[calibration]");
      auto r_ = run(text, PETSC_COMM_WORLD);
      ASSERT_TRUE(r_->measured.youngs_modulus);
      EXPECT_NEAR(*r_->measured.youngs_modulus / want, 1.0, 1e-6) << "axis " << axis << " dt " << dt;
      if (!instantaneous) EXPECT_GT(want / E, 1.01);  // mid-creep, not relaxed: the history is still acting
    }
  }
}

// The critical time step of a fibre body comes from its stiffest wave: below the isotropic matrix's by about
// sqrt(E_L / E_T).
TEST(Anisotropy, CriticalTimeStepFromStiffestWave) {
  Case c;
  c.test = "none";
  auto r = run(scene_text(c), PETSC_COMM_WORLD, {}, /*do_solve=*/false);
  const double dt = critical_time_step(*r->forces);
  const auto C = ti_tensor(c.mat, {0, 0, 1});
  // The P-wave along the fibres: rho c^2 = C_zzzz; the bound must be at most 0.8 h / c.
  EXPECT_LE(dt, 0.8 * 1.0 / std::sqrt(C[80] / 1000.0) * (1 + 1e-12));
  EXPECT_GT(dt, 0.5 * 0.8 / std::sqrt(C[80] / 1000.0));
}

void expect_refused(const std::string& text, const std::string& key) {
  try {
    parse_scene(text, "test.toml");
    ADD_FAILURE() << "accepted: " << key;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
  }
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
  text.replace(text.find(from), from.size(), to);
  return text;
}

TEST(Anisotropy, BadInput) {
  Case c;
  c.stress = 1.0;
  const std::string text = scene_text(c);
  EXPECT_NO_THROW(parse_scene(text, "test.toml"));
  expect_refused(replaced(text, "method = \"homogenized\"", "method = \"linear\"\n#"), "calibration.method");
  expect_refused(replaced(text, "direction = [0, 0, 1]", "direction = [0.0, 0.0, 0.0]"), "body.fibres.direction");
  // Not positive definite: nu_LT too large for E_T / E_L (1 - nu_TT - 2 nu_LT^2 E_T / E_L < 0).
  expect_refused(replaced(text, "poisson_ratio = 0.34999999999999998", "poisson_ratio = 3.0 #"), "body.fibres");
  expect_refused(replaced(text, "[calibration]", "toe = { law = \"exp-linear\", stretch = 0.9, exponent = 10.0 }\n"
                                                 "[calibration]"),
                 "body.fibres.toe.stretch");
  expect_refused(replaced(text, "[calibration]", "toe = { law = \"poly\", stretch = 1.1, exponent = 10.0 }\n"
                                                 "[calibration]"),
                 "body.fibres.toe.law");
  expect_refused(replaced(replaced(text, "poisson_ratio = 0.29999999999999999\n[body.fibres]", "[body.fibres]"),
                          "face-diagonals", "rectangular"),
                 "body.fibres");
  // Tension-only fibres softer than the matrix (E_f <= 0) have no stretched state to carry.
  expect_refused(replaced(replaced(text, "youngs_modulus = 20000", "youngs_modulus = 900"), "[calibration]",
                          "tension_only = true\n[calibration]"),
                 "body.fibres");
}

}  // namespace
