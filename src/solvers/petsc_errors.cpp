#include "src/solvers/petsc_errors.hpp"

#include <petscsys.h>

namespace tissue {

namespace {

std::string& last_error() {
  static std::string text;
  return text;
}

PetscErrorCode keep_first_message(MPI_Comm, int, const char* function, const char*, PetscErrorCode code,
                                  PetscErrorType type, const char* message, void*) {
  // (an error passed up from a called function repeats with PETSC_ERROR_REPEAT: its first report says what)
  if (type == PETSC_ERROR_INITIAL)
    last_error() = std::string(message && *message ? message : "an error without a message") +
                   (function && *function ? std::string(" (") + function + ")" : std::string());
  return code;
}

}  // namespace

void install_petsc_error_handler() {
  for (const char* own : {"-on_error_abort", "-on_error_attach_debugger", "-on_error_emacs", "-start_in_debugger",
                          "-stop_for_debugger"}) {
    PetscBool given = PETSC_FALSE;
    if (PetscOptionsHasName(nullptr, nullptr, own, &given) == 0 && given) return;
  }
  PetscPushErrorHandler(keep_first_message, nullptr);
}

std::string last_petsc_error() { return last_error(); }

namespace {
std::string& given() {
  static std::string text;
  return text;
}
}  // namespace

void remember_user_options(const std::string& text) { given() = text; }
const std::string& user_options() { return given(); }

SolverFailure petsc_failure(const std::string& kind) {
  const std::string why = last_petsc_error();
  return SolverFailure(kind + ": a PETSc call failed" + (why.empty() ? std::string() : " (" + why + ")"),
                       SolverFailure::State::nothing);
}

}  // namespace tissue
