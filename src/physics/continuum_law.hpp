// The continuum energy density shared by the per-cell terms (the lattice cell term, cell_elasticity.cpp, and the
// per-tetrahedron term of meshes and clouds, tetrahedron_elasticity.cpp): isochoric neo-Hookean, a volumetric part
// convex and infinite as J -> 0, the lattice's virtual face diagonals, and the fibre families of transverse
// isotropy (docs/poisson.md, docs/anisotropy.md). P = dW/dF is templated on the scalar so that forward-mode dual
// numbers give the exact tangent through the same code as the force.
#pragma once
#include <cmath>
#include <limits>

namespace tissue {
namespace continuum {

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
inline double exponential(double x) { return std::exp(x); }
inline Dual exponential(Dual x) {
  const double y = std::exp(x.v);
  return {y, y * x.d};
}
inline double root(double x) { return std::sqrt(x); }
inline Dual root(Dual x) {
  const double y = std::sqrt(x.v);
  return {y, 0.5 * x.d / y};
}

struct Moduli {
  double mu = 0, kappa = 0, alpha[3] = {0, 0, 0};
};

// One fibre family of a cell (docs/anisotropy.md): unit direction a, fibre modulus E_f, fibre-shear dG, coupling
// alpha (Pa); tension_only: the fibre and coupling terms (both carry the factor I4 - 1) are off while I4 < 1; toe:
// the fibre term is the exp-linear law of the fibre's nominal stress s(lambda), lambda = sqrt(I4):
//   s = c3 (exp(c4 (lambda - 1)) - 1) up to lambda1, then s(lambda1) + E_f (lambda - lambda1),
//   c3 = E_f / (c4 exp(c4 (lambda1 - 1))) (continuous slope), energy W = integral_1^lambda s.
// Families of the cell's 8 corners that share a direction and a law are merged (their moduli add: exact, every
// term is linear in its modulus).
struct Fibre {
  double a[3] = {0, 0, 1};
  double E_f = 0, dG = 0, alpha = 0;
  bool tension_only = false;
  double toe_stretch = 0, toe_exponent = 0;  // toe_stretch = 0: the quadratic fibre term
  bool same_law(const Fibre& o) const {
    return a[0] == o.a[0] && a[1] == o.a[1] && a[2] == o.a[2] && tension_only == o.tension_only &&
           toe_stretch == o.toe_stretch && toe_exponent == o.toe_exponent;
  }
};

// The toe law's nominal stress s(lambda) and energy W(lambda) per unit reference volume.
template <class T>
T toe_stress(const T& lambda, const Fibre& f) {
  const double c4 = f.toe_exponent, l1 = f.toe_stretch;
  const double c3 = f.E_f / (c4 * std::exp(c4 * (l1 - 1.0)));
  if (value(lambda) <= l1) return T(c3) * (exponential(T(c4) * (lambda - T(1.0))) - T(1.0));
  return T(c3 * std::expm1(c4 * (l1 - 1.0))) + T(f.E_f) * (lambda - T(l1));
}
inline double toe_energy(double lambda, const Fibre& f) {
  const double c4 = f.toe_exponent, l1 = f.toe_stretch;
  const double c3 = f.E_f / (c4 * std::exp(c4 * (l1 - 1.0)));
  auto exp_part = [&](double l) { return c3 * (std::expm1(c4 * (l - 1.0)) / c4 - (l - 1.0)); };
  if (lambda <= l1) return exp_part(lambda);
  const double d = lambda - l1;
  return exp_part(l1) + c3 * std::expm1(c4 * (l1 - 1.0)) * d + 0.5 * f.E_f * d * d;
}

// Adds the fibre family's P = dW/dF (J, cof = J F^-T as in stress()).
template <class T>
void add_fibre_stress(const T F[9], const T& J, const T cof[9], const Fibre& f, T P[9]) {
  T Fa[3];
  for (int i = 0; i < 3; ++i) Fa[i] = F[3 * i] * T(f.a[0]) + F[3 * i + 1] * T(f.a[1]) + F[3 * i + 2] * T(f.a[2]);
  const T I4 = Fa[0] * Fa[0] + Fa[1] * Fa[1] + Fa[2] * Fa[2];
  const bool stretched = !f.tension_only || value(I4) >= 1.0;
  // c (F a) (x) a collects the fibre and the coupling terms' share along (F a) (x) a.
  T c = T(0.0);
  if (stretched) {
    if (f.toe_stretch > 0) {
      const T lambda = root(I4);
      c = toe_stress(lambda, f) / lambda;  // dW/dF = s(lambda) / lambda (F a) (x) a
    } else {
      c = T(0.5 * f.E_f) * (I4 - T(1.0));  // E_f/8 (I4 - 1)^2
    }
    if (f.alpha != 0) {
      // alpha/2 (I4 - 1)(J - 1): alpha (J - 1) (F a) (x) a + alpha/2 (I4 - 1) cof
      c = c + T(f.alpha) * (J - T(1.0));
      const T v = T(0.5 * f.alpha) * (I4 - T(1.0));
      for (int q = 0; q < 9; ++q) P[q] = P[q] + v * cof[q];
    }
  }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) P[3 * i + j] = P[3 * i + j] + c * Fa[i] * T(f.a[j]);
  if (f.dG != 0) {
    // dG/2 (I5 - I4^2): dG [(F a) (x) (C a) + (F C a) (x) a - 2 I4 (F a) (x) a]
    T Ca[3], FCa[3];
    for (int j = 0; j < 3; ++j) Ca[j] = F[j] * Fa[0] + F[3 + j] * Fa[1] + F[6 + j] * Fa[2];  // F^T (F a)
    for (int i = 0; i < 3; ++i) FCa[i] = F[3 * i] * Ca[0] + F[3 * i + 1] * Ca[1] + F[3 * i + 2] * Ca[2];
    const T g = T(f.dG);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        P[3 * i + j] = P[3 * i + j] + g * (Fa[i] * Ca[j] + FCa[i] * T(f.a[j]) - T(2.0) * I4 * Fa[i] * T(f.a[j]));
  }
}

inline double fibre_energy_density(const double F[9], double J, const Fibre& f) {
  double Fa[3];
  for (int i = 0; i < 3; ++i) Fa[i] = F[3 * i] * f.a[0] + F[3 * i + 1] * f.a[1] + F[3 * i + 2] * f.a[2];
  const double I4 = Fa[0] * Fa[0] + Fa[1] * Fa[1] + Fa[2] * Fa[2];
  double W = 0;
  if (!f.tension_only || I4 >= 1.0) {
    W += f.toe_stretch > 0 ? toe_energy(std::sqrt(I4), f) : 0.125 * f.E_f * (I4 - 1.0) * (I4 - 1.0);
    W += 0.5 * f.alpha * (I4 - 1.0) * (J - 1.0);
  }
  if (f.dG != 0) {
    double Ca[3], I5 = 0;
    for (int j = 0; j < 3; ++j) Ca[j] = F[j] * Fa[0] + F[3 + j] * Fa[1] + F[6 + j] * Fa[2];
    for (int j = 0; j < 3; ++j) I5 += Ca[j] * Ca[j];
    W += 0.5 * f.dG * (I5 - I4 * I4);
  }
  return W;
}

// First Piola-Kirchhoff stress P = dW/dF (row-major 3 x 3) of the energy density above; returns false when
// J <= 0 (the energy is infinite there).
template <class T>
bool stress(const T F[9], const Moduli& m, const Fibre* fibres, int nfibres, T P[9]) {
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
  for (int k = 0; k < nfibres; ++k) add_fibre_stress(F, J, cof, fibres[k], P);
  return true;
}

// The output of a cell's fibres (docs/anisotropy.md): the stiffest family's deformed direction F a (into Fa) and
// its stretch |F a|; 0 and Fa = 0 when the cell has no fibre.
inline double fibre_stretch(const double F[9], const Fibre* fibres, int nfibres, double Fa[3]) {
  Fa[0] = Fa[1] = Fa[2] = 0.0;
  if (nfibres <= 0) return 0.0;
  const Fibre* f = fibres;  // a cell across a region boundary may hold two families
  for (int q = 1; q < nfibres; ++q)
    if (fibres[q].E_f > f->E_f) f = fibres + q;
  for (int i = 0; i < 3; ++i) Fa[i] = F[3 * i] * f->a[0] + F[3 * i + 1] * f->a[1] + F[3 * i + 2] * f->a[2];
  return std::sqrt(Fa[0] * Fa[0] + Fa[1] * Fa[1] + Fa[2] * Fa[2]);
}

inline double energy_density(const double F[9], const Moduli& m, const Fibre* fibres, int nfibres) {
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
  for (int k = 0; k < nfibres; ++k) W += fibre_energy_density(F, J, fibres[k]);
  return W;
}


}  // namespace continuum
}  // namespace tissue
