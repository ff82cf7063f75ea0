#!/usr/bin/env python3
"""The ligament examples' stress-strain curves (docs/anisotropy.md): nominal stress (applied force over the rest
cross-section) against the mean strain (elongation over the rest length), from DIR/history.csv of quasi-static
load ramps (aligned fibres, then fanned margins), with the toe's end and a line of slope E_L.

  python3 run_scripts/plot_anisotropy.py OUT.png ALIGNED_DIR FANNED_DIR AREA LENGTH TOE_STRETCH E_L
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) != 8:
        sys.exit(__doc__)
    out, aligned, fanned = sys.argv[1], sys.argv[2], sys.argv[3]
    area, length, toe, E_L = (float(x) for x in sys.argv[4:])
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    curves = {}
    for directory, label in ((aligned, "fibres along the axis"), (fanned, "margins fanned by 15 degrees")):
        with open(os.path.join(directory, "history.csv"), newline="") as f:
            rows = list(csv.DictReader(f))
        strain = [100 * float(r["elongation"]) / length for r in rows]
        stress = [float(r["force_x"]) / area / 1e6 for r in rows]
        ax.plot(strain, stress, "o-", ms=3, label=label)
        curves[directory] = (strain, stress)
    # The linear part: slope E_L through the aligned strip's last point.
    strain, stress = curves[aligned]
    s1, e1 = stress[-1], strain[-1]
    xs = [e1 - 2.0, e1]
    ax.plot(xs, [s1 - E_L / 1e6 * (e1 - x) / 100 for x in xs], "--", color="grey", label=f"slope E_L = {E_L / 1e6:g} MPa")
    ax.axvline(100 * (toe - 1), color="tab:red", lw=0.8, ls=":", label=f"fibre stretch {toe} (end of the toe)")
    ax.set_ylim(bottom=0)
    ax.set_xlabel("strain (%)")
    ax.set_ylabel("nominal stress (MPa)")
    ax.set_title("Ligament strip (preset, exp-linear toe) pulled along its axis")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(out + ".tmp.png", dpi=110)
    os.replace(out + ".tmp.png", out)


if __name__ == "__main__":
    main()
