#!/usr/bin/env python3
"""Plots DIR/history.csv of tissue runs: force and elongation against time, or a reaction against time.

  python3 run_scripts/plot_history.py OUT.png TITLE DIR:COLUMN[:LABEL] ...

Each DIR:COLUMN is one curve against `time` (a column of DIR/history.csv: elongation, force_z, reaction1_z, ...),
each on its own axis, stacked. Needs python3-matplotlib.
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read(directory):
    with open(f"{directory}/history.csv", newline="") as f:
        return list(csv.DictReader(f))


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out, title, curves = sys.argv[1], sys.argv[2], sys.argv[3:]
    fig, axes = plt.subplots(len(curves), 1, figsize=(6.4, 2.6 * len(curves)), sharex=True, squeeze=False)
    for ax, spec in zip(axes[:, 0], curves):
        directory, column, *label = spec.split(":")
        rows = read(directory)
        t = [float(r["time"]) for r in rows]
        y = [float(r[column]) if r[column] else float("nan") for r in rows]
        ax.plot(t, y, ".-", ms=3)
        ax.set_ylabel(label[0] if label else column)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].set_title(title)
    fig.tight_layout()
    fig.savefig(out + ".tmp.png", dpi=110)
    import os

    os.replace(out + ".tmp.png", out)  # atomically: a reader never sees half a picture


if __name__ == "__main__":
    main()
