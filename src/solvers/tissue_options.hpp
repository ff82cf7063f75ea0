// The project's own options in PETSc's options database (after `--`, or PETSC_OPTIONS): -static_* tune the static
// solver, -tissue_* switch guards and fused terms. Checked once at start-up, so that a malformed or out-of-range
// value is bad input (one line naming the option, exit 2) rather than PETSc's traceback in the middle of a solve.
#pragma once

namespace tissue {

// Throws InputError("PETSc options", option, what it expects) for the first bad value. Reads the database only
// (the same on every rank: every rank throws alike).
void check_tissue_options();

}  // namespace tissue
