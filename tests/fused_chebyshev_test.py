#!/usr/bin/env python3
"""The matrix-free finest smoother with its vector operations fused (src/solvers/fused_chebyshev.cpp) against
PETSc's KSPCHEBYSHEV on PCJACOBI (`-static_fused_chebyshev false`, the old path), on the LAMMPS peer tension scene
(run_scripts/scenes/peer_tension.toml, 20^3, the bench's load), 1, 2 and 3 ranks, Chebyshev degrees 2 (the default:
two work vectors), 1 (one step, straight into x) and 3 (three work vectors, the iterates rotated):
  - every number of the summary's solve equal to the bit: elongation, the measured E and Poisson ratio, the
    residual, Newton and Krylov counts (the same operations in the same order);
  - the fused path was taken: fewer VecAXPBYPCZ calls in -log_view than the old path's (PETSc's Chebyshev step).
The same with the cell term (run_scripts/scenes/poisson_block.toml: a homogenized 16^3 block, clamped base, traction on top,
bench_poisson.sh's): cubic cells at nu = 0.45 (volumetric only) and 1:1:0.5 cells at nu = 0.3, where the finest interval is not
Gershgorin's but PETSc's estimate, which the fused smoother takes from a KSPCHEBYSHEV made for it (1, 2, 3 ranks,
degree 2; degree 3 on 1 rank). The levels between the finest and the coarsest are fused too (newton_equilibrium.cpp,
fuse_coarse_chebyshev): the peer scene has one (20^3: 3 levels), and a 24^3 cell block at nu = 0.45 (1 and 3 ranks)
one with the cells' 4 coarse steps.

Usage: fused_chebyshev_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import json
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, check_same_solve, report, tissue  # noqa: E402


def axpbypcz_calls(stdout):
    m = re.search(r"^VecAXPBYCZ\s+(\d+)", stdout, re.M)
    return int(m.group(1)) if m else 0




def main():
    a, work = arguments_and_work("fused_chebyshev")
    peer = os.path.join(a.source, "run_scripts", "scenes", "peer_tension.toml")
    cells = os.path.join(a.source, "run_scripts", "scenes", "poisson_block.toml")
    cases = [(peer, "peer", ranks, degree, ["load.0.force=[0,0,-0.4]"]) for ranks in (1, 2, 3) for degree in (2, 1, 3)]
    cases += [(cells, "cells045", ranks, degree, ["body.poisson_ratio=0.45"])
              for ranks, degree in ((1, 2), (2, 2), (3, 2), (1, 3))]
    cases += [(cells, "cells03", ranks, 2, ["body.poisson_ratio=0.3", "body.spacing=[0.001,0.001,0.0005]"])
              for ranks in (1, 3)]
    # 24^3: three levels, so a level between the finest and the coarsest (the stencil shell of level 1), whose
    # smoother is fused too, with the cells' 4 steps (use_volume_smoother) and PETSc's estimate.
    # Degree 0: the defaults (no -mg_levels_ksp_max_it: 2 steps on the finest level, 4 on the coarse ones).
    cases += [(cells, "cells045_24", ranks, 0, ["body.poisson_ratio=0.45", "body.molecules=[24,24,24]",
                                                "load.0.force=[0,0,0.529]"]) for ranks in (1, 3)]
    for scene, name, ranks, degree, sets in cases:
        runs, calls = {}, {}
        for label, fused in (("fused", "true"), ("petsc", "false")):
            out = os.path.join(work, f"{name}_{label}_np{ranks}_d{degree}")
            extra = [arg for s in sets for arg in ("--set", s)]
            degree_option = ["-mg_levels_ksp_max_it", str(degree)] if degree else []
            r = tissue(a.build, ranks, "run", scene, *extra, "--set",
                       "solver.tolerance=1e-8", "--set", "output.fields=[]", "--set", "output.progress=false",
                       "--output", out, "--", "-static_fused_chebyshev", fused, *degree_option, "-log_view")
            if check(r.returncode == 0, f"{label}, {ranks} ranks, degree {degree}: exit {r.returncode}: {r.stderr[-300:]}"):
                with open(os.path.join(out, "summary.json")) as f:
                    runs[label] = json.load(f)
                calls[label] = axpbypcz_calls(r.stdout)
        if len(runs) < 2:
            continue
        what = f"{name}, {ranks} ranks, degree {degree}"
        new, old = runs["fused"], runs["petsc"]
        check_same_solve(new, old, what)
        if degree != 1:
            # PETSc's Chebyshev step (2+ steps) calls VecAXPBYPCZ; with every level's smoother fused none is left.
            check(calls["fused"] == 0 < calls["petsc"],
                  f"{what}: the fused smoothers ran on every level (VecAXPBYPCZ calls {calls['fused']} == 0 < "
                  f"{calls['petsc']})")
    # A level's own smoother option (-mg_levels_1_ksp_type) keeps that level PETSc's: its VecAXPBYPCZ calls are back,
    # and the numbers are the fused run's.
    out = os.path.join(work, "cells045_24_own_level")
    r = tissue(a.build, 1, "run", cells, "--set", "body.poisson_ratio=0.45", "--set", "body.molecules=[24,24,24]",
               "--set", "load.0.force=[0,0,0.529]", "--set", "solver.tolerance=1e-8", "--set", "output.fields=[]",
               "--set", "output.progress=false", "--output", out, "--", "-mg_levels_1_ksp_type", "chebyshev",
               "-log_view")
    fused_out = os.path.join(work, "cells045_24_fused_np1_d0", "summary.json")
    if check(r.returncode == 0 and os.path.exists(fused_out), f"own level option: exit {r.returncode}"):
        with open(os.path.join(out, "summary.json")) as f:
            own = json.load(f)
        with open(fused_out) as f:
            fused = json.load(f)
        check(axpbypcz_calls(r.stdout) > 0, "own level option: level 1 is PETSc's (VecAXPBYPCZ calls)")
        check(own["elongation"] == fused["elongation"] and own["solver"]["residual"] == fused["solver"]["residual"],
              "own level option: the same numbers")
    return report()


if __name__ == "__main__":
    sys.exit(main())
