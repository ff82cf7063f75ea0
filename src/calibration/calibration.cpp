#include "src/calibration/calibration.hpp"

namespace tissue {

// One line per method. The functions live in their own files.
void calibrate_linear(const CalibrationContext&, std::vector<double>&);
void calibrate_divided(const CalibrationContext&, std::vector<double>&);
void calibrate_manual(const CalibrationContext&, std::vector<double>&);

const std::vector<CalibrationStyle>& calibration_styles() {
  static const std::vector<CalibrationStyle> styles = {
      {"linear", calibrate_linear, "Eq. 4, k = E A / l0 with the volume each connection stands for"},
      {"divided", calibrate_divided, "the linear k divided by a constant C (calibration.divisor)"},
      {"manual", calibrate_manual, "k given per connection class (calibration.stiffness)"},
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
