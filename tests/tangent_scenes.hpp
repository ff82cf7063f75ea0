// The scenes that the tangent tests share (matrix_free_test, rest_tangent_test, lattice_galerkin_test,
// volume_smoother_test): a box with a roller face (z-) and a clamped face (x+), so a molecule has 0-3 free
// components; springs alone at unit spacing, the cell term at nu = 0.45 on 1 : 1.2 : 0.9 cells (its general path),
// and springs with a viscoelastic history (the tangent factor of a quasi-static step). Tests append bodies'
// variants with their own text.
#pragma once
#include <string>

namespace tissue::tangent_scenes {

inline const std::string fixes = R"(
[[fix]]
face = "z-"
mode = "roller"
[[fix]]
face = "x+"
mode = "clamped"
[solver]
kind = "static"
)";

inline const std::string springs = R"(
title = "tangent test: springs"
[body]
molecules = [10, 7, 12]
spacing = [1.0, 1.0, 1.0]
topology = "face-diagonals"
material = "custom"
youngs_modulus = 2.5
[calibration]
method = "manual"
stiffness = { edge = 1.0, face = 0.7 }
)" + fixes;

inline const std::string cells = R"(
title = "tangent test: cell term"
[body]
molecules = [9, 7, 11]
spacing = [1e-3, 1.2e-3, 0.9e-3]
topology = "face-diagonals"
youngs_modulus = 1e4
poisson_ratio = 0.45
[calibration]
method = "homogenized"
)" + fixes;

inline const std::string visco = R"(
title = "tangent test: viscoelastic"
[body]
molecules = [8, 7, 9]
spacing = [1.0, 1.0, 1.0]
topology = "face-diagonals"
material = "custom"
youngs_modulus = 2.5
[body.viscoelastic]
gamma = [0.8, 0.3]
tau = [0.5, 4.0]
[calibration]
method = "manual"
stiffness = { edge = 1.0, face = 0.7 }
)" + fixes;

}  // namespace tissue::tangent_scenes
