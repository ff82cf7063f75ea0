#!/usr/bin/env python3
"""The paper's Table 2 beside ours, one row per calibration method (main_job.sh prints it).

    python3 run_scripts/table2_side_by_side.py OUT_DIR METHOD...

OUT_DIR holds one directory per method (OUT_DIR/<method>/summary.json, written by the run) and, next to it,
OUT_DIR/<method>.log (the run's output) and OUT_DIR/<method>.status ("<exit code> <solver>"). The paper's
figures come from run_scripts/paper_values.csv (the one copy, also read by paper_tables.sh); ours only from the
runs' summary.json. Standard library only.
"""
import csv
import json
import os
import sys

LABEL = {"linear": "Linear case", "tetrahedral": "Tetrahedral (Eq. 5)", "divided": "k / 3.75 (divided)",
         "angles": "Angles", "angles-update": "Angles (update)", "statistical": "Statistical",
         "iterative": "Iterative", "homogenized": "Homogenized (ours)", "lloyd": "Lloyd 2007", "manual": "Manual"}
# What the paper says where Table 2 has no row for a method.
NOT_IN_PAPER = {"tetrahedral": "not implemented in the paper",
                "angles-update": "not in Table 2 (Table 1 only)"}


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
            what = "n/a: refused (exit 2)" if rc == 2 else "failed (exit %d)" % rc
            notes.append("%s: %s" % (m, reason))
            rows.append((LABEL.get(m, m), pc, NOT_IN_PAPER.get(m, "-"), None, what, "see below"))

    if first:
        fix = "clamped (the paper's test)"
        print("Table 2 of Maciel, Boulic & Thalmann beside ours: %d molecules, %d connections, %.0f N on %.3g m^2, "
              "l0 = %.3g m," % (first["molecules"], first["connections"], 1000.0, first["cross_section"],
                                first["rest_length"]))
        print("E target %s N/m^2, top face %s, %d ranks. Paper errors are unsigned, ours signed "
              "(+ = too stiff)." % (thousands(first["youngs_modulus_target"]), fix, first["ranks"]))
    print()
    head = "%-20s | %-33s | %-33s | %s" % ("method", "paper: dl (mm)   E (N/m^2)  error %",
                                          "ours:  dl (mm)   E (N/m^2)  error %", "note")
    print(head)
    print("-" * len(head))
    for label, pc, missing, oc, what, note in rows:
        paper_cell = "%13s %11s %8s" % pc if pc else "%-33s" % missing
        ours_cell = "%13s %11s %8s" % oc if oc else "%-33s" % what
        print(("%-20s | %s | %s | %s" % (label, paper_cell, ours_cell, note)).rstrip())
    for n in notes:
        print("  " + n)


if __name__ == "__main__":
    main()
