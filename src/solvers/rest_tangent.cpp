#include "src/solvers/rest_tangent.hpp"

#include <algorithm>

#include "src/physics/rest_pull.hpp"

namespace tissue {

RestTangent::RestTangent(const LocalModel& model, const ForceModel& forces, double* scratch)
    : model_(model), stencil_(forces.kernel().rest_stencil()), shell_(model, forces, scratch, &stencil_) {}

RestTangent::~RestTangent() { (void)MatDestroy(&P_); }

PetscErrorCode RestTangent::make(const LocalModel& model, const ForceModel& forces, double* scratch, bool refreshes,
                                 std::unique_ptr<RestTangent>* out) {
  PetscFunctionBeginUser;
  out->reset();
  PetscBool on = PETSC_TRUE;
  PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-static_rest_smoother", &on, nullptr));
  // The same on every rank: the options, the scene's terms and calibration.
  const auto& terms = forces.terms();
  const bool terms_fit = std::all_of(terms.begin(), terms.end(), [](const auto& t) {
    return t->tangent_within_cells() && !t->has_history();
  });
  if (!on || refreshes || !terms_fit) PetscFunctionReturn(0);
  std::unique_ptr<RestTangent> rest(new RestTangent(model, forces, scratch));
  int mine = rest->stencil_.exact ? 1 : 0, all = 0;
  PetscCallMPI(MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_MIN, model.comm));
  if (!all) PetscFunctionReturn(0);
  // The springs' product in the pull form where the rows fit it (RestPull::make, rank by rank; the push form
  // elsewhere and with -static_rest_pull false).
  PetscBool pull = PETSC_TRUE;
  PetscCall(PetscOptionsGetBool(nullptr, nullptr, "-static_rest_pull", &pull, nullptr));
  if (pull) {
    const double start = MPI_Wtime();
    rest->stencil_.pull = RestPull::make(model);
    if (const RestPull* p = rest->stencil_.pull.get())
      PetscCall(PetscInfo(nullptr,
                          "rest product in the pull form: %ld full, %ld masked, %ld listed rows (%ld springs), "
                          "made in %.3f s\n",
                          p->rows(RestPull::kFull), p->rows(RestPull::kMasked), p->rows(RestPull::kListed),
                          p->listed_springs(), MPI_Wtime() - start));
  }
  PetscCall(rest->shell_.create(&rest->P_));
  PetscCall(rest->shell_.set_positions(model.rest.data(), rest->P_));  // the terms' states at rest, once
  *out = std::move(rest);
  PetscFunctionReturn(0);
}

PetscErrorCode RestTangent::use(PC pc, const double* x, Mat J) {
  PetscFunctionBeginUser;
  int here = std::equal(x, x + 3 * static_cast<std::size_t>(model_.owned), model_.rest.begin()) ? 1 : 0, all = 0;
  PetscCallMPI(MPI_Allreduce(&here, &all, 1, MPI_INT, MPI_MIN, model_.comm));
  Mat fine = all ? P_ : J;
  if (fine == current_) PetscFunctionReturn(0);
  // PCMG sets the finest level's operators from the PC's only while the level has none or has the PC's Pmat, and
  // its residual operator only once (PCSetUp_MG, PETSc 3.18): both are set here.
  PetscInt levels;
  KSP smoother;
  PetscCall(PCMGGetLevels(pc, &levels));
  PetscCall(PCMGGetSmoother(pc, levels - 1, &smoother));
  PetscCall(KSPSetOperators(smoother, fine, fine));
  PetscCall(PCMGSetResidual(pc, levels - 1, PCMGResidualDefault, fine));
  current_ = fine;
  PetscCall(PetscInfo(pc, "finest level on the %s tangent\n", all ? "rest" : "Newton"));
  PetscFunctionReturn(0);
}

}  // namespace tissue
