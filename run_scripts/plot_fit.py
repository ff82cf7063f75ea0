#!/usr/bin/env python3
"""Plot a `tissue fit` result: the measured curve (points) and the fitted scene's curve (line), with the fitted
values and their standard errors in the legend.

Usage: plot_fit.py DIR [PNG]      (DIR: the fit's output directory, with fit.json and the fitted run's
                                   history.csv; PNG defaults to DIR/fit.png)
"""
import csv
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

d = sys.argv[1]
png = sys.argv[2] if len(sys.argv) > 2 else os.path.join(d, "fit.png")
fit = json.load(open(os.path.join(d, "fit.json")))
x = fit["x"]
ys = fit["y"] if isinstance(fit["y"], list) else [fit["y"]]  # one y column, or several fitted together


def columns(path, y):
    rows = [r for r in csv.DictReader(open(path)) if r.get(x, "") != "" and r.get(y, "") != ""]
    return [float(r[x]) for r in rows], [float(r[y]) for r in rows]


items = ["%s = %.4g +- %s" % (k.split(".")[-2] + "_" + k.split(".")[-1] if k.split(".")[-1].isdigit()
                               else k.split(".")[-1], v,
                               "%.2g" % fit["standard_errors"][k] if fit["standard_errors"][k] is not None else "?")
         for k, v in fit["parameters"].items()]
label = ",\n".join(", ".join(items[i:i + 2]) for i in range(0, len(items), 2))  # two values a line
fig, axes = plt.subplots(len(ys), 1, figsize=(7, 3.2 + 1.3 * len(ys)), sharex=True, squeeze=False)
for ax, y in zip(axes[:, 0], ys):
    mx, my = columns(fit["data"], y)
    fx, fy = columns(os.path.join(d, "history.csv"), y)
    ax.plot(mx, my, "o", ms=3, color="tab:gray", label="measured (%s)" % os.path.basename(fit["data"]))
    ax.plot(fx, fy, "-", color="tab:blue", label="fitted: " + label)
    ax.set_ylabel(y)
    ax.legend(fontsize=8)
axes[-1, 0].set_xlabel(x)
axes[0, 0].set_title("tissue fit: %d forward runs, |r| = %.3g%s" % (
    fit["forward_runs"], fit["residual_norm"], "" if fit["identifiable"] else " (not identifiable)"))
fig.tight_layout()
fig.savefig(png, dpi=120)
print(png)
