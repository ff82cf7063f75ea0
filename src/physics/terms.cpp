// The registry of physics terms: one line each, in the order they add their forces. The connection forces are
// not a term here: they are the ForceModel's own kernel, always present and kept free of indirection.
#include <mpi.h>

#include "src/physics/term.hpp"

namespace tissue {

std::unique_ptr<Term> make_gravity(const TermContext&);
std::unique_ptr<Term> make_viscosity(const TermContext&);
std::unique_ptr<Term> make_cyclic_load(const TermContext&);
std::unique_ptr<Term> make_obstacles(const TermContext&);
std::unique_ptr<Term> make_contact(const TermContext&);

namespace {
bool has_cyclic(const Scene& s) {
  for (const auto& l : s.loads)
    if (l.period > 0) return true;
  return false;
}
}  // namespace

const std::vector<TermStyle>& term_styles() {
  static const std::vector<TermStyle> styles = {
      {"gravity", [](const Scene& s) { return s.physics.gravity.has_value(); }, make_gravity,
       "[physics] gravity = [gx, gy, gz]: m g on every molecule"},
      {"viscosity", [](const Scene& s) { return s.physics.viscosity.has_value() && *s.physics.viscosity > 0; },
       make_viscosity, "[physics] viscosity = c: ambient viscous friction -c v on every molecule"},
      {"cyclic-load", has_cyclic, make_cyclic_load,
       "[[load]] period = T: the face load scaled by sin(2 pi t / T) (dynamic runs)"},
      {"obstacles", [](const Scene& s) { return !s.obstacles.empty(); }, make_obstacles,
       "[[obstacle]]: rigid planes and spheres pushing molecules (spheres) out by a penalty force"},
      {"contact", [](const Scene& s) { return s.physics.contact; }, make_contact,
       "[physics] contact = true: molecule-molecule contact between bodies and non-neighbours of one body"},
  };
  return styles;
}

std::vector<double> body_support_stiffness(const LocalModel& m) {
  const int nb = m.shape.bodies();
  std::vector<double> local(2 * nb, 0.0), global(2 * nb, 0.0);
  for (int c : m.written_here()) local[m.body[m.end_a[c]]] += 2.0 * m.k(c);
  for (int i = 0; i < m.owned; ++i) local[nb + m.body[i]] += 1.0;
  MPI_Allreduce(local.data(), global.data(), 2 * nb, MPI_DOUBLE, MPI_SUM, m.comm);
  std::vector<double> k(nb);
  for (int b = 0; b < nb; ++b) k[b] = global[nb + b] > 0 ? global[b] / global[nb + b] : 0.0;
  return k;
}

}  // namespace tissue
