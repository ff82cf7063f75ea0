#!/usr/bin/env python3
"""Scaling model of the explicit solver (docs/scaling.md): projected steps/s and parallel efficiency at 64 to
1024 ranks for 1M, 20M and 1B molecules of the peer lattice (face diagonals), from
  - the measured 1-rank step cost (CPU seconds per step at N = 100, docs/benchmarks.md 2026-11-29), spread over
    the connections a rank computes (those with an owned end: cut ones are computed on both sides);
  - the partition's ghost exchange, measured on the 100^3 lattice for 2..1024 parts by build/partition_table
    (METIS as `tissue` runs it, on one process): ghost molecules per part (24 bytes each per step) and
    neighbour parts (one message each per step);
  - a network: latency ALPHA, bandwidth BETA (default 1.5 us, 10 GB/s: InfiniBand HDR-class).
A larger body at the same rank count is the 100^3 partition scaled up (METIS's parts keep their shape): each
part's surface grows as L^2 and its volume as L^3, so ghosts/owned = (measured at 1M, same P) x (1M / n)^(1/3),
and the neighbour parts (messages) stay those measured at the same P.

Usage (from the repository root, after building): run_scripts/scaling_model.py [--step-seconds S] [--alpha A]
    [--beta B] [--table docs/scaling_partition.csv (reused if present; --remeasure runs partition_table)]
Writes docs/scaling_partition.csv, docs/scaling.csv and docs/scaling.png; prints the projection table.
Runs in about 10 s of CPU (the partition table at 10 part counts) plus the plot."""
import argparse
import csv
import math
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PARTS = [2, 4, 8, 16, 32, 64, 128, 256, 512, 1024]
SPRINGS_PER_MOLECULE_100 = 8850600 / 1e6  # the N = 100 lattice: 8,850,600 connections for 1,000,000 molecules
BYTES_PER_GHOST = 24                      # 3 doubles of position per ghost molecule per step


def measure_table(path, binary):
    out = subprocess.run([binary, "100"] + [str(p) for p in PARTS], check=True, capture_output=True, text=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(out.stdout)
    os.replace(tmp, path)


def read_table(path):
    with open(path) as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--step-seconds", type=float, default=0.0292,
                    help="1-rank CPU seconds per step at N = 100 (docs/benchmarks.md, 2026-11-29)")
    ap.add_argument("--alpha", type=float, default=1.5e-6, help="network latency per message, s")
    ap.add_argument("--beta", type=float, default=10e9, help="network bandwidth per rank, bytes/s")
    ap.add_argument("--table", default=os.path.join(ROOT, "docs", "scaling_partition.csv"))
    ap.add_argument("--binary", default=os.path.join(ROOT, "build", "partition_table"))
    ap.add_argument("--remeasure", action="store_true")
    args = ap.parse_args()
    if args.remeasure or not os.path.exists(args.table):
        measure_table(args.table, args.binary)
    table = read_table(args.table)

    # Per connection computed (kernel + the Verlet passes, amortized): the 1-rank step over its connections.
    t_conn = args.step_seconds / (SPRINGS_PER_MOLECULE_100 * 1e6)
    # Measured per part count: ghosts/owned, neighbour parts and connections computed per owned molecule
    # (worst part); the extra connections per ghost (cut ones computed on both sides) as one constant.
    by_parts = {int(r["parts"]): r for r in table}
    kappa = sum((r["max_local_connections"] / r["max_owned"] - SPRINGS_PER_MOLECULE_100) / r["max_ghosts_per_owned"]
                for r in table) / len(table)

    rows = []
    for n in (1_000_000, 20_000_000, 1_000_000_000):
        t1 = n * SPRINGS_PER_MOLECULE_100 * t_conn  # one rank (ideal: all in memory)
        for P in (64, 128, 256, 512, 1024):
            m = n / P
            g = by_parts[P]["max_ghosts_per_owned"] * (1e6 / n) ** (1.0 / 3.0)
            source = "measured" if n == 1_000_000 else "scaled"
            ghosts = g * m
            local = m * (SPRINGS_PER_MOLECULE_100 + kappa * g)
            t_comp = local * t_conn
            msgs = by_parts[P]["max_neighbour_parts"]
            t_comm = msgs * args.alpha + ghosts * BYTES_PER_GHOST / args.beta
            t_reduce = 2 * math.log2(P) * args.alpha / 16  # the guard's all-reduce, every 16 steps
            t_plain = t_comp + t_comm + t_reduce                  # as now: exchange, then the kernel
            t_overlap = max(t_comp, t_comm) + t_reduce            # interior connections during the exchange
            rows.append({
                "molecules": n, "ranks": P, "molecules_per_rank": round(m), "ghosts_per_owned": round(g, 5),
                "ghosts_source": source, "neighbour_parts": int(msgs), "message_bytes_per_step": round(ghosts * BYTES_PER_GHOST),
                "compute_s": t_comp, "exchange_s": t_comm + t_reduce,
                "steps_per_s": 1 / t_plain, "efficiency": t1 / (P * t_plain),
                "steps_per_s_overlap": 1 / t_overlap, "efficiency_overlap": t1 / (P * t_overlap),
            })
    out = os.path.join(ROOT, "docs", "scaling.csv")
    with open(out + ".tmp", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    os.replace(out + ".tmp", out)

    print(f"t_conn = {t_conn * 1e9:.3f} ns per connection-step; "
          f"extra connections per ghost kappa = {kappa:.3f}; alpha = {args.alpha * 1e6:.2f} us, "
          f"beta = {args.beta / 1e9:.1f} GB/s")
    print("| molecules | ranks | molecules/rank | ghosts/owned | neighbours | compute ms | exchange ms | steps/s | "
          "efficiency | steps/s (overlap) | efficiency (overlap) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['molecules']:,} | {r['ranks']} | {r['molecules_per_rank']:,} | {r['ghosts_per_owned']:.3f}"
              f"{'' if r['ghosts_source'] == 'measured' else ' (scaled)'} | {r['neighbour_parts']} | "
              f"{r['compute_s'] * 1e3:.3f} | {r['exchange_s'] * 1e3:.3f} | {r['steps_per_s']:.4g} | "
              f"{r['efficiency']:.2f} | {r['steps_per_s_overlap']:.4g} | {r['efficiency_overlap']:.2f} |")

    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("scaling_model: no matplotlib, no plot", file=sys.stderr)
        return
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for n, style, color in ((1_000_000, "o-", "C0"), (20_000_000, "s-", "C1"), (1_000_000_000, "^-", "C2")):
        sel = [r for r in rows if r["molecules"] == n]
        ranks = [r["ranks"] for r in sel]
        ax[0].loglog(ranks, [r["steps_per_s"] for r in sel], style, color=color, label=f"{n:,} molecules")
        ax[1].semilogx(ranks, [r["efficiency"] for r in sel], style, color=color, label=f"{n:,} molecules")
        ax[1].semilogx(ranks, [r["efficiency_overlap"] for r in sel], style, color=color, alpha=0.35)
    ax[0].set_xlabel("ranks"), ax[0].set_ylabel("steps/s (projected)"), ax[0].legend()
    ax[1].set_xlabel("ranks"), ax[1].set_ylabel("parallel efficiency (faint: with overlap)")
    ax[1].set_ylim(0, 1.05)
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"Explicit solver, face-diagonal lattice: {args.alpha * 1e6:.1f} us, {args.beta / 1e9:.0f} GB/s")
    fig.tight_layout()
    png = os.path.join(ROOT, "docs", "scaling.png")
    fig.savefig(png + ".tmp.png", dpi=110)
    os.replace(png + ".tmp.png", png)


if __name__ == "__main__":
    main()
