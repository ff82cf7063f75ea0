// `tissue fit`: the material parameters for which a simulated test reproduces a measured curve.
//
//   tissue fit creep_fit.toml --output out/fit          # the scene of the experiment plus a [fit] table
//   mpirun -np 2 tissue fit creep_fit.toml -- -fit_tao_max_funcs 200 -fit_tao_monitor
//
// Bounded nonlinear least squares over the [fit] parameters: residual r_i = y_simulated(x_i) - y_measured(x_i)
// at each simulated row x_i inside the measured range (the measured curve interpolated there). PETSc's TAO
// POUNDERS (derivative-free, model-based) minimises |r|^2 in scaled variables u in [0, 1]^n (logarithmic for
// positive bounds spanning more than a decade, such as time constants); every forward run is the ordinary
// solver on every rank. Afterwards a finite-difference Jacobian at the optimum gives the standard errors and the
// correlation matrix; parameters the data cannot separate are flagged. TAO's options take the prefix -fit_.
#pragma once
#include <mpi.h>

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "io/fit_input.hpp"

namespace tissue {

// One forward run of the scene with these --set items, writing into `directory`; returns the exit code
// (0 = finished). Collective.
using ForwardRun = std::function<int(const std::vector<std::string>& overrides, const std::string& directory)>;

struct FitResult {
  std::vector<double> values, standard_errors;  // per parameter
  std::vector<std::vector<double>> correlation;
  std::vector<bool> on_bound;
  double residual_norm = 0.0;  // |r| at the fitted values (several y columns: of r, each column over its scale)
  std::vector<double> column_norms;  // per y column: |r| of that column, in its units
  long residuals = 0;          // how many points r has
  long forward_runs = 0, failed_runs = 0;
  bool converged = false;      // TAO's reason is a convergence
  bool identifiable = true;    // J^T J well conditioned and no |correlation| > 0.999
  std::string reason;          // TAO's converged reason, in words
  std::string notes;
};

// Collective. Fits input.parameters; forward runs write into `work` (overwritten run after run).
FitResult fit_parameters(const FitInput& input, const ForwardRun& forward, const std::string& work, MPI_Comm comm,
                         bool progress);

}  // namespace tissue
