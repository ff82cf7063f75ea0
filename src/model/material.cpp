#include "src/model/material.hpp"

namespace tissue {

const std::vector<TissuePreset>& tissue_presets() {
  // Representative values sit inside the ranges of ../shared/reference/tissues.md; a study should set its own.
  // Poisson ratios: drained (equilibrium) values for cartilage, near-incompressible values for the soft tissues,
  // whose water stays in over a test (docs/poisson.md, "Presets").
  static const std::vector<TissuePreset> presets = {
      {"cartilage", 10.0e6, 1100.0, "0.7-15.3 MPa (tension higher, indentation lower)",
       "Materials Today Bio 31:101617 (2025) Table 1; PMC2854000", 0.185, "0.1-0.4 drained (0.185 +- 0.065 bovine)",
       "Jurvelin, Buschmann, Hunziker 1997, J Biomech 30:235", 0.0, 0.0, 0.0, ""},
      {"ligament", 400.0e6, 1130.0, "184-516 MPa (human MCL 327-442, LCL 184-494, rabbit ACL 516)",
       "PMC8792233; Woo 1992, J Biomech 25:377", 0.45, "0.4-0.5 (nearly incompressible)",
       "Weiss, Maker, Govindjee 1996, CMAME 135:107", 11.0e6, 0.45, 1.4e6,
       "E_T 11.0 +- 3.6 MPa (human MCL, Quapp & Weiss 1998, J Biomech Eng 120:757); G_L 1.4 MPa (human MCL shear, "
       "Weiss, Gardiner, Bonifasi-Lista 2002, J Biomech 35:943); nu_LT = nu_TT = 0.45 assumed"},
      {"tendon", 600.0e6, 1130.0, "500-660 MPa (range 143-2310 MPa)", "Ann Biomed Eng 43:641 (2015) Table 1", 0.45,
       "0.4-0.5 (nearly incompressible)", "Weiss, Maker, Govindjee 1996, CMAME 135:107", 20.0e6, 0.45, 1.4e6,
       "E_T and G_L: the ligament's ratios E_T / E_L = 11 / 332 and G_L (assumed; transverse tendon data are sparse, "
       "Lynch et al. 2003, J Biomech Eng 125:726); nu_LT = nu_TT = 0.45 assumed"},
      {"cortical-bone", 17.0e9, 2000.0, "10-20 GPa (range 3-30 GPa)",
       "Zysset 1999 J Biomech 32:1005; Mech Mater 44:174 (2012)", 0.3, "0.2-0.4",
       "Reilly, Burstein 1975, J Biomech 8:393", 0.0, 0.0, 0.0, ""},
      {"cancellous-bone", 500.0e6, 1000.0, "50-5000 MPa apparent", "Materials Today Bio 31:101617 (2025)", 0.3,
       "0.2-0.4 apparent", "Keaveny et al. 2001, Annu Rev Biomed Eng 3:307", 0.0, 0.0, 0.0, ""},
      {"skin", 1.5e6, 1100.0, "1-2 MPa (indentation)", "Ann Biomed Eng 43:641 (2015)", 0.48, "0.45-0.49",
       "Ann Biomed Eng 43:641 (2015)", 0.0, 0.0, 0.0, ""},
      {"muscle", 50.0e3, 1050.0, "25-100 kPa passive (indentation)", "Ann Biomed Eng 43:641 (2015)", 0.49,
       "0.45-0.499 (nearly incompressible)", "Ann Biomed Eng 43:641 (2015)", 0.0, 0.0, 0.0, ""},
      {"liver", 5.0e3, 1060.0, "about 5 kPa (3 x shear 1.8 kPa)", "PMC6925591", 0.49,
       "0.45-0.499 (nearly incompressible; E = 3 G)", "PMC6925591", 0.0, 0.0, 0.0, ""},
      {"brain", 3.0e3, 1040.0, "1-6 kPa", "PMC4030922", 0.49, "0.45-0.499 (nearly incompressible)", "PMC4030922",
       0.0, 0.0, 0.0, ""},
  };
  return presets;
}

const TissuePreset* find_tissue(const std::string& name) {
  for (const auto& p : tissue_presets())
    if (p.name == name) return &p;
  return nullptr;
}

}  // namespace tissue
