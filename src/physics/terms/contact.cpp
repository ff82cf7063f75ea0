// Molecule-molecule contact ([physics] contact = true): molecules are spheres (their body's `radius`, default
// half the smallest spacing); two molecules of different bodies, or of one body but not joined by a connection,
// that overlap by delta = r_i + r_j - |x_j - x_i| > 0 push each other apart with the penalty force k delta along
// the line of centres. At rest no pair of a box lattice overlaps (axis neighbours are always connected, and every
// other pair is at least sqrt(h_a^2 + h_b^2) > 2 r apart).
//
// Penalty stiffness k: [physics] contact_stiffness when given, else the two bodies' support stiffnesses
// (obstacles.cpp: the mean summed connection stiffness of a body's molecules) in series, k_a k_b / (k_a + k_b).
//
// Finding pairs: a Verlet list per owned molecule of every molecule within reach = 2 r_max + skin (skin:
// [physics] contact_skin, default half the smallest radius), built with a cell list of cell size `reach` over the
// owned molecules and the contact halo (partition/contact_halo: the other ranks' molecules within reach, ghosts by
// distance). The list is rebuilt when some molecule has moved more than skin / 2 since the last build (one
// MPI_Allreduce per evaluation), and sorted by original id, so each molecule sums its contact forces in the same
// order whatever the partition: results do not depend on the rank count. Each pair is computed on both sides.
//
// Tangent (static solver): the diagonal blocks k n n^T of each active pair; the off-diagonal -k n n^T are left
// out (their pattern changes with the contacts; the matrix is preallocated for the connections only), so Newton
// converges linearly rather than quadratically when molecules of the bodies touch. Relaxation and dynamic runs
// need no tangent and support contact fully.
#include <algorithm>
#include <cmath>
#include <numeric>

#include "partition/contact_halo.hpp"
#include "src/physics/term.hpp"

namespace tissue {

namespace {
class Contact final : public Term {
public:
  Contact(const Scene& scene, const LocalModel& m) : m_(m), halo_(m, 0.0) {
    const int nb = m.shape.bodies();
    radius_.resize(nb);
    double rmax = 0, rmin = 1e300;
    for (int b = 0; b < nb; ++b) {
      radius_[b] = m.shape.body(b).radius;
      rmax = std::max(rmax, radius_[b]), rmin = std::min(rmin, radius_[b]);
    }
    skin_ = scene.physics.contact_skin > 0 ? scene.physics.contact_skin : 0.5 * rmin;
    reach_ = 2 * rmax + skin_;
    halo_.set_reach(reach_);
    const std::vector<double> support = body_support_stiffness(m);
    k_.assign(nb * nb, scene.physics.contact_stiffness);
    if (!(scene.physics.contact_stiffness > 0))
      for (int a = 0; a < nb; ++a)
        for (int b = 0; b < nb; ++b) {
          const double s = support[a] + support[b];
          k_[a * nb + b] = s > 0 ? support[a] * support[b] / s : 0.0;
        }
    kmax_ = *std::max_element(k_.begin(), k_.end());
    // Connection neighbours of each owned molecule (original ids, sorted): excluded from contact.
    first_.assign(m.owned + 1, 0);
    for (int c = 0; c < m.connections(); ++c) {
      if (m.end_a[c] < m.owned) ++first_[m.end_a[c] + 1];
      if (m.end_b[c] < m.owned) ++first_[m.end_b[c] + 1];
    }
    for (int i = 0; i < m.owned; ++i) first_[i + 1] += first_[i];
    joined_.resize(first_[m.owned]);
    std::vector<int> fill(first_.begin(), first_.end() - 1);
    for (int c = 0; c < m.connections(); ++c) {
      const int a = m.end_a[c], b = m.end_b[c];
      if (a < m.owned) joined_[fill[a]++] = m.id[b];
      if (b < m.owned) joined_[fill[b]++] = m.id[a];
    }
    for (int i = 0; i < m.owned; ++i) std::sort(joined_.begin() + first_[i], joined_.begin() + first_[i + 1]);
  }

  void add_forces(const double* x, const double*, double, double* f) override {
    refresh(x);
    const int nb = m_.shape.bodies();
    bodies_.assign(3 * nb, 0.0), self_.assign(3 * nb, 0.0);
    for (int i = 0; i < m_.owned; ++i) {
      const int bi = m_.body[i];
      for (int p = list_first_[i]; p < list_first_[i + 1]; ++p) {
        double n[3], depth;
        const int j = list_[p];
        const int bj = body_of(j);
        if (!overlap(x, i, j, bi, bj, n, depth)) continue;
        const double s = k_[bi * nb + bj] * depth;  // pushes i away from j (n points from i to j)
        for (int d = 0; d < 3; ++d) {
          f[3 * i + d] -= s * n[d];
          (bj != bi ? bodies_ : self_)[3 * bi + d] -= s * n[d];
        }
      }
    }
  }
  double potential_energy(const double* x) const override {
    double e = 0;
    const int nb = m_.shape.bodies();
    if (list_first_.empty()) return 0.0;
    for (int i = 0; i < m_.owned; ++i)
      for (int p = list_first_[i]; p < list_first_[i + 1]; ++p) {
        double n[3], depth;
        const int j = list_[p], bj = body_of(j);
        if (overlap(x, i, j, m_.body[i], bj, n, depth)) e += 0.25 * k_[m_.body[i] * nb + bj] * depth * depth;
      }
    return e;  // each pair is visited from both of its molecules
  }
  void add_stiffness_bound(std::vector<double>& ksum) const override {
    // Gershgorin: 2 k per touching pair; a molecule pressed into another lattice touches about 4 at once.
    for (int i = 0; i < m_.owned; ++i) ksum[i] += 4.0 * kmax_;
  }
  PetscErrorCode add_tangent(const double* x, BlockAdd add, void* ctx) const override {
    const int nb = m_.shape.bodies();
    if (list_first_.empty()) return 0;
    for (int i = 0; i < m_.owned; ++i) {
      double K[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
      bool any = false;
      for (int p = list_first_[i]; p < list_first_[i + 1]; ++p) {
        double n[3], depth;
        const int j = list_[p], bj = body_of(j);
        if (!overlap(x, i, j, m_.body[i], bj, n, depth)) continue;
        const double k = k_[m_.body[i] * nb + bj];
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) K[3 * r + c] += k * n[r] * n[c];
        any = true;
      }
      if (any) {
        PetscErrorCode ierr = add(ctx, i, i, K);
        if (ierr) return ierr;
      }
    }
    return 0;
  }
  void add_totals(ContactTotals& t) const override {
    for (std::size_t d = 0; d < bodies_.size(); ++d) t.bodies[d] += bodies_[d], t.bodies_self[d] += self_[d];
  }

private:
  // Partner j: an owned molecule (j < owned) or halo molecule j - owned.
  int body_of(int j) const { return j < m_.owned ? m_.body[j] : halo_.body()[j - m_.owned]; }
  const double* position(const double* x, int j) const {
    return j < m_.owned ? x + 3 * j : halo_.positions() + 3 * (j - m_.owned);
  }
  bool overlap(const double* x, int i, int j, int bi, int bj, double n[3], double& depth) const {
    const double* a = x + 3 * i;
    const double* b = position(x, j);
    const double e[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const double d2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2], reach = radius_[bi] + radius_[bj];
    if (!(d2 < reach * reach) || d2 == 0.0) return false;
    const double d = std::sqrt(d2);
    depth = reach - d;
    for (int c = 0; c < 3; ++c) n[c] = e[c] / d;
    return true;
  }

  // Collective: the halo's positions, rebuilding the halo and the Verlet lists when needed.
  void refresh(const double* x) {
    double moved = list_first_.empty() ? 1e300 : 0.0;
    if (!list_first_.empty())
      for (int i = 0; i < 3 * m_.owned; i += 3) {
        const double e[3] = {x[i] - built_[i], x[i + 1] - built_[i + 1], x[i + 2] - built_[i + 2]};
        moved = std::max(moved, e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
      }
    double worst = 0;
    MPI_Allreduce(&moved, &worst, 1, MPI_DOUBLE, MPI_MAX, m_.comm);
    if (worst <= 0.25 * skin_ * skin_) {
      halo_.update(x);
      return;
    }
    halo_.rebuild(x);
    built_.assign(x, x + 3 * m_.owned);
    build_lists(x);
  }

  void build_lists(const double* x) {
    const int n = m_.owned + halo_.size();
    double lo[3] = {1e300, 1e300, 1e300};
    for (int j = 0; j < n; ++j)
      for (int d = 0; d < 3; ++d) lo[d] = std::min(lo[d], position(x, j)[d]);
    auto cell = [&](const double* p, int d) { return static_cast<long>(std::floor((p[d] - lo[d]) / reach_)); };
    auto key = [](long i, long j, long k) { return (i * 1000003L + j) * 1000033L + k; };
    std::vector<std::pair<long, int>> cells(n);
    for (int j = 0; j < n; ++j) {
      const double* p = position(x, j);
      cells[j] = {key(cell(p, 0), cell(p, 1), cell(p, 2)), j};
    }
    std::sort(cells.begin(), cells.end());
    list_first_.assign(m_.owned + 1, 0);
    list_.clear();
    std::vector<std::pair<std::int64_t, int>> mine;
    for (int i = 0; i < m_.owned; ++i) {
      mine.clear();
      const double* a = x + 3 * i;
      const long ci = cell(a, 0), cj = cell(a, 1), ck = cell(a, 2);
      for (long di = -1; di <= 1; ++di)
        for (long dj = -1; dj <= 1; ++dj)
          for (long dk = -1; dk <= 1; ++dk) {
            const long kk = key(ci + di, cj + dj, ck + dk);
            auto it = std::lower_bound(cells.begin(), cells.end(), std::make_pair(kk, -1));
            for (; it != cells.end() && it->first == kk; ++it) {
              const int j = it->second;
              if (j == i) continue;
              const double* b = position(x, j);
              const double e[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
              if (e[0] * e[0] + e[1] * e[1] + e[2] * e[2] > reach_ * reach_) continue;
              const std::int64_t g = j < m_.owned ? m_.id[j] : halo_.id()[j - m_.owned];
              if (std::binary_search(joined_.begin() + first_[i], joined_.begin() + first_[i + 1], g)) continue;
              mine.push_back({g, j});
            }
          }
      std::sort(mine.begin(), mine.end());  // original-id order: the same sums on every partition
      for (const auto& p : mine) list_.push_back(p.second);
      list_first_[i + 1] = static_cast<int>(list_.size());
    }
  }

  const LocalModel& m_;
  ContactHalo halo_;
  std::vector<double> radius_, k_;
  double skin_ = 0, reach_ = 0, kmax_ = 0;
  std::vector<int> first_;
  std::vector<std::int64_t> joined_;
  std::vector<int> list_first_, list_;
  std::vector<double> built_;
  std::vector<double> bodies_, self_;
};
}  // namespace

std::unique_ptr<Term> make_contact(const TermContext& c) { return std::make_unique<Contact>(c.scene, c.model); }

TISSUE_TERM(contact, {"contact", [](const Scene& s) { return s.physics.contact; }, make_contact,
                      "[physics] contact = true: molecule-molecule contact between bodies and non-neighbours of one "
                      "body", 50, false, ContactReport::molecules});

}  // namespace tissue
