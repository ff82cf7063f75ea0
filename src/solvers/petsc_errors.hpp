// PETSc's errors as our one line. PETSc's default error handler prints a traceback on rank 0 and, on every other
// rank, sleeps 10 s and calls abort(): an error every rank meets together (a refused option, a preconditioner that
// breaks down) then ends the job as "exited improperly", exit 1, instead of the failure every rank agrees on.
// Installed after PetscInitialize, this handler prints nothing and keeps the error's first message, which the
// solver's SolverFailure then carries (exit 3, one line).
#pragma once

#include <string>

#include "src/solvers/solver.hpp"

namespace tissue {

// Unless the user asked PETSc for its own handling (-on_error_abort, -on_error_attach_debugger, ...).
void install_petsc_error_handler();
// The first message of the latest PETSc error with the function that raised it, or "" (none since start-up).
std::string last_petsc_error();
// "kind: a PETSc call failed (message)": nothing worth writing (the state is whatever PETSc left).
SolverFailure petsc_failure(const std::string& kind);
// The options the user gave PETSc (the command line after `--`, PETSC_OPTIONS), as text for messages: the
// database also holds those the program sets itself.
void remember_user_options(const std::string& text);
const std::string& user_options();

}  // namespace tissue
