#!/usr/bin/env python3
"""Plot docs/convergence.csv (run_scripts/convergence.sh): |error in E| against molecule count, log-log.

Usage: plot_convergence.py CSV PNG

Two panels: roller supports (error against the material's E) and clamped (error against E, dash-dotted line at
the continuum's own clamped-cube reading +2.05%). One colour per method, one marker and line style per topology.
Errors at round-off (exact methods) are drawn at the 1e-10 % floor; failed solves (exit code != 0) are left out.
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

csv_path, png_path = sys.argv[1], sys.argv[2]
rows = [r for r in csv.DictReader(open(csv_path)) if r["E"] and r["exit_code"] == "0"]  # failed solves left out
colors = {"linear": "tab:blue", "homogenized": "tab:green", "tetrahedral": "tab:purple", "iterative": "tab:orange",
          "statistical": "tab:red"}
markers = {"face-diagonals": "o", "body-diagonals": "s", "tetrahedral": "^"}
styles = {"face-diagonals": "-", "body-diagonals": "--", "tetrahedral": ":"}
floor = 1e-10

fig, axes = plt.subplots(1, 2, figsize=(13, 5.5), sharey=True)
for ax, support in zip(axes, ["roller", "clamped"]):
    series = {}
    for r in rows:
        if r["support"] != support:
            continue
        series.setdefault((r["method"], r["topology"]), []).append((int(r["molecules"]), float(r["error_percent"])))
    for (method, topology), pts in sorted(series.items()):
        pts.sort()
        x = [p[0] for p in pts]
        y = [max(abs(p[1]), floor) for p in pts]
        ax.loglog(x, y, styles[topology], marker=markers[topology], color=colors.get(method, "k"), ms=4,
                  label="%s, %s" % (method, topology))
    if support == "clamped":
        ax.axhline(2.05, color="k", lw=0.8, ls="-.", label="continuum, clamped cube: +2.05%")
        ax.set_title("top face clamped (the paper's test): |E error| vs target E")
    else:
        ax.set_title("roller supports (the material): |E error| vs target E")
    ax.set_xlabel("molecules (n^3)")
    ax.grid(True, which="both", alpha=0.3)
axes[0].set_ylabel("|error in E| (%)  (round-off drawn at 1e-10)")
handles, labels = [], []
for ax in axes:  # every series of both panels, once
    for h, l in zip(*ax.get_legend_handles_labels()):
        if l not in labels:
            handles.append(h), labels.append(l)
fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=7, frameon=False)
fig.tight_layout(rect=(0, 0.17, 1, 1))
fig.savefig(png_path, dpi=110)
print("wrote", png_path)
