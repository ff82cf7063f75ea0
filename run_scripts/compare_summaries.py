#!/usr/bin/env python3
"""Compare two tissue summary.json files key by key (issue 21: "behaviour and results unchanged").

    python3 run_scripts/compare_summaries.py OLD/summary.json NEW/summary.json [--rtol 1e-12] [--quiet]
    python3 run_scripts/compare_summaries.py --excluded          # the excluded keys and why, then exit 0
    python3 run_scripts/compare_summaries.py --self-test         # shows that perturbed numbers and keys are caught

Walks both JSON trees recursively. Numbers agree when |a - b| <= rtol * max(|a|, |b|) + 1e-300 (NaN equals NaN;
the 1e-300 is the absolute floor for numbers at or near zero); strings, booleans and null must be equal; a list
must have the same length; an object must have the same keys. Every differing key path is printed with both
values (`solver.residual_history[3]: old 1.2e-08 new 1.3e-08 (rel 7.7e-02)`); a key present on one side only is
reported as missing or extra, also for excluded keys (they must still exist, only their values are not compared).
The last line is always `max_rel R at PATH` (the largest relative difference over all compared numbers, also
when within rtol; `max_rel 0.000e+00 (all numbers equal)` when every number is bit for bit the same), which run_scripts/compare_binaries.sh prints per scene.
Exit code: 0 all agree, 1 any difference or missing / extra key, 2 a file cannot be read or parsed.
Standard library only.
"""
import json
import math
import re
import sys

# THE list of keys whose values are legitimately run-dependent, as key paths with list indices removed
# ("solver.seconds" matches it in every summary; "a.b[]" would match every element of list a.b). This is the
# only place where keys are excluded; run_scripts/compare_binaries.sh uses it as is.
EXCLUDED = {
    "wall_seconds": "wall time of the whole run: depends on the machine's load",
    "solver.seconds": "wall time of the solve: depends on the machine's load",
    "solver.cpu_seconds": "rank 0's CPU time of the solve: depends on the machine's load",
    "solver.guard_seconds": "wall time inside the explicit solvers' guards: depends on the machine's load",
    "peak_memory_bytes": "resident memory: depends on the allocator, shared libraries and the binary's layout, "
                         "not on the results (run_scripts/compare_speed.sh compares it)",
    "version": "the program's version string: a new build may legitimately carry a new one",
    "scene": "a path: the scene file, or for a restart the checkpoint, which lies in each binary's own output "
             "directory",
}

# Keys that later work added to summary.json (../shared/interface.md lists them): a NEW summary may have them where
# an OLD one (a binary from before that work) does not; "extra in new" for these is not a difference. Their values
# are compared whenever both summaries have them. Any other extra key, and any missing key, is a difference.
ADDED = {
    "reactions": "issue 16: the total force each [[fix]] exerts on the body",
    "poisson_ratios_measured": "issue 15: both lateral Poisson ratios",
    "shear_modulus_measured": "issue 15: the simple-shear test's G",
    "aggregate_modulus_measured": "issue 15: confined compression's H_A",
}

# Measurements that later work makes where an OLD binary reported null: "old null, new a number" is not a
# difference for these (any other pair of values is compared as usual, a number turning null included).
MEASURED_SINCE = {
    "poisson_ratio_measured": "a1c948a: also on a random box's or a mesh's planes x- .. z+ (null there before)",
}


def _strip(path):
    return re.sub(r"\[\d+\]", "[]", path)


def _fmt(v):
    return json.dumps(v) if not isinstance(v, float) else repr(v)


class Comparison:
    def __init__(self, rtol):
        self.rtol = rtol
        self.differences = []  # (path, message)
        self.max_rel = 0.0
        self.max_rel_path = "-"

    def differ(self, path, message):
        self.differences.append((path or "(root)", message))

    def walk(self, a, b, path):
        if _strip(path) in EXCLUDED:
            return
        num = lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)
        if num(a) and num(b):
            fa, fb = float(a), float(b)
            if math.isnan(fa) or math.isnan(fb):
                if not (math.isnan(fa) and math.isnan(fb)):
                    self.differ(path, "old %s new %s" % (_fmt(a), _fmt(b)))
                return
            scale = max(abs(fa), abs(fb))
            if fa == fb:  # also two equal infinities (inf - inf is NaN)
                rel, same = 0.0, True
            else:
                delta = abs(fa - fb)
                rel = delta / scale if math.isfinite(delta) else math.inf
                same = delta <= self.rtol * scale + 1e-300
            if rel > self.max_rel:
                self.max_rel, self.max_rel_path = rel, path or "(root)"
            if not same:
                self.differ(path, "old %s new %s (rel %.3e)" % (_fmt(a), _fmt(b), rel))
            return
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                sub = "%s.%s" % (path, k) if path else k
                if k not in b:
                    self.differ(sub, "missing in new (old %s)" % _fmt(a[k]))
                elif k not in a:
                    if _strip(sub) not in ADDED:
                        self.differ(sub, "extra in new (new %s)" % _fmt(b[k]))
                else:
                    self.walk(a[k], b[k], sub)
            return
        if isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                self.differ(path, "list length old %d new %d" % (len(a), len(b)))
            for i in range(min(len(a), len(b))):
                self.walk(a[i], b[i], "%s[%d]" % (path, i))
            for i in range(len(b), len(a)):
                self.differ("%s[%d]" % (path, i), "missing in new (old %s)" % _fmt(a[i]))
            for i in range(len(a), len(b)):
                self.differ("%s[%d]" % (path, i), "extra in new (new %s)" % _fmt(b[i]))
            return
        # strings, booleans, null, or two different types (a number against null, say)
        if a is None and num(b) and _strip(path) in MEASURED_SINCE:
            return
        if type(a) is not type(b) or a != b:
            self.differ(path, "old %s new %s" % (_fmt(a), _fmt(b)))


def self_test():
    """Perturbs a summary-like tree in the ways a regression could, and checks each verdict."""
    base = {"elongation": 0.008599999962545974, "center_of_mass": [0.5, 1e-17, 0.0], "wall_seconds": 1.9,
            "contact_force": None, "poisson_ratio_measured": None,
            "solver": {"converged": True, "iterations": 9, "residual_history": [2.6e-13]},
            "version": "0.1.0", "calibration": {"method": "iterative", "divisor": 1.3067182818589531}}
    cases = [  # (what, mutation, should differ)
        ("unchanged", lambda t: None, False),
        ("elongation x (1 + 2e-12)", lambda t: t.update(elongation=t["elongation"] * (1 + 2e-12)), True),
        ("elongation x (1 + 5e-13)", lambda t: t.update(elongation=t["elongation"] * (1 + 5e-13)), False),
        ("calibration.divisor + 1e-10", lambda t: t["calibration"].update(divisor=1.3067182819589531), True),
        ("center_of_mass[1] 1e-17 -> 2e-17", lambda t: t["center_of_mass"].__setitem__(1, 2e-17), True),
        ("center_of_mass[2] 0.0 -> -0.0", lambda t: t["center_of_mass"].__setitem__(2, -0.0), False),
        ("solver.iterations 9 -> 10", lambda t: t["solver"].update(iterations=10), True),
        ("solver.converged flipped", lambda t: t["solver"].update(converged=False), True),
        ("contact_force null -> [0, 0, 0]", lambda t: t.update(contact_force=[0.0, 0.0, 0.0]), True),
        ("residual_history one more", lambda t: t["solver"]["residual_history"].append(1e-14), True),
        ("calibration.method changed", lambda t: t["calibration"].update(method="divided"), True),
        ("wall_seconds changed (excluded)", lambda t: t.update(wall_seconds=99.0), False),
        ("version changed (excluded)", lambda t: t.update(version="0.2.0"), False),
        ("wall_seconds missing (excluded, still required)", lambda t: t.pop("wall_seconds"), True),
        ("extra key", lambda t: t.update(new_key=1), True),
        ("an added key (ADDED) in new only", lambda t: t.update(reactions=[[0.0, 0.0, 1.0]]), False),
        ("poisson_ratio_measured null -> 0.25 (MEASURED_SINCE)", lambda t: t.update(poisson_ratio_measured=0.25),
         False),
        ("contact_force null -> 1.0 (not MEASURED_SINCE)", lambda t: t.update(contact_force=1.0), True),
    ]
    bad = 0
    for what, mutate, should in cases:
        t = json.loads(json.dumps(base))
        mutate(t)
        c = Comparison(1e-12)
        c.walk(base, t, "")
        ok = bool(c.differences) == should
        bad += not ok
        print("%-4s %-48s %s" % ("ok" if ok else "BAD", what, "; ".join("%s: %s" % d for d in c.differences) or
                                 "no difference (max_rel %.1e)" % c.max_rel))
    print("self-test: %s" % ("passed" if not bad else "%d case(s) wrong" % bad))
    return 1 if bad else 0


def main(argv):
    args = argv[1:]
    rtol, quiet, files = 1e-12, False, []
    i = 0
    while i < len(args):
        if args[i] == "--rtol":
            rtol = float(args[i + 1])
            i += 2
            continue
        if args[i] == "--quiet":
            quiet = True
        elif args[i] == "--excluded":
            for k, why in ADDED.items():
                print("%-28s added: %s" % (k, why))
            for k, why in MEASURED_SINCE.items():
                print("%-28s measured since: %s" % (k, why))
            for k, why in EXCLUDED.items():
                print("%-22s %s" % (k, why))
            return 0
        elif args[i] == "--self-test":
            return self_test()
        elif args[i] in ("-h", "--help"):
            print(__doc__)
            return 0
        else:
            files.append(args[i])
        i += 1
    if len(files) != 2:
        print("usage: compare_summaries.py OLD.json NEW.json [--rtol R] [--quiet] | --excluded", file=sys.stderr)
        return 2
    trees = []
    for f in files:
        try:
            with open(f) as fh:
                trees.append(json.load(fh))
        except (OSError, ValueError) as e:
            print("compare_summaries: cannot read %s: %s" % (f, e), file=sys.stderr)
            return 2
    c = Comparison(rtol)
    c.walk(trees[0], trees[1], "")
    if not quiet:
        for path, message in c.differences:
            print("  %s: %s" % (path, message))
    print("max_rel %.3e%s" % (c.max_rel, " at " + c.max_rel_path if c.max_rel > 0 else " (all numbers equal)"))
    return 1 if c.differences else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
