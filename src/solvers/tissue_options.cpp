#include "src/solvers/tissue_options.hpp"

#include <petscsys.h>

#include <string>

#include "src/model/scene.hpp"

namespace tissue {

namespace {

// PETSc's own parse errors returned, not printed: the InputError's line is the message.
struct QuietPetscErrors {
  QuietPetscErrors() { PetscPushErrorHandler(PetscIgnoreErrorHandler, nullptr); }
  ~QuietPetscErrors() { PetscPopErrorHandler(); }
};

[[noreturn]] void bad(const char* name, const std::string& expects) {
  throw InputError("PETSc options", name, "expects " + expects);
}

void boolean(const char* name) {
  PetscBool v = PETSC_FALSE;
  if (PetscOptionsGetBool(nullptr, nullptr, name, &v, nullptr)) bad(name, "true or false");
}

void whole(const char* name, PetscInt least) {
  PetscInt v = 0;
  PetscBool given = PETSC_FALSE;
  if (PetscOptionsGetInt(nullptr, nullptr, name, &v, &given) || (given && v < least))
    bad(name, "a whole number >= " + std::to_string(least));
}

// A fraction in [lo, 1): open at 0 when `zero_allowed` is false.
void fraction(const char* name, bool zero_allowed) {
  PetscReal v = 0;
  PetscBool given = PETSC_FALSE;
  const bool parsed = PetscOptionsGetReal(nullptr, nullptr, name, &v, &given) == 0;
  if (!parsed || (given && !(zero_allowed ? v >= 0 && v < 1 : v > 0 && v < 1)))
    bad(name, zero_allowed ? "a number in [0, 1) (0: off)" : "a number in (0, 1)");
}

void nonnegative(const char* name) {
  PetscReal v = 0;
  PetscBool given = PETSC_FALSE;
  if (PetscOptionsGetReal(nullptr, nullptr, name, &v, &given) || (given && !(v >= 0)))
    bad(name, "a number >= 0");
}

}  // namespace

void check_tissue_options() {
  QuietPetscErrors quiet;
  boolean("-tissue_guards");
  boolean("-tissue_fuse_terms");
  whole("-tissue_fuse_rows", 1);
  fraction("-static_first_rtol", true);
  fraction("-static_enough_fraction", true);
  fraction("-static_enough_share", true);
  fraction("-static_chebyshev_fraction", false);
  boolean("-static_fused_chebyshev");
  boolean("-static_rest_smoother");
  boolean("-static_rest_pull");
  boolean("-static_cell_pull");
  boolean("-static_reuse_residual");
  boolean("-static_estimate_on_idle");
  whole("-static_cell_coarse_steps", 0);
  boolean("-static_volume_smoother");
  whole("-static_volume_smoother_steps", 1);
  whole("-static_gamg_reuse_molecules", 0);
  boolean("-static_level_one_pull");
  nonnegative("-static_symbol_upper");
}

}  // namespace tissue
