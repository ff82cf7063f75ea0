#!/usr/bin/env python3
"""The paper's Table 2 beside ours, one row per calibration method (main_job.sh prints it).

    python3 run_scripts/table2_side_by_side.py OUT_DIR METHOD...

OUT_DIR holds one directory per method (OUT_DIR/<method>/summary.json, written by the run) and, next to it,
OUT_DIR/<method>.log (the run's output) and OUT_DIR/<method>.status ("<exit code> <solver>"); TABLE2_SUPPORT
(default clamped) names the support in the heading. The paper's
figures come from run_scripts/paper_values.csv (the one copy, also read by paper_tables.sh); ours only from the
runs' summary.json. Standard library only.
"""
import csv
import json
import os
import re
import sys
import textwrap

LABEL = {"linear": "Linear case", "tetrahedral": "Tetrahedral (Eq. 5)", "divided": "k / 3.75 (divided)",
         "angles": "Angles", "angles-update": "Angles (update)", "statistical": "Statistical",
         "iterative": "Iterative", "homogenized": "Homogenized (ours)", "lloyd": "Lloyd 2007", "manual": "Manual"}
# What the paper says where Table 2 has no row for a method.
NOT_IN_PAPER = {"tetrahedral": "not implemented",
                "angles-update": "not in Table 2"}


def thousands(x):
    return format(round(x), ",").replace(",", "'")


def main():
    out, methods = sys.argv[1], sys.argv[2:]
    here = os.path.dirname(os.path.abspath(__file__))
    paper = {p["method"]: p for p in csv.DictReader(open(os.path.join(here, "paper_values.csv")))
             if p["table"] == "2"}
    rows, notes, first = [], [], None
    for m in methods:
        rc, solver = open(os.path.join(out, m + ".status")).read().split(None, 1)
        rc, solver = int(rc), solver.strip()
        p = paper.get(m)
        pc = ("%.3f" % float(p["elongation_mm"]), thousands(int(p["youngs_modulus"])), p["error_percent"]) \
            if p else None
        s = os.path.join(out, m, "summary.json")
        if rc == 0 and os.path.exists(s):
            j = json.load(open(s))
            first = first or j
            el = j["elongation"]
            oc = ("-" if el is None else "%.3f" % (1e3 * el), thousands(j["youngs_modulus_measured"]),
                  "%+.2f" % j["error_percent"])
            note = []
            divisor = (j.get("calibration") or {}).get("divisor")
            if m in ("divided", "iterative") and divisor:
                note.append("C = %.4f" % divisor)
            if solver != "static":
                note.append(solver)
            rows.append((LABEL.get(m, m), pc, NOT_IN_PAPER.get(m, "-"), oc, None, ", ".join(note)))
        else:   # refused (exit 2) or failed: the program's own one line
            log = open(os.path.join(out, m + ".log")).read().splitlines()
            said = [l.strip() for l in log if "calibration." in l or "needs" in l or "error" in l.lower()]
            reason = said[0] if said else "exit %d" % rc
            reason = re.sub(r"^\S+\.toml: ", "", reason)   # the scene's path: the same for every row
            what = "n/a: refused (exit 2)" if rc == 2 else "failed (exit %d)" % rc
            notes.append("%s (exit %d): %s" % (m, rc, reason))
            needs = re.search(r'needs topology = "([^"]+)"', reason)
            rows.append((LABEL.get(m, m), pc, NOT_IN_PAPER.get(m, "-"), None, what,
                         "needs topology \"%s\" (below)" % needs.group(1) if needs else "reason below"))

    support = os.environ.get("TABLE2_SUPPORT", "clamped")
    if first:
        print("The paper's Table 2 beside ours: %d molecules, %d connections, %s N on %g m^2, l0 = %g m, E target %s"
              % (first["molecules"], first["connections"], thousands(first["applied_force"]), first["cross_section"],
                 first["rest_length"], thousands(first["youngs_modulus_target"])))
        print("N/m^2, top face %s, %d ranks. The paper's errors are unsigned, ours signed (+ = too stiff)."
              % ("clamped (the paper's test)" if support == "clamped" else support, first["ranks"]))
        print()
    cell = "%10s %10s %8s"
    head = "%-19s | %s | %s | %s" % ("method", cell % ("paper: dl", "E", "error"), cell % ("ours: dl", "E", "error"),
                                    "note")
    print(head)
    print("%-19s | %s | %s |" % ("", cell % ("(mm)", "(N/m^2)", "(%)"), cell % ("(mm)", "(N/m^2)", "(%)")))
    print("-" * len(head))
    width = len(cell % ("", "", ""))
    for label, pc, missing, oc, what, note in rows:
        paper_cell = cell % pc if pc else "%-*s" % (width, missing)
        ours_cell = cell % oc if oc else "%-*s" % (width, what)
        print(("%-19s | %s | %s | %s" % (label, paper_cell, ours_cell, note)).rstrip())
    for n in notes:
        print(textwrap.fill(n, 115, initial_indent="  ", subsequent_indent="    "))


if __name__ == "__main__":
    main()
