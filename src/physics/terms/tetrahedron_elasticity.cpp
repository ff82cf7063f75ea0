// The tetrahedron term: `homogenized` on meshes and random clouds (docs/poisson.md, "Meshes and random clouds").
// One energy per tetrahedron of its linear deformation gradient, the continuum law of the lattice cell term
// (src/physics/continuum_law.hpp) with the whole target: isochoric neo-Hookean mu = E / (2 (1 + nu)), volumetric
// kappa = E / (3 (1 - 2 nu)), and with [body.fibres] the matrix (E_m, nu_m) plus the fibre, fibre-shear and
// coupling terms of transverse isotropy (src/model/cell_law.hpp). The springs carry nothing (homogenized sets them
// to 0 on these bodies: central springs on an irregular graph are not isotropic), so every affine state has the
// target's stress in every tetrahedron: with traction loads by tributary area (a third of each face triangle: the
// consistent loads of linear tetrahedra) a block's affine tension is the discrete equilibrium, and E, nu (and the
// five fibre constants) are measured to round-off at small strain, on any mesh.
//
// The volumetric part is averaged per molecule (nodal averaging), so nu -> 1/2 does not lock (one volume
// constraint per molecule, not per tetrahedron):
//   W = sum_t V_t W_iso(F_t) + sum_(a,m) V_am U_m(Jbar_am),  V_am = sum_(t ni a, in m) V_t / 4,
//   Jbar_am = sum_(t ni a, in m) (V_t / 4) J_t / V_am,       U_m(J) = kappa_m / 4 (J^2 - 1 - 2 ln J),
// one patch per molecule a and material m (a region's tetrahedra average among themselves: a state uniform in each
// region stays exact across an interface). Affine states keep Jbar = J, hence the same stress as before. Fibres
// (and their J coupling) stay per tetrahedron. The force on corner b of t is -V_t (P_iso + pbar_t cof F_t) g_b with
// pbar_t = (1/4) sum_(a in t) U'(Jbar_a,m(t)): pass 1 computes p = U'(Jbar) for the owned molecules (which hold all
// their tetrahedra), one ghost update gives the corners' p, pass 2 the forces.
// The tangent: each tetrahedron's isochoric part and pbar_t V_t d2J_t, plus per owned patch the rank-one block
// U''(Jbar)/V_am g g^T over the patch's star (g_b = sum_t (V_t / 4) dJ_t/dx_b): it couples molecules two rings
// apart, so those rows of ghosts are added off-process (the owners' pattern gets them: add_remote_couplings).
//
// F = I + sum_a u_a (x) g_a (u the displacements, g_a the gradients of the linear shape functions: rows of
// Dm^-1 for corners 1..3, g_0 = -(g_1 + g_2 + g_3), Dm = [X_1 - X_0, X_2 - X_0, X_3 - X_0]); forces
// f_a = -V P g_a; the tangent is P's exact derivative by forward-mode dual numbers through the same code.
//
// Ranks: each rank holds the tetrahedra with an owned corner (partition/explicit_model.cpp), evaluates them in
// increasing global id and adds to its owned corners only: a molecule sums its tetrahedra (and a patch its J) in
// the same order on any partition, so results are bit for bit those of one rank. A tetrahedron's energy and
// output belong to the rank owning its lowest-id corner; a patch's energy to its molecule's owner.
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include "partition/ghosted_vector.hpp"
#include "src/model/cell_law.hpp"
#include "src/physics/continuum_law.hpp"
#include "src/physics/term.hpp"

namespace tissue {

namespace {

using namespace continuum;

class TetrahedronElasticity final : public Term {
public:
  TetrahedronElasticity(const Scene& scene, const LocalModel& model) : m_(model), pressure_(model, material_count(scene)) {
    const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
    // One material per body and per region of it (a mesh's physical volumes: each tetrahedron has its region's).
    auto material = [](double youngs_modulus, std::optional<double> poisson_ratio, const FibreSpec* fibres,
                       double density) {
      Material mat;
      mat.density = density;
      const double nu = poisson_ratio.value_or(0.25);
      double E = youngs_modulus, n = nu;
      if (fibres) {
        const TransverseIsotropy ti = transverse_isotropy(youngs_modulus, nu, *fibres);
        const FibreModuli fm = fibre_moduli(ti);
        E = fm.E_m, n = fm.nu_m;
        Fibre f;
        for (int d = 0; d < 3; ++d) f.a[d] = fibres->direction[d];
        f.E_f = fm.E_f, f.dG = fm.dG, f.alpha = fm.alpha;
        f.tension_only = fibres->tension_only;
        f.toe_stretch = fibres->toe_stretch, f.toe_exponent = fibres->toe_exponent;
        mat.fibres.push_back(f);
      }
      mat.moduli.mu = E / (2.0 * (1.0 + n));
      mat.moduli.kappa = E / (3.0 * (1.0 - 2.0 * n));
      mat.iso = mat.moduli;
      mat.iso.kappa = 0;  // the volumetric part is the patches' (nodal averaging)
      mat.force_modulus = mat.moduli.kappa + 2.0 * mat.moduli.mu;
      for (const Fibre& f : mat.fibres) mat.force_modulus += std::abs(f.E_f) + 2 * std::abs(f.dG) + 2 * std::abs(f.alpha);
      return mat;
    };
    std::vector<int> first_material;  // per body: its own material, then its regions'
    for (const BodySpec& spec : specs) {
      first_material.push_back(static_cast<int>(materials_.size()));
      const FibreSpec* body_fibres = spec.fibres ? &*spec.fibres : nullptr;
      materials_.push_back(material(spec.youngs_modulus, spec.poisson_ratio, body_fibres, spec.density));
      for (const RegionSpec& r : spec.regions)  // a region inherits the body's fibres and nu (the scene reader)
        materials_.push_back(material(r.youngs_modulus, r.poisson_ratio, r.fibres ? &*r.fibres : body_fibres,
                                      r.density));
    }
    const std::size_t count = model.tetrahedron_id.size();
    geometry_.resize(count);
    material_.resize(count);
    owns_energy_.resize(count);
    long long owned_energy = 0;
    std::vector<double> row_sum(3 * static_cast<std::size_t>(model.owned), 0.0);  // |K| row sums, owned rows
    for (std::size_t t = 0; t < count; ++t) {
      const int* c = &model.tetrahedra[4 * t];
      Geometry& geo = geometry_[t];
      material_[t] = first_material[model.body[c[0]]] +
                 (model.tetrahedron_region.empty() ? 0 : 1 + model.tetrahedron_region[t]);
      // Dm^-1 by cofactors: row r of Dm^-1 is g_(r+1).
      double D[3][3];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) D[i][j] = model.rest[3 * c[j + 1] + i] - model.rest[3 * c[0] + i];
      const double det = D[0][0] * (D[1][1] * D[2][2] - D[1][2] * D[2][1]) -
                         D[0][1] * (D[1][0] * D[2][2] - D[1][2] * D[2][0]) +
                         D[0][2] * (D[1][0] * D[2][1] - D[1][1] * D[2][0]);
      if (det != 0) {
        // inv[j][i] = cofactor(i, j) / det
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            const int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
            geo.g[j + 1][i] = (D[i1][j1] * D[i2][j2] - D[i1][j2] * D[i2][j1]) / det;
          }
        geo.volume = std::abs(det) / 6.0;
      }  // else a flat tetrahedron: no volume, no energy (g = 0)
      for (int i = 0; i < 3; ++i) geo.g[0][i] = -(geo.g[1][i] + geo.g[2][i] + geo.g[3][i]);
      int lowest = 0;
      for (int a = 1; a < 4; ++a)
        if (model.id[c[a]] < model.id[c[lowest]]) lowest = a;
      owns_energy_[t] = c[lowest] < model.owned;
      owned_energy += owns_energy_[t];
      // The explicit time step: element by element, omega^2 <= max over tetrahedra of the largest eigenvalue of
      // M_t^-1 K_t with M_t = rho V / 4 per corner (a molecule's mass is the sum of its tetrahedra's quarters,
      // src/model/unstructured.cpp). K_t (at rest) is positive semi-definite with at most 6 non-zero eigenvalues,
      // so lambda_max <= trace(K_t^8)^(1/8) = |K_t^4|_F^(1/4) <= 6^(1/8) lambda_max: an upper bound within 1.25x.
      if (geo.volume > 0) {
        const Material& mat = materials_[material_[t]];
        double K[12][12];
        element_stiffness(t, nullptr, nullptr, K);
        for (int a = 0; a < 4; ++a)
          if (c[a] < model.owned)
            for (int i = 0; i < 3; ++i)
              for (int q = 0; q < 12; ++q) row_sum[3 * c[a] + i] += std::abs(K[3 * a + i][q]);
        const double lambda = largest_eigenvalue_bound(K);
        dt_ = std::min(dt_, 2.0 / std::sqrt(lambda / (0.25 * mat.density * geo.volume)));
      }
    }
    // Or Gershgorin on the assembled M^-1 K with the molecules' own masses (a sliver's quarter of its own small
    // volume makes the element bound loose): the larger of two upper-bound-derived steps is still a lower bound of
    // the stability limit.
    double rate = 0;
    for (int i = 0; i < model.owned; ++i)
      for (int d = 0; d < 3; ++d) rate = std::max(rate, row_sum[3 * i + d] / model.mass[i]);
    // Each bound over all ranks first (a per-rank max of the two would depend on the partition).
    double element_dt = dt_, largest_rate = rate;
    MPI_Allreduce(&element_dt, &dt_, 1, MPI_DOUBLE, MPI_MIN, model.comm);
    MPI_Allreduce(&rate, &largest_rate, 1, MPI_DOUBLE, MPI_MAX, model.comm);
    if (largest_rate > 0) dt_ = std::max(dt_, 2.0 / std::sqrt(largest_rate));
    MPI_Allreduce(&owned_energy, &global_count_, 1, MPI_LONG_LONG, MPI_SUM, model.comm);

    // The patches: each owned molecule's tetrahedra (all held here), in increasing id, and V_am.
    nmat_ = static_cast<int>(materials_.size());
    star_start_.assign(model.owned + 1, 0);
    for (std::size_t t = 0; t < count; ++t)
      for (int a = 0; a < 4; ++a)
        if (model.tetrahedra[4 * t + a] < model.owned) ++star_start_[model.tetrahedra[4 * t + a] + 1];
    for (int i = 0; i < model.owned; ++i) star_start_[i + 1] += star_start_[i];
    star_tets_.resize(star_start_[model.owned]);
    std::vector<int> fill(star_start_.begin(), star_start_.end() - 1);
    patch_volume_.assign(static_cast<std::size_t>(nmat_) * model.owned, 0.0);
    for (std::size_t t = 0; t < count; ++t)
      for (int a = 0; a < 4; ++a) {
        const int c = model.tetrahedra[4 * t + a];
        if (c >= model.owned) continue;
        star_tets_[fill[c]++] = static_cast<int>(t);
        patch_volume_[static_cast<std::size_t>(nmat_) * c + material_[t]] += 0.25 * geometry_[t].volume;
      }
    jbar_.assign(patch_volume_.size(), 1.0);
    dt_ = std::max(dt_, averaged_time_step());
  }

  void add_forces(const double* x, const double*, double, double* f) override {
    update_pressure(x);  // collective: every rank calls forces together
    const double* p = pressure_.array();
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      const int* c = &m_.tetrahedra[4 * t];
      const Geometry& geo = geometry_[t];
      const Material& mat = materials_[material_[t]];
      double F[9], P[9];
      gradient(x, t, F);
      if (!stress(F, mat.iso, mat.fibres.data(), static_cast<int>(mat.fibres.size()), P)) {
        // An inverted tetrahedron: its energy is infinite; NaN forces make every solver's guard stop or cut back.
        for (int a = 0; a < 4; ++a)
          if (c[a] < m_.owned)
            for (int i = 0; i < 3; ++i) f[3 * c[a] + i] = std::numeric_limits<double>::quiet_NaN();
        continue;
      }
      add_pressure_stress(F, corner_pressure(p, t), P);
      for (int a = 0; a < 4; ++a) {
        if (c[a] >= m_.owned) continue;
        const double* g = geo.g[a];
        for (int i = 0; i < 3; ++i)
          f[3 * c[a] + i] -= geo.volume * (P[3 * i] * g[0] + P[3 * i + 1] * g[1] + P[3 * i + 2] * g[2]);
      }
    }
  }

  double potential_energy(const double* x) const override {
    double e = 0;
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      if (!owns_energy_[t]) continue;
      const Material& mat = materials_[material_[t]];
      double F[9];
      gradient(x, t, F);
      e += geometry_[t].volume * energy_density(F, mat.iso, mat.fibres.data(), static_cast<int>(mat.fibres.size()));
    }
    // The patches' volumetric energy, V_am U(Jbar_am), for the owned molecules (no communication).
    std::vector<double> jbar;
    patch_volume_ratios(x, jbar);
    for (std::size_t q = 0; q < jbar.size(); ++q) {
      if (patch_volume_[q] == 0) continue;
      const double J = jbar[q];
      if (!(J > 0)) return std::numeric_limits<double>::infinity();
      e += patch_volume_[q] * 0.25 * materials_[q % nmat_].moduli.kappa * (J * J - 1.0 - 2.0 * std::log(J));
    }
    return e;
  }

  PetscErrorCode add_tangent(const double* x, BlockAdd add, void* ctx) const override {
    update_pressure(x);  // collective, before anything may return
    const double* p = pressure_.array();
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      const int* c = &m_.tetrahedra[4 * t];
      double K[12][12];
      const double pbar = corner_pressure(p, t);
      if (!element_stiffness(t, x, &pbar, K)) return 0;  // inverted: the residual is NaN already
      for (int a = 0; a < 4; ++a) {
        if (c[a] >= m_.owned) continue;
        for (int b = 0; b < 4; ++b) {
          double B[9];
          for (int i = 0; i < 3; ++i)
            for (int k = 0; k < 3; ++k) B[3 * i + k] = K[3 * a + i][3 * b + k];
          const PetscErrorCode ierr = add(ctx, c[a], c[b], B);
          if (ierr) return ierr;
        }
      }
    }
    // The patches' rank-one blocks U''(Jbar) / V_am g_b g_c^T, b and c over the star (rows of ghosts included).
    std::vector<int> nodes;
    std::vector<double> g;
    for (int a = 0; a < m_.owned; ++a)
      for (int m = 0; m < nmat_; ++m) {
        const std::size_t q = static_cast<std::size_t>(nmat_) * a + m;
        if (patch_volume_[q] == 0) continue;
        if (!patch_gradient(x, a, m, nodes, g)) return 0;
        const double J = jbar_[q];
        const double w = 0.5 * materials_[m].moduli.kappa * (1.0 + 1.0 / (J * J)) / patch_volume_[q];
        for (std::size_t b = 0; b < nodes.size(); ++b)
          for (std::size_t d = 0; d < nodes.size(); ++d) {
            double B[9];
            for (int i = 0; i < 3; ++i)
              for (int k = 0; k < 3; ++k) B[3 * i + k] = w * g[3 * b + i] * g[3 * d + k];
            const PetscErrorCode ierr = add(ctx, nodes[b], nodes[d], B);
            if (ierr) return ierr;
          }
      }
    return 0;
  }

  bool tangent_has_ghost_rows() const override { return true; }

  void add_couplings(std::vector<std::vector<int>>& extra) const override {
    // A tetrahedron's corners are connection neighbours already; listed for a pattern that never depends on it.
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      const int* c = &m_.tetrahedra[4 * t];
      for (int a = 0; a < 4; ++a)
        if (c[a] < m_.owned)
          for (int b = 0; b < 4; ++b) extra[c[a]].push_back(c[b]);
    }
    // The patches' stars: every owned pair of a star (the star of an owned molecule is local).
    std::vector<int> nodes;
    for (int a = 0; a < m_.owned; ++a) {
      star_nodes(a, nodes);
      for (int b : nodes)
        if (b < m_.owned) extra[b].insert(extra[b].end(), nodes.begin(), nodes.end());
    }
  }

  void add_remote_couplings(std::vector<std::int64_t>& pairs) const override {
    // Rows of ghosts in an owned molecule's star: their owners need the star's columns.
    std::vector<int> nodes;
    for (int a = 0; a < m_.owned; ++a) {
      star_nodes(a, nodes);
      for (int b : nodes)
        if (b >= m_.owned)
          for (int d : nodes) pairs.push_back(m_.block[b]), pairs.push_back(m_.block[d]);
    }
  }

  double critical_time_step() const override { return dt_; }

  void add_force_scale(const double* x, std::vector<double>& scale, std::vector<double>& squares) const override {
    // A corner's force at unit strain: V |g_a| times the tetrahedron's moduli; from positions, that times
    // R |g_a| / 2 (Term::add_force_scale).
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      const int* c = &m_.tetrahedra[4 * t];
      const Geometry& geo = geometry_[t];
      double R = 0;
      for (int a = 0; a < 4; ++a)
        for (int d = 0; d < 3; ++d) R = std::max(R, std::fabs(x[3 * c[a] + d]));
      for (int a = 0; a < 4; ++a) {
        const double* g = geo.g[a];
        const double norm = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        const double unit = geo.volume * materials_[material_[t]].force_modulus * norm, positions = unit * R * norm / 2;
        scale[c[a]] += unit, squares[c[a]] += positions * positions;
      }
    }
  }

  void cells(const double* x, CellField& out) const override {
    out.nodes = 4;
    out.global_count = global_count_;
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      if (!owns_energy_[t]) continue;
      const int* c = &m_.tetrahedra[4 * t];
      double F[9];
      gradient(x, t, F);
      out.id.push_back(m_.tetrahedron_id[t]);
      for (int a = 0; a < 4; ++a) out.corners.push_back(m_.id[c[a]]);
      out.volume_ratio.push_back(F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
                                 F[2] * (F[3] * F[7] - F[4] * F[6]));
      const Material& mat = materials_[material_[t]];
      double Fa[3];
      out.fibre_stretch.push_back(fibre_stretch(F, mat.fibres.data(), static_cast<int>(mat.fibres.size()), Fa));
    }
  }

  // Per molecule (the snapshots' /molecules/fibre_*): the mean over its tetrahedra with fibres, as the lattice
  // cell term averages its cells.
  bool fibre_field(const double* x, double* direction, double* stretch) const override {
    bool any = false;
    for (const Material& mat : materials_) any = any || !mat.fibres.empty();
    if (!any) return false;
    std::vector<int> count(m_.owned, 0);
    std::fill(direction, direction + 3 * m_.owned, 0.0);
    std::fill(stretch, stretch + m_.owned, 0.0);
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      const Material& mat = materials_[material_[t]];
      if (mat.fibres.empty()) continue;
      double F[9], Fa[3];
      gradient(x, t, F);
      const double l = fibre_stretch(F, mat.fibres.data(), static_cast<int>(mat.fibres.size()), Fa);
      const int* c = &m_.tetrahedra[4 * t];
      for (int a = 0; a < 4; ++a) {
        if (c[a] >= m_.owned || l <= 0) continue;
        for (int d = 0; d < 3; ++d) direction[3 * c[a] + d] += Fa[d] / l;
        stretch[c[a]] += l;
        ++count[c[a]];
      }
    }
    for (int i = 0; i < m_.owned; ++i) {
      if (count[i] == 0) continue;
      stretch[i] /= count[i];
      const double* d = direction + 3 * i;
      const double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      for (int j = 0; j < 3; ++j) direction[3 * i + j] /= n > 0 ? n : 1.0;
    }
    return true;
  }

private:
  struct Material {
    Moduli moduli;  // the whole law (the per-tetrahedron bound of the time step)
    Moduli iso;     // without the volumetric part (kappa = 0): what each tetrahedron carries
    std::vector<Fibre> fibres;
    double density = 0, force_modulus = 0;
  };
  struct Geometry {
    double volume = 0;
    double g[4][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  };

  // F = I + sum_a u_a (x) g_a, from displacements (positions far from the origin would cost digits of F - I).
  void gradient(const double* x, std::size_t t, double F[9]) const {
    const int* c = &m_.tetrahedra[4 * t];
    const Geometry& geo = geometry_[t];
    for (int q = 0; q < 9; ++q) F[q] = q % 4 == 0 ? 1.0 : 0.0;
    for (int a = 0; a < 4; ++a) {
      const double* xa = x + 3 * c[a];
      const double* Xa = m_.rest.data() + 3 * c[a];
      for (int i = 0; i < 3; ++i) {
        const double u = xa[i] - Xa[i];
        for (int j = 0; j < 3; ++j) F[3 * i + j] += u * geo.g[a][j];
      }
    }
  }

  // K[3a + i][3b + k] = -d f_a[i] / d x_b[k] = V sum_jl dP_ij/dF_kl g_a[j] g_b[l] at x (nullptr: at rest);
  // false when the tetrahedron is inverted. pbar: the isochoric law plus pbar cof F (the patches' pressure at
  // fixed pbar; their rank-one part is add_tangent's); nullptr: the whole law per tetrahedron (an upper bound of
  // the averaged stiffness, for the time step: (sum w v)(sum w v)^T / sum w <= sum w v v^T per patch).
  bool element_stiffness(std::size_t t, const double* x, const double* pbar, double K[12][12]) const {
    const Geometry& geo = geometry_[t];
    const Material& mat = materials_[material_[t]];
    double F[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    if (x) gradient(x, t, F);
    double D[9][9];  // D[kl][ij] = dP_ij / dF_kl
    for (int kl = 0; kl < 9; ++kl) {
      Dual Fd[9], Pd[9];
      for (int q = 0; q < 9; ++q) Fd[q] = Dual(F[q], q == kl ? 1.0 : 0.0);
      if (!stress(Fd, pbar ? mat.iso : mat.moduli, mat.fibres.data(), static_cast<int>(mat.fibres.size()), Pd))
        return false;
      if (pbar) add_pressure_stress(Fd, Dual(*pbar), Pd);
      for (int q = 0; q < 9; ++q) D[kl][q] = Pd[q].d;
    }
    double Dg[9][4][3];  // Dg[kl][a][i] = sum_j D[kl][ij] g_a[j]
    for (int kl = 0; kl < 9; ++kl)
      for (int a = 0; a < 4; ++a)
        for (int i = 0; i < 3; ++i)
          Dg[kl][a][i] = D[kl][3 * i] * geo.g[a][0] + D[kl][3 * i + 1] * geo.g[a][1] + D[kl][3 * i + 2] * geo.g[a][2];
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        for (int i = 0; i < 3; ++i)
          for (int k = 0; k < 3; ++k)
            K[3 * a + i][3 * b + k] = geo.volume * (Dg[3 * k][a][i] * geo.g[b][0] + Dg[3 * k + 1][a][i] * geo.g[b][1] +
                                                    Dg[3 * k + 2][a][i] * geo.g[b][2]);
    return true;
  }

  // Collective. A stable step from the averaged stiffness itself (the bounds above are those of the stiffer
  // per-tetrahedron volumetric part, valid but loose once it is averaged). K = K_iso + sum_patches K_a, so
  // lambda_max(M^-1 K) <= max_t lambda(M_t^-1 K_iso,t) + max_a lambda(M_a^-1 K_a), each element by element: a
  // tetrahedron's corners get rho V_t / 4 (as above), and patch (a, m) the share rho V_t / 16 of each of its
  // tetrahedra's corners (over a's four corners these shares sum to the molecule's mass), so K_a's only non-zero
  // eigenvalue is kappa / V_am sum_b |g_b|^2 / mu_b.
  double averaged_time_step() const {
    double iso = 0, vol = 0;
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      if (geometry_[t].volume <= 0) continue;
      const double zero = 0;
      double K[12][12];
      element_stiffness(t, nullptr, &zero, K);
      iso = std::max(iso, largest_eigenvalue_bound(K) / (0.25 * materials_[material_[t]].density * geometry_[t].volume));
    }
    std::vector<int> nodes;
    std::vector<double> g, share;
    for (int a = 0; a < m_.owned; ++a)
      for (int m = 0; m < nmat_; ++m) {
        const std::size_t q = static_cast<std::size_t>(nmat_) * a + m;
        if (patch_volume_[q] == 0) continue;
        patch_gradient(m_.rest.data(), a, m, nodes, g);
        share.assign(nodes.size(), 0.0);
        for (int s = star_start_[a]; s < star_start_[a + 1]; ++s) {
          const std::size_t t = star_tets_[s];
          if (material_[t] != m) continue;
          for (int k = 0; k < 4; ++k) {
            const auto at = std::lower_bound(nodes.begin(), nodes.end(), m_.tetrahedra[4 * t + k]) - nodes.begin();
            share[at] += materials_[m].density * geometry_[t].volume / 16.0;
          }
        }
        double sum = 0;
        for (std::size_t b = 0; b < nodes.size(); ++b)
          if (share[b] > 0) sum += (g[3 * b] * g[3 * b] + g[3 * b + 1] * g[3 * b + 1] + g[3 * b + 2] * g[3 * b + 2]) / share[b];
        vol = std::max(vol, materials_[m].moduli.kappa / patch_volume_[q] * sum);
      }
    double local[2] = {iso, vol}, global[2];
    MPI_Allreduce(local, global, 2, MPI_DOUBLE, MPI_MAX, m_.comm);
    const double rate = global[0] + global[1];
    return rate > 0 ? 2.0 / std::sqrt(rate) : 0.0;
  }

  // lambda_max of a symmetric positive semi-definite 12 x 12 K from above: trace(K^8)^(1/8) (within 6^(1/8) of
  // it when K has at most 6 non-zero eigenvalues).
  static double largest_eigenvalue_bound(double K[12][12]) {
    double largest = 0;  // K / largest: the eighth power stays in range
    for (int r = 0; r < 12; ++r)
      for (int q = 0; q < 12; ++q) largest = std::max(largest, std::abs(K[r][q]));
    if (largest == 0) return 0;
    double A[12][12], B[12][12];
    for (int r = 0; r < 12; ++r)
      for (int q = 0; q < 12; ++q) A[r][q] = K[r][q] / largest;
    auto square = [](const double X[12][12], double Y[12][12]) {
      for (int r = 0; r < 12; ++r)
        for (int q = 0; q < 12; ++q) {
          double s = 0;
          for (int k = 0; k < 12; ++k) s += X[r][k] * X[k][q];
          Y[r][q] = s;
        }
    };
    square(A, B);
    square(B, A);
    double frobenius = 0;
    for (int r = 0; r < 12; ++r)
      for (int q = 0; q < 12; ++q) frobenius += A[r][q] * A[r][q];
    return largest * std::pow(frobenius, 0.125);
  }

  static int material_count(const Scene& scene) {
    const std::vector<BodySpec> specs = scene.bodies.empty() ? std::vector<BodySpec>{scene.body} : scene.bodies;
    int n = 0;
    for (const BodySpec& spec : specs) n += 1 + static_cast<int>(spec.regions.size());
    return n;
  }

  // P += p cof F (the pressure's share, p dJ/dF).
  template <class T>
  static void add_pressure_stress(const T F[9], const T& p, T P[9]) {
    const T cof[9] = {F[4] * F[8] - F[5] * F[7], F[5] * F[6] - F[3] * F[8], F[3] * F[7] - F[4] * F[6],
                      F[2] * F[7] - F[1] * F[8], F[0] * F[8] - F[2] * F[6], F[1] * F[6] - F[0] * F[7],
                      F[1] * F[5] - F[2] * F[4], F[2] * F[3] - F[0] * F[5], F[0] * F[4] - F[1] * F[3]};
    for (int q = 0; q < 9; ++q) P[q] = P[q] + p * cof[q];
  }

  static double determinant(const double F[9]) {
    return F[0] * (F[4] * F[8] - F[5] * F[7]) - F[1] * (F[3] * F[8] - F[5] * F[6]) +
           F[2] * (F[3] * F[7] - F[4] * F[6]);
  }

  // pbar_t = (1/4) sum over t's corners of their patch pressure in t's material (corner order: the same on every rank).
  double corner_pressure(const double* p, std::size_t t) const {
    const int* c = &m_.tetrahedra[4 * t];
    const int m = material_[t];
    return 0.25 * (((p[nmat_ * c[0] + m] + p[nmat_ * c[1] + m]) + p[nmat_ * c[2] + m]) + p[nmat_ * c[3] + m]);
  }

  // Jbar_am of the owned patches (nmat values a molecule; patches without volume read 1), each summed over the
  // molecule's tetrahedra in increasing id.
  void patch_volume_ratios(const double* x, std::vector<double>& jbar) const {
    jbar.assign(patch_volume_.size(), 0.0);
    for (std::size_t t = 0; t < geometry_.size(); ++t) {
      const int* c = &m_.tetrahedra[4 * t];
      double F[9];
      gradient(x, t, F);
      const double w = 0.25 * geometry_[t].volume * determinant(F);
      for (int a = 0; a < 4; ++a)
        if (c[a] < m_.owned) jbar[static_cast<std::size_t>(nmat_) * c[a] + material_[t]] += w;
    }
    for (std::size_t q = 0; q < jbar.size(); ++q) jbar[q] = patch_volume_[q] > 0 ? jbar[q] / patch_volume_[q] : 1.0;
  }

  // Collective: p = U'(Jbar) of the owned patches and their ghost copies (pressure_), Jbar kept in jbar_.
  // Jbar <= 0 (infinite energy) gives NaN, so the forces of its star are NaN.
  void update_pressure(const double* x) const {
    patch_volume_ratios(x, jbar_);
    double* p = pressure_.array();
    for (std::size_t q = 0; q < jbar_.size(); ++q) {
      const double J = jbar_[q];
      p[q] = J > 0 ? 0.5 * materials_[q % nmat_].moduli.kappa * (J - 1.0 / J) : std::numeric_limits<double>::quiet_NaN();
    }
    pressure_.update_ghosts();
  }

  // The distinct molecules of owned molecule a's tetrahedra (local indices, ascending).
  void star_nodes(int a, std::vector<int>& nodes) const {
    nodes.clear();
    for (int s = star_start_[a]; s < star_start_[a + 1]; ++s)
      for (int k = 0; k < 4; ++k) nodes.push_back(m_.tetrahedra[4 * star_tets_[s] + k]);
    std::sort(nodes.begin(), nodes.end());
    nodes.erase(std::unique(nodes.begin(), nodes.end()), nodes.end());
  }

  // g = sum over a's tetrahedra of material m of (V_t / 4) dJ_t/dx at x, per molecule of the star (3 values each,
  // in `nodes` order); false when a tetrahedron is inverted.
  bool patch_gradient(const double* x, int a, int m, std::vector<int>& nodes, std::vector<double>& g) const {
    star_nodes(a, nodes);
    g.assign(3 * nodes.size(), 0.0);
    for (int s = star_start_[a]; s < star_start_[a + 1]; ++s) {
      const std::size_t t = star_tets_[s];
      if (material_[t] != m) continue;
      double F[9];
      gradient(x, t, F);
      if (!(determinant(F) > 0)) return false;
      const double cof[9] = {F[4] * F[8] - F[5] * F[7], F[5] * F[6] - F[3] * F[8], F[3] * F[7] - F[4] * F[6],
                             F[2] * F[7] - F[1] * F[8], F[0] * F[8] - F[2] * F[6], F[1] * F[6] - F[0] * F[7],
                             F[1] * F[5] - F[2] * F[4], F[2] * F[3] - F[0] * F[5], F[0] * F[4] - F[1] * F[3]};
      const Geometry& geo = geometry_[t];
      for (int k = 0; k < 4; ++k) {
        const int slot = static_cast<int>(std::lower_bound(nodes.begin(), nodes.end(), m_.tetrahedra[4 * t + k]) - nodes.begin());
        const double* gk = geo.g[k];
        for (int i = 0; i < 3; ++i)
          g[3 * slot + i] += 0.25 * geo.volume * (cof[3 * i] * gk[0] + cof[3 * i + 1] * gk[1] + cof[3 * i + 2] * gk[2]);
      }
    }
    return true;
  }

  const LocalModel& m_;
  std::vector<Material> materials_;  // per body: its own, then one per region
  std::vector<Geometry> geometry_;   // per held tetrahedron (model.tetrahedron_id order)
  std::vector<int> material_;  // per tetrahedron: its body's or region's, index into materials_
  std::vector<char> owns_energy_;
  long long global_count_ = 0;
  double dt_ = std::numeric_limits<double>::infinity();
  // The patches (one per owned molecule and material): tetrahedra of each owned molecule (CSR over owned
  // molecules, increasing id), V_am, and the last Jbar_am; the pressures p_am with their ghost copies.
  int nmat_ = 1;
  std::vector<int> star_start_, star_tets_;
  std::vector<double> patch_volume_;
  mutable std::vector<double> jbar_;
  mutable GhostedVector pressure_;
};

}  // namespace

std::unique_ptr<Term> make_tetrahedron_elasticity(const TermContext& c) {
  return std::make_unique<TetrahedronElasticity>(c.scene, c.model);
}

TISSUE_TERM(tetrahedron_elasticity, {"tetrahedron-elasticity", scene_has_tetrahedra, make_tetrahedron_elasticity,
                                     "homogenized on a mesh or random cloud: one continuum energy per tetrahedron, "
                                     "its volumetric part averaged per molecule against locking (E, nu and fibres "
                                     "exact for affine "
                                     "states; docs/poisson.md)",
                                     6, /*energy_never_grows=*/true, ContactReport::none,
                                     /*reads_velocity=*/false, /*energy_line_search=*/true});

}  // namespace tissue
