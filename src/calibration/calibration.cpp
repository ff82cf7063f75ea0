#include "src/calibration/calibration.hpp"

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

}  // namespace tissue
