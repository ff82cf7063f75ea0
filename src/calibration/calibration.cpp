#include "src/calibration/calibration.hpp"

#include <memory>

#include "partition/local_model.hpp"

namespace tissue {

// One line per method. The functions live in their own files.
void calibrate_linear(const CalibrationContext&, std::vector<double>&);
void calibrate_divided(const CalibrationContext&, std::vector<double>&);
void calibrate_manual(const CalibrationContext&, std::vector<double>&);
void calibrate_tetrahedral(const CalibrationContext&, std::vector<double>&);
void calibrate_lloyd(const CalibrationContext&, std::vector<double>&);
void calibrate_angles(const CalibrationContext&, std::vector<double>&);
CalibrationRefresher angles_updater(const CalibrationContext&, std::vector<double>&);
void calibrate_statistical(const CalibrationContext&, std::vector<double>&);
void calibrate_homogenized(const CalibrationContext&, std::vector<double>&);
void calibrate_iterative(const CalibrationContext&, std::vector<double>&);

const std::vector<CalibrationStyle>& calibration_styles() {
  static const std::vector<CalibrationStyle> styles = {
      {"linear", calibrate_linear, "Eq. 4, k = E A / l0 with the volume each connection stands for"},
      {"divided", calibrate_divided, "the linear k divided by a constant C (calibration.divisor)"},
      {"manual", calibrate_manual, "k given per connection class (calibration.stiffness)"},
      {"tetrahedral", calibrate_tetrahedral, "Eq. 5 (Van Gelder): k = E sum vol(T_e) / |c|^2; tetrahedral topology"},
      {"lloyd", calibrate_lloyd, "Lloyd et al. 2007: k = sum (2 sqrt2 / 25) E l_equiv per tetrahedron"},
      {"angles", calibrate_angles, "Eq. 6-7: the linear k shared with the connections at angles, rest cosines"},
      {"angles-update", calibrate_angles, "Eq. 6-7 with cosines from the current positions, every iteration",
       angles_updater},
      {"statistical", calibrate_statistical, "the paper's statistical method: directions from connection counts"},
      {"homogenized", calibrate_homogenized, "per-cell springs exact for an isotropic E, nu = 1/4 (Cauchy-Born)"},
      {"iterative", calibrate_iterative, "C adjusted by measurement until Eq. 3 gives E (wraps the solver)"},
  };
  return styles;
}

const CalibrationStyle* find_calibration(const std::string& name) {
  for (const auto& s : calibration_styles())
    if (name == s.name) return &s;
  return nullptr;
}

std::vector<std::string> calibration_method_names() {
  std::vector<std::string> names;
  for (const auto& s : calibration_styles()) names.emplace_back(s.name);
  return names;
}

namespace {

// The part of `m` a body's calibration sees: every local molecule (same local indices, so positions given to a
// refresher need no mapping) but only the connections of body b (`which`: their indices in m), and the body's
// geometry as the shape's own (what single-body methods such as homogenized read).
LocalModel body_view(const LocalModel& m, int b, std::vector<int>& which) {
  LocalModel v;
  v.comm = m.comm, v.rank = m.rank, v.size = m.size;
  v.shape = m.shape;  // the geometry only: its global arrays are empty
  static_cast<BoxGeometry&>(v.shape) = m.shape.body(b);
  v.global_molecules = m.global_molecules, v.global_connections = m.global_connections;
  v.partition = m.partition;
  v.owned = m.owned, v.local = m.local, v.first_block = m.first_block;
  v.id = m.id, v.block = m.block, v.rest = m.rest, v.mass = m.mass, v.youngs_modulus = m.youngs_modulus;
  v.degree = m.degree, v.body = m.body, v.first_connection = m.first_connection;
  which.clear();
  std::vector<int> index_in_view(m.connections(), -1);
  for (int c = 0; c < m.connections(); ++c) {
    if (m.body[m.end_a[c]] != b) continue;  // connections never join two bodies: end a tells
    index_in_view[c] = static_cast<int>(which.size());
    which.push_back(c);
    v.end_a.push_back(m.end_a[c]), v.end_b.push_back(m.end_b[c]);
    if (!m.forward_rank.empty()) v.forward_rank.push_back(m.forward_rank[c]);
    v.connection_class.push_back(m.connection_class[c]);
    v.stiffness.push_back(m.stiffness[c]);
    if (m.length_type.empty())
      v.rest_length.push_back(m.rest_length[c]);
    else
      v.length_type.push_back(m.length_type[c]);
    if (!m.tetra_volume.empty()) v.tetra_volume.push_back(m.tetra_volume[c]);
    if (!m.tetra_lloyd_sum.empty()) v.tetra_lloyd_sum.push_back(m.tetra_lloyd_sum[c]);
  }
  // Only a body with tetrahedra has them: another body's view has none (the tetrahedral methods check this).
  if (v.shape.topology != "tetrahedral" && !v.shape.unstructured()) v.tetra_volume.clear(), v.tetra_lloyd_sum.clear();
  v.length_table = m.length_table;
  for (int c : m.written_here())
    if (index_in_view[c] >= 0) ++v.written_count;
  return v;
}

}  // namespace

bool stiffness_is_final(const Scene& scene, const CalibrationRefresher& refresh) {
  if (refresh || scene.calibration.method == "iterative") return false;
  for (const auto& c : scene.calibrations)
    if (c.method == "iterative") return false;
  return true;
}

CalibrationRefresher calibrate_scene(const Scene& scene, const LocalModel& model, std::vector<double>& stiffness) {
  const int nbodies = model.shape.bodies();
  if (nbodies <= 1 || scene.calibrations.size() <= 1) {  // one body: the method sees the whole model
    const CalibrationStyle* method = find_calibration(scene.calibration.method);
    method->compute(CalibrationContext{scene, model}, stiffness);
    if (!method->updater) return {};
    return method->updater(CalibrationContext{scene, model}, stiffness);
  }
  std::vector<CalibrationRefresher> refreshers;
  for (int b = 0; b < nbodies; ++b) {
    // What the body's method sees: its own connections, geometry and calibration. Kept alive by the refresher.
    struct View {
      Scene scene;
      LocalModel model;
      std::vector<int> which;  // view connection i is model connection which[i]
      std::vector<double> k;
    };
    auto view = std::make_shared<View>();
    view->scene = scene;
    view->scene.calibration = scene.calibrations[b];
    view->scene.body = scene.bodies[b];
    view->model = body_view(model, b, view->which);
    view->k.assign(view->which.size(), 0.0);
    const CalibrationStyle* method = find_calibration(view->scene.calibration.method);
    const CalibrationContext ctx{view->scene, view->model};
    method->compute(ctx, view->k);  // collective methods (angles) are called by every rank, body after body
    for (std::size_t i = 0; i < view->which.size(); ++i) stiffness[view->which[i]] = view->k[i];
    if (!method->updater) continue;
    CalibrationRefresher inner = method->updater(ctx, view->k);
    std::vector<double>* target = &stiffness;
    refreshers.push_back([view, inner, target](const double* x) {
      inner(x);
      for (std::size_t i = 0; i < view->which.size(); ++i) (*target)[view->which[i]] = view->k[i];
    });
  }
  if (refreshers.empty()) return {};
  if (refreshers.size() == 1) return refreshers[0];
  return [refreshers](const double* x) {
    for (const auto& r : refreshers) r(x);  // every rank in the same order: each is collective
  };
}

}  // namespace tissue
