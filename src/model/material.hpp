// Tissue presets: linear-region Young's modulus and density of joint and soft tissues, with their sources
// (../shared/reference/tissues.md). A scene names one with `material = "cartilage"`; youngs_modulus or density
// given in the scene override the preset's value.
#pragma once
#include <string>
#include <vector>

namespace tissue {

struct TissuePreset {
  std::string name;
  double youngs_modulus;  // Pa, a representative value inside the range
  double density;         // kg/m^3
  std::string range;      // the literature range, in words
  std::string source;
  double poisson_ratio;             // drained / linear-region nu, representative
  std::string poisson_range;        // its literature range, in words
  std::string poisson_source;
  // Fibres (docs/anisotropy.md), used only when the scene gives [body.fibres] (0: none): the body's E is then
  // transverse_modulus (E_T) unless given, and the fibres' E_L = youngs_modulus, nu_LT, G_L unless given.
  double transverse_modulus = 0;
  double fibre_poisson_ratio = 0;   // nu_LT
  double fibre_shear_modulus = 0;   // G_L
  std::string fibre_source;
};

const std::vector<TissuePreset>& tissue_presets();
// nullptr when the name is unknown ("custom" is not a preset: the scene gives E and density itself).
const TissuePreset* find_tissue(const std::string& name);

}  // namespace tissue
