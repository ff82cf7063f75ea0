// Cyclic face loads: a [[load]] with `period = T` (s) applies F sin(2 pi t / T) at time t instead of F, so a
// dynamic run loads and unloads the body periodically (t from the run's start; T > 0; dynamic runs only, checked
// by the scene reader). Constant loads stay in the ForceModel; only cyclic ones live here.
#include <cmath>

#include "src/physics/term.hpp"

namespace tissue {

namespace {
class CyclicLoad final : public Term {
public:
  CyclicLoad(const Scene& scene, const LocalModel& m) : m_(m) {
    for (const auto& load : scene.loads) {
      if (!(load.period > 0)) continue;
      omega_.push_back(2.0 * M_PI / load.period);
      shares_.emplace_back(3 * m.owned, 0.0);
      add_face_load(load, m, shares_.back().data());
    }
  }
  void add_forces(const double*, const double*, double time, double* f) override {
    for (std::size_t l = 0; l < omega_.size(); ++l) {
      const double s = std::sin(omega_[l] * time);
      const double* F = shares_[l].data();
      for (int i = 0; i < 3 * m_.owned; ++i) f[i] += s * F[i];
    }
  }

private:
  const LocalModel& m_;
  std::vector<double> omega_;
  std::vector<std::vector<double>> shares_;
};
}  // namespace

std::unique_ptr<Term> make_cyclic_load(const TermContext& c) { return std::make_unique<CyclicLoad>(c.scene, c.model); }

namespace {
bool has_cyclic(const Scene& s) {
  for (const auto& l : s.loads)
    if (l.period > 0) return true;
  return false;
}
}  // namespace

TISSUE_TERM(cyclic_load, {"cyclic-load", has_cyclic, make_cyclic_load,
                          "[[load]] period = T: the face load scaled by sin(2 pi t / T) (dynamic runs)", 30});

}  // namespace tissue
