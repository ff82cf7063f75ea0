#!/usr/bin/env python3
"""Plots of run_scripts/speed_accuracy.sh's CSV, the fitted cost exponents, and the peer table.

Usage: plot_speed_accuracy.py docs/speed_accuracy.csv docs [DYNAMIC_CSV]
Reads the CSV, DYNAMIC_CSV (default DIR/speed_accuracy_dynamic.csv: the damped dynamic runs' error against steps,
when present) and
DIR/bench_static_huge.csv (run_scripts/bench_static_huge.sh's matrix-free runs up to 2 x 10^7 molecules, when
present). Writes
  DIR/speed_accuracy_pareto.png: per N, the error against the converged static answer (top) and the relative force
    residual (bottom) vs CPU seconds of all ranks (the load-robust time; wall times are in the CSV), our runs and the
    Pareto front (no other run both cheaper and more accurate); the dynamic run is a curve (its error every few
    steps; it reports no residual),
  DIR/speed_accuracy_pareto_memory.png: the same error vs peak bytes a molecule,
  DIR/speed_accuracy_scaling.png: CPU time, wall time and peak memory (largest rank x ranks) vs molecules, log-log,
    with the least-squares exponent over >= 10^4 molecules per solver (run_scripts/speed_accuracy_fit.py),
  DIR/speed_accuracy_exponents.csv: those exponents,
  DIR/speed_accuracy_iterations.png (Newton, Krylov and FIRE iterations vs N) and DIR/speed_accuracy_peer.csv
    (LAMMPS FIRE vs ours per N and peer rank count, when the CSV has peer rows),
and prints the tables as Markdown.
"""
import csv
import math
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from speed_accuracy_fit import power_law_fit  # noqa: E402

path, outdir = sys.argv[1], sys.argv[2]
FIT_MIN = 1e4  # molecules: below, the libraries' fixed start-up cost dominates time and memory


def num(v):
    return float(v) if v not in ("", "None", None) else math.nan


rows = list(csv.DictReader(open(path)))
CONFIG_NAME = {"mg": "mg (assembled)", "mf": "mg (matrix-free)", "gamg": "gamg", "hypre": "hypre",
               "jacobi": "jacobi", "ref": "ref", "fire": "fire", "damped": "damped to rest"}
for r in rows:
    for k in ("N", "molecules", "ranks", "newton_its", "krylov_its"):
        r[k] = int(float(r[k])) if r[k] not in ("", "None") else 0
    for k in ("wall_s", "process_s", "bytes_per_molecule", "elongation", "residual", "cpu_s", "peak_bytes"):
        r[k] = num(r.get(k))
    r["err"] = num(r["err_vs_static_ref"])
    r["label"] = f"{r['solver']} {CONFIG_NAME.get(r['config'], r['config'])}" + (
        f" {r['tolerance']}" if r["solver"] == "relaxation" else "")

sweep = [r for r in rows if r["case"] == "sweep"]
big = [r for r in rows if r["case"] == "big"]
peer = [r for r in rows if r["case"] == "peer"]
dyn = defaultdict(list)  # N -> [(est_cpu_s, est_wall_s, err, step)]
dyn_path = sys.argv[3] if len(sys.argv) > 3 else os.path.join(outdir, "speed_accuracy_dynamic.csv")
if os.path.exists(dyn_path):
    for r in csv.DictReader(open(dyn_path)):
        if int(r["step"]) > 0:
            dyn[int(r["N"])].append((num(r["est_cpu_s"]), num(r["est_wall_s"]), num(r["err_vs_static_ref"]),
                                     int(r["step"])))
huge = []
huge_path = os.path.join(outdir, "bench_static_huge.csv")
if os.path.exists(huge_path):
    huge = [r for r in csv.DictReader(open(huge_path))]
FLOOR = 1e-13  # an error of 0 (the reference run's, or a run equal to it) is drawn at this floor
labels = sorted({r["label"] for r in sweep + big if r["config"] != "ref"})
colors = {lab: plt.cm.tab10(i % 10) for i, lab in enumerate(labels)}
MARK = {"static": "o", "relaxation": "s", "dynamic": "D"}


def front(points):
    """The Pareto front of (cost, error) points: no other point is both cheaper and more accurate."""
    best, line = math.inf, []
    for t, e in sorted(points):
        if e < best:
            best = e
            line.append((t, e))
    return line


def tick_125(v, _):
    """A log axis label at 1, 2 and 5 times a power of ten only (readable on panels spanning under a decade)."""
    if v <= 0:
        return ""
    m = v / 10 ** math.floor(math.log10(v) + 1e-9)
    return f"{v:g}" if min(abs(m - k) for k in (1, 2, 5)) < 1e-6 else ""


def legend_below(fig, axes):
    seen = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(lab, h)
    fig.legend(seen.values(), seen.keys(), loc="lower center", ncol=min(5, len(seen)), fontsize=9)
    return len(seen)


# 1. Pareto: error and residual vs CPU time, one column per N; error vs memory.
ns = sorted({r["N"] for r in sweep if r["config"] != "ref"})
if ns:
    fig, axes = plt.subplots(2, len(ns), figsize=(max(3.9 * len(ns), 11), 8.8), squeeze=False)
    figm, axm = plt.subplots(1, len(ns), figsize=(max(3.9 * len(ns), 11), 5.0), squeeze=False)
    for col, n in enumerate(ns):
        pts = [r for r in sweep if r["N"] == n and r["config"] != "ref"]
        ax_e, ax_r, ax_m = axes[0][col], axes[1][col], axm[0][col]
        for r in pts:
            m, c = MARK[r["solver"]], colors[r["label"]]
            ax_e.loglog(r["cpu_s"], max(r["err"], FLOOR), m, color=c, label=r["label"], ms=7)
            if math.isfinite(r["residual"]):
                ax_r.loglog(r["cpu_s"], r["residual"], m, color=c, label=r["label"], ms=7)
            ax_m.loglog(r["bytes_per_molecule"], max(r["err"], FLOOR), m, color=c, label=r["label"], ms=7)
        curve = sorted(dyn.get(n, []), key=lambda p: p[3])
        dlab = next((r["label"] for r in pts if r["solver"] == "dynamic"), "dynamic damped to rest")
        if curve:
            ax_e.loglog([p[0] for p in curve], [max(p[2], FLOOR) for p in curve], "-", lw=1,
                        color=colors.get(dlab, "grey"), label=dlab + " (every few steps)")
        err_pts = [(r["cpu_s"], max(r["err"], FLOOR)) for r in pts if math.isfinite(r["err"])]
        err_pts += [(p[0], max(p[2], FLOOR)) for p in curve if math.isfinite(p[2])]
        for ax, fp in ((ax_e, err_pts),
                       (ax_r, [(r["cpu_s"], r["residual"]) for r in pts if math.isfinite(r["residual"])]),
                       (ax_m, [(r["bytes_per_molecule"], max(r["err"], FLOOR)) for r in pts
                               if math.isfinite(r["err"])])):
            line = front(fp)
            if line:
                ax.loglog(*zip(*line), "k--", lw=1, alpha=0.6, label="Pareto front")
            ax.grid(True, which="both", alpha=0.3)
            # 1, 2, 5, 10, ... labelled: a panel may span less than a decade
            ax.xaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
            for fmt in (ax.xaxis.set_major_formatter, ax.xaxis.set_minor_formatter):
                fmt(FuncFormatter(tick_125))
        ax_e.axhline(1e-6, color="r", lw=0.8, ls=":")
        ax_m.axhline(1e-6, color="r", lw=0.8, ls=":")
        ax_e.set_ylim(bottom=FLOOR / 3)
        ax_e.set_title(f"N = {n} ({n**3:,} molecules)")
        ax_m.set_title(f"N = {n} ({n**3:,} molecules)")
        ax_r.set_xlabel("CPU time, all ranks [s]")
        ax_m.set_xlabel("peak memory [B / molecule]")
    axes[0][0].set_ylabel("elongation error vs converged static\n(0 drawn at 1e-13)")
    axes[1][0].set_ylabel("relative force residual")
    axm[0][0].set_ylabel("elongation error vs converged static")
    k = legend_below(fig, list(axes[0]) + list(axes[1]))
    fig.suptitle("Accuracy vs CPU time, 2 ranks (dashed: Pareto front; dotted red: error 1e-6)\n"
                 "top: elongation error against the converged static answer; bottom: relative force residual "
                 "(the dynamic solver reports none)")
    fig.tight_layout(rect=(0, 0.035 * (1 + (k - 1) // 5), 1, 0.96))
    fig.savefig(os.path.join(outdir, "speed_accuracy_pareto.png"), dpi=90)
    plt.close(fig)
    k = legend_below(figm, list(axm[0]))
    figm.suptitle("Accuracy vs memory, 2 ranks (peak of the largest rank x 2 / molecules; dashed: Pareto front)")
    figm.tight_layout(rect=(0, 0.07 * (1 + (k - 1) // 5), 1, 0.93))
    figm.savefig(os.path.join(outdir, "speed_accuracy_pareto_memory.png"), dpi=90)
    plt.close(figm)

# 2. Cost curves: CPU time, wall time, memory vs molecules, log-log, fitted exponents (>= 10^4 molecules).
fits = []  # (series, quantity, exponent, points, molecules min, max, source)
series = defaultdict(list)
for r in sweep + big:
    if r["config"] != "ref":
        series[r["label"]].append(r)
QUANT = [("cpu_s", "CPU time, all ranks [s]"), ("wall_s", "wall time [s]"), ("peak_bytes_total", "peak memory [B]")]
fig, axes = plt.subplots(1, 3, figsize=(17, 9.0))
for i, (lab, rs) in enumerate(sorted(series.items())):
    rs.sort(key=lambda r: r["molecules"])
    for ax, (q, _) in zip(axes, QUANT):
        pts = [(r["molecules"], r["bytes_per_molecule"] * r["molecules"] if q == "peak_bytes_total" else r[q])
               for r in rs]
        f = power_law_fit(pts, FIT_MIN)
        tag = ""
        if f:
            mol = [x for x, _ in pts if x >= FIT_MIN]
            fits.append((lab, q, f[0], f[2], min(mol), max(mol), "speed_accuracy.csv"))
            tag = f" (^{f[0]:.2f})"
        ax.loglog(*zip(*pts), MARK[rs[0]["solver"]] + ("-" if rs[0]["solver"] == "static" else "--"),
                  color=colors[lab], ms=5, label=lab + tag)
if huge:
    # bench_static_huge.sh: matrix-free static to 1e-8 on 2 ranks, no CPU time recorded. Only its rows from
    # HUGE_SINCE on are drawn (the binary of this sweep's time: its earlier rows are an older binary's memory); its
    # memory joins the sweep's matrix-free points in one more fit; its wall time (another load) is not fitted.
    since = os.environ.get("HUGE_SINCE", "2026-12-02T14:00")
    hs = [r for r in huge if r["date"] >= since]
    mf = [r for r in sweep + big if r["label"] == "static mg (matrix-free)"]
    for r in hs:
        when = f"{r['date'].replace('T', ' ')} UTC, load {float(r['loadavg']):.2g}"
        lab = f"static mg (matrix-free), bench_static_huge.sh, {when}"
        m = int(r["molecules"])
        axes[1].loglog(m, float(r["wall_s"]), "k*", ms=11, label=lab)
        axes[2].loglog(m, float(r["bytes_per_molecule"]) * m, "k*", ms=11, label=lab)
    if hs and mf:
        pts = [(r["molecules"], r["bytes_per_molecule"] * r["molecules"]) for r in mf]
        pts += [(int(r["molecules"]), float(r["bytes_per_molecule"]) * int(r["molecules"])) for r in hs]
        f = power_law_fit(pts, FIT_MIN)
        if f:
            mol = [x for x, _ in pts if x >= FIT_MIN]
            fits.append(("static mg (matrix-free) + bench_static_huge", "peak_bytes_total", f[0], f[2], min(mol),
                         max(mol), "speed_accuracy.csv + bench_static_huge.csv"))
            pts = sorted(p for p in pts if p[0] >= FIT_MIN)
            c = f[1]
            axes[2].loglog([pts[0][0], pts[-1][0]], [c * pts[0][0] ** f[0], c * pts[-1][0] ** f[0]], "k:", lw=1,
                           label=f"fit: matrix-free + bench_static_huge (^{f[0]:.2f})")
for ax, (q, what) in zip(axes, QUANT):
    ax.set_xlabel("molecules")
    ax.set_ylabel(what)
    ax.grid(True, which="both", alpha=0.3)
    # below the panel: the curves fill the whole panel
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1)
axes[0].set_title("CPU time (the load-robust one)")
axes[1].set_title("wall time (shared machine: see the load column)")
axes[2].set_title("peak memory (largest rank x ranks)")
fig.suptitle("Cost vs size, 2 ranks; (^p): least-squares exponent over >= 10^4 molecules")
fig.tight_layout(rect=(0, 0, 1, 0.95))
fig.savefig(os.path.join(outdir, "speed_accuracy_scaling.png"), dpi=90)
plt.close(fig)
if fits:
    with open(os.path.join(outdir, "speed_accuracy_exponents.csv") + ".tmp", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["series", "quantity", "exponent", "points", "molecules_min", "molecules_max", "source"])
        for row in fits:
            w.writerow([row[0], row[1], f"{row[2]:.3f}", row[3], row[4], row[5], row[6]])
    os.replace(os.path.join(outdir, "speed_accuracy_exponents.csv") + ".tmp",
               os.path.join(outdir, "speed_accuracy_exponents.csv"))

# 3. Iterations vs N.
fig, ax = plt.subplots(figsize=(7.5, 5.5))
for i, (lab, key, style) in enumerate([
        ("static mg (assembled)", "newton_its", "o-"), ("static mg (assembled)", "krylov_its", "o--"),
        ("static mg (matrix-free)", "krylov_its", "x--"),
        ("static gamg", "newton_its", "P-"), ("static gamg", "krylov_its", "P--"),
        ("static hypre", "krylov_its", "v--"), ("static jacobi", "krylov_its", "D--"),
        ("relaxation fire 1e-8", "newton_its", "s-")]):
    pts = sorted((r["N"], r[key]) for r in sweep if r["label"] == lab)
    if pts:
        what = {"newton_its": "Newton" if lab.startswith("static") else "FIRE", "krylov_its": "Krylov"}[key]
        ax.loglog(*zip(*pts), style, label=f"{lab}: {what} iterations")
pts = sorted((r["N"], r["newton_its"]) for r in peer if r["solver"] == "lammps_fire" and r["config"] == "np1")
if pts:
    ax.loglog(*zip(*pts), "k^:", ms=9, label="LAMMPS FIRE (ftol 1e-8): iterations")
mg = sorted((r["N"], r["krylov_its"]) for r in sweep if r["label"] == "static mg (assembled)")
if mg:
    # the "no faster than log N" yardstick, through the smallest N's Krylov count
    n0, k0 = mg[0]
    xs = [n for n, _ in mg]
    ax.loglog(xs, [k0 * math.log(n) / math.log(n0) for n in xs], "k:", lw=1, label="log N (through mg's first point)")
ax.set_xlabel("N (molecules per axis)")
ax.set_ylabel("iterations (Krylov: summed over Newton iterations)")
ax.set_title("Iterations vs N")
ax.grid(True, which="both", alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(outdir, "speed_accuracy_iterations.png"), dpi=110)
plt.close(fig)

# 4. The peer table.
out = []
for r in peer:
    if r["solver"] != "lammps_fire":
        continue
    n = r["N"]
    ref = [s for s in rows if s["N"] == n and s["config"] == "ref"]
    # ours: the static runs of the same N just before and after this LAMMPS run (alternation), and the peer
    # case's relaxation run
    idx = rows.index(r)
    near = [s for s in rows[max(0, idx - 1): idx + 2] if s["case"] == "peer" and s["solver"] == "static" and s["N"] == n]
    rx = next((s for s in rows[idx:] if s["case"] == "peer" and s["solver"] == "relaxation" and s["N"] == n), None)
    if not near:
        continue
    st = dict(near[0])
    st["wall_s"] = sum(s["wall_s"] for s in near) / len(near)
    st["cpu"] = sum(float(s.get("cpu_s") or "nan") for s in near) / len(near)
    if rx is None:
        rx = {"elongation": math.nan, "wall_s": math.nan, "newton_its": 0}
    out.append({
        "N": n, "molecules": n**3, "lammps_ranks": r["ranks"], "our_ranks": st["ranks"],
        "lammps_elongation": repr(r["elongation"]), "static_elongation": repr(st["elongation"]),
        "relaxation_elongation": repr(rx["elongation"]),
        "lammps_vs_static_rel": abs(r["elongation"] - st["elongation"]) / abs(st["elongation"]),
        "lammps_vs_ref_rel": abs(r["elongation"] - ref[0]["elongation"]) / abs(ref[0]["elongation"]) if ref else "",
        "lammps_loop_s": r["wall_s"], "lammps_process_s": r["process_s"], "lammps_iterations": r["newton_its"],
        "static_wall_s": st["wall_s"], "relaxation_wall_s": rx["wall_s"], "relaxation_iterations": rx["newton_its"],
        "speedup_static": r["wall_s"] / st["wall_s"], "speedup_relaxation": r["wall_s"] / rx["wall_s"],
        "lammps_B_per_molecule": r["bytes_per_molecule"], "static_B_per_molecule": st["bytes_per_molecule"],
        "lammps_cpu_s": float(r.get("cpu_s") or "nan"), "static_cpu_s": st["cpu"],
        "cpu_ratio_static": float(r.get("cpu_s") or "nan") / st["cpu"],
    })
if out:
    with open(os.path.join(outdir, "speed_accuracy_peer.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(out[0]))
        w.writeheader()
        w.writerows(out)

# 5. Markdown to stdout.
print("\n| N | molecules | run | wall s | CPU s | B/molecule | Newton/FIRE its, steps | Krylov its | residual | "
      "err vs converged | load |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for r in sweep + big:
    res = f"{r['residual']:.2g}" if math.isfinite(r["residual"]) else "-"
    err = f"{r['err']:.2g}" if math.isfinite(r["err"]) else "-"
    print(f"| {r['N']} | {r['molecules']:,} | {r['label']} | {r['wall_s']:.3g} | {r['cpu_s']:.3g} | "
          f"{r['bytes_per_molecule']:.0f} | {r['newton_its']} | {r['krylov_its']} | {res} | {err} | {r['loadavg']} |")
if fits:
    print("\n| series | quantity | exponent (>= 10^4 molecules) | points | molecules |")
    print("|---|---|---|---|---|")
    for row in fits:
        print(f"| {row[0]} | {row[1]} | {row[2]:.2f} | {row[3]} | {row[4]:,} - {row[5]:,} |")
for n, curve in sorted(dyn.items()):
    # the dynamic run's cost to reach each accuracy: the first step whose error is at or below it
    hits = []
    for target in (1e-2, 1e-4, 1e-6, 1e-8):
        p = next((p for p in sorted(curve, key=lambda p: p[3]) if p[2] <= target), None)
        hits.append(f"{target:g}: step {p[3]}, {p[0]:.3g} CPU s" if p else f"{target:g}: not reached")
    print(f"dynamic N = {n}: " + "; ".join(hits))
if out:
    print("\n| N | LAMMPS ranks | LAMMPS loop s | LAMMPS its | ours static s | ours relax s (its) | speed-up static | "
          "speed-up relax | LAMMPS vs ours elongation | LAMMPS vs converged | CPU s LAMMPS / ours static |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for o in out:
        print(f"| {o['N']} | {o['lammps_ranks']} | {o['lammps_loop_s']:.3g} | {o['lammps_iterations']} | "
              f"{o['static_wall_s']:.3g} | {o['relaxation_wall_s']:.3g} ({o['relaxation_iterations']}) | "
              f"{o['speedup_static']:.2f}x | {o['speedup_relaxation']:.2f}x | {o['lammps_vs_static_rel']:.2g} | "
              f"{o['lammps_vs_ref_rel'] if o['lammps_vs_ref_rel'] == '' else format(o['lammps_vs_ref_rel'], '.2g')} | "
              f"{o['lammps_cpu_s']:.3g} / {o['static_cpu_s']:.3g} |")
