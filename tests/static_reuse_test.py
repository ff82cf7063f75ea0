#!/usr/bin/env python3
"""The static solve with the cell term (issue 15) without work it did twice or memory it touched for one use, against
the same solve without either (`-static_reuse_residual false -static_estimate_on_idle false`), on bench_poisson.sh's
block (run_scripts/scenes/poisson_block.toml, 16^3 and 24^3, nu = 0.45: the cp line search, the finest level's
Chebyshev interval from PETSc's estimate, `-static_symbol_upper 0`, not from the interior's symbol), 1, 2 and 3
ranks:
  - every number of the summary's solve equal to the bit: elongation, the measured E and Poisson ratio, the
    residual, Newton and Krylov counts;
  - the residual at the positions of the last evaluation was kept, not evaluated again, where the cp line search
    takes lambda = 1 exactly after evaluating there: with its full-step rule (the slope at lambda = 1 below 1e-3
    of its start) in both Newton steps of both blocks; with the secant always taken (-snes_linesearch_rtol 1e-8,
    PETSc's default) once a solve at 24^3 (Newton 2), and evaluated again where the lambda it takes differs from
    1 by a few ulps of the positions (16^3: 1 - 3e-8 in Newton 2; -info); the
    estimate's work vectors placed on idle arrays (-info: 5 of them: the outer CG's 3 and the finest smoother's 2);
    without the options neither.
And the springs-only block (nu = 1/4: no cell term, basic line search, Gershgorin's interval): neither happens, the
same numbers.

Usage: static_reuse_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import json
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, check_same_solve, report, tissue  # noqa: E402

KEPT = "the residual at the last evaluation's positions kept"


def idle_arrays(stdout):
    """The counts of idle arrays the finest estimate took, rank 0's lines."""
    return [int(n) for n in re.findall(r"^\[0\] .*the estimate's work vectors on (\d+) idle arrays", stdout, re.M)]


def main():
    a, work = arguments_and_work("static_reuse")
    scene = os.path.join(a.source, "run_scripts", "scenes", "poisson_block.toml")
    # (name, ranks, --set, cells, evaluations kept)
    # (name, ranks, --set, cells, evaluations kept, PETSc options of both runs)
    secant = ["-snes_linesearch_rtol", "1e-8"]
    cells24 = ["body.poisson_ratio=0.45", "body.molecules=[24,24,24]", "load.0.force=[0,0,0.529]"]
    cases = [("cells16", ranks, ["body.poisson_ratio=0.45"], True, 2, []) for ranks in (1, 3)]
    cases += [("cells16 secant", ranks, ["body.poisson_ratio=0.45"], True, 0, secant) for ranks in (1, 2, 3)]
    cases += [("cells24", 2, cells24, True, 2, [])]
    cases += [("cells24 secant", ranks, cells24, True, 1, secant) for ranks in (1, 3)]
    cases += [("springs16", 2, [], False, 0, [])]
    for name, ranks, sets, cells, kept, both in cases:
        runs, out_text = {}, {}
        for label, options in (("new", ["-static_symbol_upper", "0", *both]),
                               ("old", ["-static_symbol_upper", "0", "-static_reuse_residual", "false",
                                        "-static_estimate_on_idle", "false", *both])):
            out = os.path.join(work, f"{name.replace(' ', '_')}_{label}_np{ranks}")
            extra = [arg for s in sets for arg in ("--set", s)]
            r = tissue(a.build, ranks, "run", scene, *extra, "--set", "output.fields=[]", "--set",
                       "output.progress=false", "--output", out, "--", "-info", *options)
            if check(r.returncode == 0, f"{name} {label}, {ranks} ranks: exit {r.returncode}: {r.stderr[-300:]}"):
                with open(os.path.join(out, "summary.json")) as f:
                    runs[label] = json.load(f)
                out_text[label] = r.stdout
        if len(runs) < 2:
            continue
        what = f"{name}, {ranks} ranks"
        new, old = runs["new"], runs["old"]
        check_same_solve(new, old, what)
        kept_new = len(re.findall(r"^\[0\] .*" + re.escape(KEPT), out_text["new"], re.M))
        kept_old = len(re.findall(re.escape(KEPT), out_text["old"]))
        if cells:
            check(kept_new == kept, f"{what}: {kept} evaluation(s) kept ({kept_new})")
            check(idle_arrays(out_text["new"]) == [5], f"{what}: the estimate on 5 idle arrays "
                                                       f"({idle_arrays(out_text['new'])})")
        else:
            check(kept_new == 0 and not idle_arrays(out_text["new"]), f"{what}: nothing kept, no estimate")
        check(kept_old == 0 and not idle_arrays(out_text["old"]), f"{what}: the options turn both off")
    return report()


if __name__ == "__main__":
    sys.exit(main())
