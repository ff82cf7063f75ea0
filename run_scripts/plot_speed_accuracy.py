#!/usr/bin/env python3
"""Plots of run_scripts/speed_accuracy.sh's CSV, and the peer table.

Usage: plot_speed_accuracy.py docs/speed_accuracy.csv docs
Writes DIR/speed_accuracy_pareto.png (error against the converged static answer vs wall time, one panel per N, the
Pareto front of all our runs drawn), DIR/speed_accuracy_scaling.png (wall time vs molecules, log-log, with the
least-squares exponent over N >= 20 per solver), DIR/speed_accuracy_iterations.png (Newton, Krylov and FIRE
iterations vs N) and DIR/speed_accuracy_peer.csv (LAMMPS FIRE vs ours per N and peer rank count: elongations,
relative difference, times and ratios); prints the tables as Markdown.
"""
import csv
import math
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

path, outdir = sys.argv[1], sys.argv[2]
rows = list(csv.DictReader(open(path)))
for r in rows:
    for k in ("N", "molecules", "ranks", "newton_its", "krylov_its"):
        r[k] = int(float(r[k])) if r[k] not in ("", "None") else 0
    for k in ("wall_s", "process_s", "bytes_per_molecule", "elongation", "residual"):
        r[k] = float(r[k]) if r[k] not in ("", "None") else math.nan
    r["err"] = float(r["err_vs_static_ref"]) if r["err_vs_static_ref"] not in ("", "None") else math.nan
    r["label"] = f"{r['solver']} {r['config']}" + (f" {r['tolerance']}" if r["solver"] == "relaxation" else "")

sweep = [r for r in rows if r["case"] == "sweep"]
peer = [r for r in rows if r["case"] == "peer"]
FLOOR = 1e-13  # the reference run's error is 0: drawn at this floor

# 1. Pareto: error vs time, one panel per N.
ns = sorted({r["N"] for r in sweep})
if ns:
    fig, axes = plt.subplots(1, len(ns), figsize=(4.2 * len(ns), 4.2), squeeze=False)
    labels = sorted({r["label"] for r in sweep})
    colors = {lab: plt.cm.tab10(i % 10) for i, lab in enumerate(labels)}
    markers = {"static": "o", "relaxation": "s"}
    for ax, n in zip(axes[0], ns):
        pts = [r for r in sweep if r["N"] == n and r["config"] != "ref"]
        for r in pts:
            ax.loglog(r["wall_s"], max(r["err"], FLOOR), markers[r["solver"]], color=colors[r["label"]],
                      label=r["label"], ms=8)
        # the Pareto front: no other run is both faster and more accurate
        front = sorted((r["wall_s"], max(r["err"], FLOOR)) for r in pts)
        best, line = math.inf, []
        for t, e in front:
            if e < best:
                best = e
                line.append((t, e))
        if line:
            ax.loglog(*zip(*line), "k--", lw=1, alpha=0.6)
        ax.axhline(1e-6, color="r", lw=0.8, ls=":")
        ax.set_title(f"N = {n} ({n**3:,} molecules)")
        ax.set_xlabel("wall time [s] (2 ranks)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("|elongation - converged static| / converged static")
    handles, labs = axes[0][0].get_legend_handles_labels()
    uniq = dict(zip(labs, handles))
    fig.legend(uniq.values(), uniq.keys(), loc="lower center", ncol=len(uniq), fontsize=8)
    fig.suptitle("Error vs time (dashed: Pareto front; dotted red: the 1e-6 target)")
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    fig.savefig(os.path.join(outdir, "speed_accuracy_pareto.png"), dpi=110)
    plt.close(fig)

# 2. Scaling: time vs molecules, log-log, with the fitted exponent.
fits = {}
fig, ax = plt.subplots(figsize=(7.5, 5.5))
groups = defaultdict(list)
for r in sweep:
    if r["config"] != "ref":
        groups[r["label"]].append((r["molecules"], r["wall_s"]))
for i, (lab, pts) in enumerate(sorted(groups.items())):
    pts.sort()
    x, y = zip(*pts)
    fit = [(math.log(a), math.log(b)) for a, b in pts if a >= 20**3]
    slope = ""
    if len(fit) >= 2:
        mx = sum(a for a, _ in fit) / len(fit)
        my = sum(b for _, b in fit) / len(fit)
        p = sum((a - mx) * (b - my) for a, b in fit) / sum((a - mx) ** 2 for a, _ in fit)
        fits[lab] = p
        slope = f" (t ~ n^{p:.2f})"
    ax.loglog(x, y, "o-" if lab.startswith("static") else "s--", color=plt.cm.tab10(i % 10), label=lab + slope)
lammps = defaultdict(list)
for r in peer:
    if r["solver"] == "lammps_fire":
        lammps[r["config"]].append((r["molecules"], r["wall_s"]))
for cfg, pts in sorted(lammps.items()):
    pts.sort()
    ax.loglog(*zip(*pts), "k^:", ms=9, label=f"LAMMPS FIRE {cfg} (loop time)",
              alpha=1.0 if cfg == "np2" else 0.5)
ax.set_xlabel("molecules")
ax.set_ylabel("wall time [s]")
ax.set_title("Time to equilibrium vs size (ours: 2 ranks, whole run; exponents fitted over N >= 20)")
ax.title.set_fontsize(9)
ax.grid(True, which="both", alpha=0.3)
ax.legend(fontsize=8)
fig.tight_layout()
fig.savefig(os.path.join(outdir, "speed_accuracy_scaling.png"), dpi=110)
plt.close(fig)

# 3. Iterations vs N.
fig, ax = plt.subplots(figsize=(7.5, 5.5))
for i, (lab, key, style) in enumerate([
        ("static mg", "newton_its", "o-"), ("static mg", "krylov_its", "o--"),
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
mg = sorted((r["N"], r["krylov_its"]) for r in sweep if r["label"] == "static mg")
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
print("\n| N | molecules | run | wall s | B/molecule | Newton/FIRE its | Krylov its | residual | err vs converged | err vs E target |")
print("|---|---|---|---|---|---|---|---|---|---|")
for r in sweep:
    print(f"| {r['N']} | {r['molecules']:,} | {r['label']} | {r['wall_s']:.3g} | {r['bytes_per_molecule']:.0f} | "
          f"{r['newton_its']} | {r['krylov_its']} | {r['residual']:.2g} | {r['err']:.2g} | "
          f"{float(r['err_vs_E_target']):.3g} |")
if fits:
    print("\nFitted exponents t ~ molecules^p (N >= 20): " + ", ".join(f"{k}: {v:.2f}" for k, v in sorted(fits.items())))
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
