// The lattice multigrid's finest level on the tangent at rest (issue 18). The preconditioner is built once a solve,
// at the state of its first tangent (SNES lag -1), which in a static solve is the rest state: its coarse operators
// are the rest tangent's. The finest level's smoother and PCMG's residual there may then use the tangent at rest
// too, while the outer CG keeps the Newton tangent J: at rest every spring's block is a constant of its stencil
// direction, k n n^T (l = l0: no geometric part), applied without the positions, square roots or divisions
// (SpringKernel::rest_tangent; in the pull form, each row's springs summed once, where the rows fit it:
// src/physics/rest_pull.hpp, off with -static_rest_pull false), and the terms' products come from their states at
// rest, made once. The two tangents differ by O(strain), so the Krylov counts do not move at a tissue test's strains.
// Where the hierarchy is rebuilt at any other state (a slow solve's rebuild, later quasi-static steps) the level
// is J again, as before. Off with -static_rest_smoother false, and where the rest tangent is not what the
// hierarchy was built from: a term with history or beyond the lattice cells, a calibration that follows the
// deformation, or springs whose rest separations are not their stencil direction's (RestStencil::exact).
#pragma once
#include <petscksp.h>

#include <memory>

#include "partition/local_model.hpp"
#include "src/physics/force_model.hpp"
#include "src/solvers/matrix_free.hpp"

namespace tissue {

class RestTangent {
public:
  // Collective. The rest tangent for the matrix-free solve's finest level, or null (every rank alike) where it does
  // not apply (above) or -static_rest_smoother is false. scratch: as MatrixFreeTangent's (the Newton solve's force
  // array). refreshes: the calibration changes the stiffness during the solve (SolverHooks::refresh).
  static PetscErrorCode make(const LocalModel& model, const ForceModel& forces, double* scratch, bool refreshes,
                             std::unique_ptr<RestTangent>* out);
  ~RestTangent();
  RestTangent(const RestTangent&) = delete;
  RestTangent& operator=(const RestTangent&) = delete;
  // Collective; at every rebuild of pc (a PCMG, before its set-up), x: the positions the hierarchy is built at. The
  // finest level's smoother and residual operator become the rest tangent when x is the rest state on every rank
  // (agreed), else J (what PCMG takes by itself).
  PetscErrorCode use(PC pc, const double* x, Mat J);
  Mat matrix() const { return P_; }
  // Whether the last use() chose the rest tangent.
  bool at_rest() const { return current_ == P_; }

private:
  RestTangent(const LocalModel& model, const ForceModel& forces, double* scratch);
  const LocalModel& model_;
  RestStencil stencil_;
  MatrixFreeTangent shell_;
  Mat P_ = nullptr;
  Mat current_ = nullptr;  // the finest level's operator as use() last set it
};

}  // namespace tissue
