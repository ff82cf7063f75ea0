// The solvers' set-up checks, made once before any step (see docs/stability.md); the per-step guards are
// src/solvers/guards.hpp.
//  - the time step: one above the critical time step is refused (InputError naming solver.time_step, exit 2)
//    unless the scene sets solver.allow_unstable_time_step = true (then used as given, with a warning);
//  - a connection of zero (or non-finite) rest length is refused (InputError naming body).
#pragma once
#include "partition/local_model.hpp"
#include "src/model/scene.hpp"

namespace tissue {

// The time step an explicit solver uses: `requested` (the scene's, or absent) checked against `critical`.
// Throws InputError naming solver.time_step when it is above critical and the scene does not allow it; prints
// a warning on rank 0 when it does.
double checked_time_step(const Scene& scene, const LocalModel& model, double requested, double critical,
                         const char* solver);

// Collective. Throws InputError (file: the scene, key: body) when a connection has a zero, negative or
// non-finite rest length, or a non-finite or negative stiffness.
void check_connections(const Scene& scene, const LocalModel& model);

}  // namespace tissue
