// Viscoelastic connections ([body.viscoelastic], a Prony series per body): every spring's elastic force
// f_e = k (l - l0) gets history forces h_i, one per Prony term, with the exact exponential update of
// ../shared/reference/material_laws.md ("Viscoelasticity"):
//   h_i <- exp(-dt/tau_i) h_i + gamma_i beta_i (f_e(n+1) - f_e(n)),  beta_i = (tau_i/dt)(1 - exp(-dt/tau_i)),
// exact when f_e varies linearly within a step and unconditionally stable. The force along the spring is
// f_e + sum_i h_i, so the relaxation modulus is E (1 + sum gamma_i exp(-t/tau_i)) with E the calibrated (relaxed)
// one; a step of dt = 0 gives the instantaneous response (beta = 1, no decay). The consistent tangent adds
// (sum gamma_i beta_i) times the spring's material stiffness and the geometric stiffness of the history force.
// Before the first begin_step (static, relaxation) the term adds nothing: those solves find the relaxed state.
// Between commit_step and the next begin_step the history is frozen (reactions and measurements of the end state
// see the committed forces).
// Storage (only in scenes that ask): per connection the committed f_e and one h per Prony term; with Prony
// series per [[body.region]], each connection's table too.
#include <algorithm>
#include <cmath>

#include "src/physics/term.hpp"

namespace tissue {

namespace {

class ViscoelasticSprings final : public Term {
public:
  ViscoelasticSprings(const Scene& scene, const LocalModel& m) : m_(m) {
    // The Prony tables: one per body, then one per region with its own ([[body.region]] viscoelastic).
    std::vector<const PronySpec*> tables;
    for (const auto& b : scene.bodies) tables.push_back(&b.viscoelastic);
    std::vector<std::vector<int>> region_table(scene.bodies.size());  // per body and region: its table or -1
    for (std::size_t b = 0; b < scene.bodies.size(); ++b)
      for (const auto& r : scene.bodies[b].regions) {
        region_table[b].push_back(r.viscoelastic.empty() ? -1 : static_cast<int>(tables.size()));
        if (!r.viscoelastic.empty()) tables.push_back(&r.viscoelastic);
      }
    for (const PronySpec* t : tables) width_ = std::max(width_, static_cast<int>(t->gamma.size()));
    const int nt = static_cast<int>(tables.size());
    gamma_.assign(nt * width_, 0.0), tau_.assign(nt * width_, 1.0);
    for (int t = 0; t < nt; ++t)
      for (std::size_t i = 0; i < tables[t]->gamma.size(); ++i)
        gamma_[t * width_ + i] = tables[t]->gamma[i], tau_[t * width_ + i] = tables[t]->tau[i];
    decay_.assign(gamma_.size(), 1.0), weight_.assign(gamma_.size(), 0.0), tangent_factor_.assign(nt, 0.0);
    // Each connection's table, stored (2 bytes a connection) only when some region has its own: the region
    // whose box (the body's frame) holds the connection's rest midpoint, the last such one.
    if (nt > static_cast<int>(scene.bodies.size())) {
      table_.resize(m.connections());
      for (int c = 0; c < m.connections(); ++c) {
        const int b = m.body[m.end_a[c]];
        const BodySpec& body = scene.bodies[b];
        int t = b;
        for (std::size_t r = 0; r < body.regions.size(); ++r) {
          if (region_table[b][r] < 0) continue;
          bool inside = true;
          for (int d = 0; d < 3; ++d) {
            const double mid = 0.5 * (m.rest[3 * m.end_a[c] + d] + m.rest[3 * m.end_b[c] + d]) - body.offset[d];
            inside = inside && mid >= body.regions[r].lo[d] && mid <= body.regions[r].hi[d];
          }
          if (inside) t = region_table[b][r];
        }
        table_[c] = static_cast<std::uint16_t>(t);
      }
    }
    fe_.assign(m.connections(), 0.0);
    h_.assign(static_cast<std::size_t>(m.connections()) * width_, 0.0);
  }

  bool has_history() const override { return true; }

  void begin_step(double dt) override {
    active_ = stepping_ = true;
    const int nb = static_cast<int>(tangent_factor_.size());
    for (int b = 0; b < nb; ++b) {
      tangent_factor_[b] = 0.0;
      for (int i = 0; i < width_; ++i) {
        const int j = b * width_ + i;
        const double r = dt / tau_[j];
        decay_[j] = std::exp(-r);
        // beta = (1 - exp(-r)) / r, by expm1 for small r (beta -> 1 as dt -> 0, the instantaneous step).
        const double beta = r > 0 ? -std::expm1(-r) / r : 1.0;
        weight_[j] = gamma_[j] * beta;
        tangent_factor_[b] += weight_[j];
      }
    }
  }

  void add_forces(const double* x, const double*, double, double* f) override {
    if (!active_) return;
    const int n = m_.connections();
    for (int c = 0; c < n; ++c) {  // ascending c is the global order: each molecule's sum is rank-independent
      double d[3], len;
      const double H = trial(x, c, d, len) / len;
      const int a = m_.end_a[c], b = m_.end_b[c];
      if (a < m_.owned)
        for (int r = 0; r < 3; ++r) f[3 * a + r] += H * d[r];
      if (b < m_.owned)
        for (int r = 0; r < 3; ++r) f[3 * b + r] -= H * d[r];
    }
  }

  void commit_step(const double* x) override {
    if (!active_) return;
    const int n = m_.connections();
    for (int c = 0; c < n; ++c) {
      double d[3], len;
      const double fe = m_.k(c) * (length(x, c, d, len) - m_.l0(c));
      const double* g = weight_.data() + table(c) * width_;
      const double* e = decay_.data() + table(c) * width_;
      double* h = h_.data() + static_cast<std::size_t>(c) * width_;
      for (int i = 0; i < width_; ++i) h[i] = e[i] * h[i] + g[i] * (fe - fe_[c]);
      fe_[c] = fe;
    }
    stepping_ = false;
  }

  // Per connection: the committed elastic force, then its history forces.
  int history_width() const override { return 1 + width_; }
  void save_history(double* rows) const override {
    const int n = m_.connections(), w = 1 + width_;
    for (int c = 0; c < n; ++c) {
      rows[w * c] = fe_[c];
      std::copy(h_.begin() + static_cast<std::size_t>(c) * width_, h_.begin() + static_cast<std::size_t>(c + 1) * width_,
                rows + w * c + 1);
    }
  }
  void load_history(const double* rows) override {
    const int n = m_.connections(), w = 1 + width_;
    for (int c = 0; c < n; ++c) {
      fe_[c] = rows[w * c];
      std::copy(rows + w * c + 1, rows + w * (c + 1), h_.begin() + static_cast<std::size_t>(c) * width_);
    }
    // Committed and frozen, as the run that wrote them left them between two steps (a zero history adds zero).
    active_ = true, stepping_ = false;
  }

  void add_stiffness_bound(std::vector<double>& ksum) const override {
    // The explicit step follows the instantaneous modulus, E (1 + sum gamma).
    const int n = m_.connections();
    for (int c = 0; c < n; ++c) {
      const double* g = gamma_.data() + table(c) * width_;
      double sum = 0;
      for (int i = 0; i < width_; ++i) sum += g[i];
      ksum[m_.end_a[c]] += m_.k(c) * sum, ksum[m_.end_b[c]] += m_.k(c) * sum;
    }
  }

  PetscErrorCode add_tangent(const double* x, BlockAdd add, void* ctx) const override {
    PetscFunctionBeginUser;
    if (!active_) PetscFunctionReturn(0);
    const int n = m_.connections();
    for (int c = 0; c < n; ++c) {
      double d[3], len;
      const double H = trial(x, c, d, len);
      const double kv = stepping_ ? tangent_factor_[table(c)] * m_.k(c) : 0.0, geo = H / len;
      // d(H n)/dx_b = kv n n^T + (H / l)(I - n n^T): the history's material part and its geometric part.
      double K[9];
      for (int r = 0; r < 3; ++r)
        for (int s = 0; s < 3; ++s) {
          const double nn = d[r] * d[s] / (len * len);
          K[3 * r + s] = kv * nn + geo * ((r == s ? 1.0 : 0.0) - nn);
        }
      double minus[9];
      for (int q = 0; q < 9; ++q) minus[q] = -K[q];
      const int a = m_.end_a[c], b = m_.end_b[c];
      if (a < m_.owned) {
        PetscCall(add(ctx, a, a, K));
        PetscCall(add(ctx, a, b, minus));
      }
      if (b < m_.owned) {
        PetscCall(add(ctx, b, b, K));
        PetscCall(add(ctx, b, a, minus));
      }
    }
    PetscFunctionReturn(0);
  }

private:
  double length(const double* x, int c, double d[3], double& len) const {
    const double* xa = x + 3 * m_.end_a[c];
    const double* xb = x + 3 * m_.end_b[c];
    d[0] = xb[0] - xa[0], d[1] = xb[1] - xa[1], d[2] = xb[2] - xa[2];
    len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    return len;
  }
  // The summed history force of connection c at x within the current step (not committed).
  double trial(const double* x, int c, double d[3], double& len) const {
    const double fe = m_.k(c) * (length(x, c, d, len) - m_.l0(c));
    const double* g = weight_.data() + table(c) * width_;
    const double* e = decay_.data() + table(c) * width_;
    const double* h = h_.data() + static_cast<std::size_t>(c) * width_;
    double H = 0;
    if (stepping_)
      for (int i = 0; i < width_; ++i) H += e[i] * h[i] + g[i] * (fe - fe_[c]);
    else
      for (int i = 0; i < width_; ++i) H += h[i];  // committed: frozen until the next step begins
    return H;
  }

  // Connection c's Prony table: its region's, else its body's.
  int table(int c) const { return table_.empty() ? m_.body[m_.end_a[c]] : table_[c]; }

  const LocalModel& m_;
  std::vector<std::uint16_t> table_;       // per connection, when some region has its own table
  int width_ = 0;                          // Prony terms (the most of any body; absent ones have gamma 0)
  std::vector<double> gamma_, tau_;        // per table (bodies, then regions with their own) and term
  std::vector<double> decay_, weight_;     // per table and term: exp(-dt/tau), gamma beta of the current step
  std::vector<double> tangent_factor_;     // per table: sum gamma beta
  std::vector<double> fe_, h_;             // per connection: committed elastic force, history per term
  bool active_ = false;    // a step has begun once: the history acts
  bool stepping_ = false;  // within a step (begin_step .. commit_step): the history follows x; else frozen
};

bool listed(const Scene& s) {
  for (const auto& b : s.bodies) {
    if (!b.viscoelastic.empty()) return true;
    for (const auto& r : b.regions)
      if (!r.viscoelastic.empty()) return true;
  }
  return false;
}

std::unique_ptr<Term> make_viscoelastic(const TermContext& c) {
  return std::make_unique<ViscoelasticSprings>(c.scene, c.model);
}

}  // namespace

TISSUE_TERM(viscoelastic, {"viscoelastic", listed, make_viscoelastic,
                           "[body.viscoelastic] gamma, tau: Prony-series history forces on every connection", 5,
                           /*energy_never_grows=*/true});

}  // namespace tissue
