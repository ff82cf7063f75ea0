// Calibration: a stiffness k (N/m) per connection, chosen so the body has the material's Young's modulus.
// One file per method (the paper's section 3.3 and beyond), each a function plus one registry line in
// calibration.cpp. A method sees only this rank's connections and their end molecules (ghosts included).
#pragma once
#include <string>
#include <vector>

#include "io/scene.hpp"

namespace tissue {

struct LocalModel;

struct CalibrationContext {
  const Scene& scene;
  const LocalModel& model;
};

// Sets model.stiffness[c] for every local connection c.
using CalibrationFunction = void (*)(const CalibrationContext&, std::vector<double>& stiffness);

struct CalibrationStyle {
  const char* name;
  CalibrationFunction compute;
  const char* description;
};

const std::vector<CalibrationStyle>& calibration_styles();
const CalibrationStyle* find_calibration(const std::string& name);
std::vector<std::string> calibration_method_names();

// Eq. 4 for one connection, k = E A / l0, with A and l0 the part of the body the connection stands for
// (see linear.cpp); the divided and iterative methods scale it.
double linear_stiffness(const LocalModel& model, int connection);

}  // namespace tissue
