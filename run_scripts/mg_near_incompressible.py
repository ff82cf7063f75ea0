#!/usr/bin/env python3
"""Why the lattice multigrid's Krylov counts grow as nu -> 1/2 (issue 15, docs/poisson.md "Static solves near
nu = 1/2"): a small model of the static solver's linear problem, solved with the same multigrid shape, trying
coarse operators and smoothers that the C++ code does not have, to see which one keeps the counts flat before
building it.

The model: an N^3 face-diagonal lattice of linear springs (edges and face diagonals, stiffness h/2 each: the
isotropic set, lambda_s = mu_s = 1/2), plus the cell term's volumetric part at small strain, one per cell of its
one-point (cell-centre) gradient: lambda_c V (tr eps)^2 / 2 with lambda_c = mu (2 nu / (1 - 2 nu) - 1), so
springs + cells are the isotropic (lambda, mu) of Poisson ratio nu (docs/poisson.md "The route"). Base clamped,
unit force along z on every top molecule. CG preconditioned by one V-cycle: levels keep every other lattice plane,
trilinear interpolation (src/solvers/lattice_mg.cpp), coarsest level solved directly; smoother Chebyshev over
[f, 1.1] x the largest eigenvalue of M^-1 A (power iterations), 2 steps, M one of:
  jacobi  the diagonal (the C++ default, f = 0.1)
  cell    additive Schwarz over the 8 molecules of every cell (24 x 24 blocks, overlapping; assembled, M has the
          tangent's 27-point pattern)
  star    additive Schwarz over the 27 molecules around every molecule (81 x 81 blocks; M is a 125-point stencil)
Coarse operators: galerkin (P^T A P, what src/solvers/lattice_galerkin.cpp computes) or redisc (springs by
Galerkin, the cell term rediscretized on the coarse cells, same lambda_c, one-point).

--mixed instead solves the mixed form with one pressure per cell, p = lambda_c V div u (the volumetric part kept
out of the multigrid): MINRES preconditioned by diag(one V-cycle of the springs-only, nu = 1/4, operator with the
smoother above, the cell-diagonal Schur complement V (1 / w + 1 / lambda_c)), w = --schur (lambda_s + 2 mu_s = 1.5).

Prints, for nu = 0.25 / 0.45 / 0.49, the Krylov iterations to a relative residual of 1e-8.
Needs numpy and scipy (Debian: python3-numpy python3-scipy). About a minute at N = 17 (star: a few).
  /usr/bin/python3 run_scripts/mg_near_incompressible.py [N] [--smoother jacobi|cell|star] [--coarse galerkin|redisc]
      [--steps S] [--fraction F] [--mixed [--schur W]]
"""
import argparse

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def node(n, i, j, k):
    return i + n * (j + n * k)


def coo(rows, cols, vals, size):
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(size, size))


def springs(n, h):
    """Edges and face diagonals, stiffness h/2 each (a spring of length L and stiffness k adds k L^2 e e e e / h^3
    to the elastic tensor: edges 1/2 to C11, face diagonals 1/2 to C11, C12 and C44: isotropic, lambda = mu = 1/2)."""
    dirs = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1)]
    i, j, k = (a.ravel() for a in np.meshgrid(range(n), range(n), range(n), indexing="ij"))
    rows, cols, vals = [], [], []
    for d in dirs:
        e = np.array(d, float) / np.linalg.norm(d)
        keep = (i + d[0] >= 0) & (i + d[0] < n) & (j + d[1] >= 0) & (j + d[1] < n) & (k + d[2] < n) & (k + d[2] >= 0)
        a = node(n, i[keep], j[keep], k[keep])
        b = node(n, i[keep] + d[0], j[keep] + d[1], k[keep] + d[2])
        block = 0.5 * h * np.outer(e, e)
        for p in range(3):
            for q in range(3):
                for r, c, s in ((a, a, 1), (b, b, 1), (a, b, -1), (b, a, -1)):
                    rows.append(3 * r + p), cols.append(3 * c + q), vals.append(np.full(len(r), s * block[p, q]))
    return coo(rows, cols, vals, 3 * n**3)


def cells(n, h, lam):
    """lambda V (div u)^2 / 2 per cell, div from the one-point gradient g_a = s_a / (4h)."""
    signs = [(sx, sy, sz) for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)]
    i, j, k = (a.ravel() for a in np.meshgrid(range(n - 1), range(n - 1), range(n - 1), indexing="ij"))
    b = np.array([s[d] / (4 * h) for s in signs for d in range(3)])
    ke = lam * h**3 * np.outer(b, b)
    corner = [node(n, i + (s[0] > 0), j + (s[1] > 0), k + (s[2] > 0)) for s in signs]
    rows, cols, vals = [], [], []
    for a in range(8):
        for c in range(8):
            for p in range(3):
                for q in range(3):
                    rows.append(3 * corner[a] + p), cols.append(3 * corner[c] + q)
                    vals.append(np.full(len(i), ke[3 * a + p, 3 * c + q]))
    return coo(rows, cols, vals, 3 * n**3)


def divergence(n, h):
    """Each cell's one-point div u (rows: cells)."""
    signs = [(sx, sy, sz) for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)]
    i, j, k = (a.ravel() for a in np.meshgrid(range(n - 1), range(n - 1), range(n - 1), indexing="ij"))
    cell = i + (n - 1) * (j + (n - 1) * k)
    rows, cols, vals = [], [], []
    for s in signs:
        c = node(n, i + (s[0] > 0), j + (s[1] > 0), k + (s[2] > 0))
        for d in range(3):
            rows.append(cell), cols.append(3 * c + d), vals.append(np.full(len(i), s[d] / (4 * h)))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=((n - 1) ** 3, 3 * n**3))


def interpolation(nf):
    """Trilinear, every other plane (nf odd), the same weight for the three components."""
    nc = (nf + 1) // 2
    rows, cols, vals = [], [], []
    for k in range(nf):
        for j in range(nf):
            for i in range(nf):
                w = [[(x // 2, 1.0)] if x % 2 == 0 else [(x // 2, 0.5), (x // 2 + 1, 0.5)] for x in (i, j, k)]
                for a, wa in w[0]:
                    for b, wb in w[1]:
                        for c, wc in w[2]:
                            for d in range(3):
                                rows.append(3 * node(nf, i, j, k) + d), cols.append(3 * node(nc, a, b, c) + d)
                                vals.append(wa * wb * wc)
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * nf**3, 3 * nc**3))


def free(n):
    f = np.ones(3 * n**3, bool)
    for j in range(n):
        for i in range(n):
            f[3 * node(n, i, j, 0):3 * node(n, i, j, 0) + 3] = False  # clamped base
    return np.where(f)[0]


def hierarchy(n, lam, coarse, levels):
    sizes = [n]
    for _ in range(levels - 1):
        sizes.append((sizes[-1] + 1) // 2)
    fr = [free(m) for m in sizes]
    s, c = springs(n, 1.0), cells(n, 1.0, lam)
    ops, interps = [(s + c)[fr[0]][:, fr[0]].tocsr()], []
    for l in range(levels - 1):
        p = interpolation(sizes[l])
        pf = p[fr[l]][:, fr[l + 1]].tocsr()
        interps.append(pf)
        if coarse == "galerkin":
            ops.append((pf.T @ ops[-1] @ pf).tocsr())
        else:
            s = (p.T @ s @ p).tocsr()
            ops.append((s + cells(sizes[l + 1], 2.0 ** (l + 1), lam))[fr[l + 1]][:, fr[l + 1]].tocsr())
    return sizes, fr, ops, interps


def schwarz(a, n, fr, kind):
    """Additive Schwarz over cell (8 molecules) or vertex-star (27) patches, assembled."""
    pos = -np.ones(3 * n**3, int)
    pos[fr] = np.arange(len(fr))
    offsets = (0, 1) if kind == "cell" else (-1, 0, 1)
    starts = range(n - 1) if kind == "cell" else range(n)
    rows, cols, vals = [], [], []
    for k in starts:
        for j in starts:
            for i in starts:
                ids = [node(n, i + x, j + y, k + z) for z in offsets for y in offsets for x in offsets
                       if 0 <= i + x < n and 0 <= j + y < n and 0 <= k + z < n]
                d = pos[np.array([3 * m + q for m in ids for q in range(3)])]
                d = d[d >= 0]
                if len(d):
                    inv = np.linalg.inv(a[d][:, d].toarray())
                    rows.append(np.repeat(d, len(d))), cols.append(np.tile(d, len(d))), vals.append(inv.ravel())
    return coo(rows, cols, vals, len(fr))


class Chebyshev:
    def __init__(self, a, m, fraction, steps):
        self.a, self.steps = a, steps
        self.apply = (lambda r, d=1.0 / a.diagonal(): d * r) if m is None else (lambda r: m @ r)
        v = np.random.RandomState(0).rand(a.shape[0])
        for _ in range(30):
            v = self.apply(a @ v)
            top = np.linalg.norm(v)
            v /= top
        self.hi, self.lo = 1.1 * top, fraction * top

    def __call__(self, b, x):
        theta, delta = (self.hi + self.lo) / 2, (self.hi - self.lo) / 2
        sigma = theta / delta
        rho = 1 / sigma
        d = self.apply(b - self.a @ x) / theta
        for s in range(self.steps):
            x = x + d
            if s == self.steps - 1:
                break
            rho_next = 1 / (2 * sigma - rho)
            d = rho_next * rho * d + 2 * rho_next / delta * self.apply(b - self.a @ x)
            rho = rho_next
        return x


def krylov(n, nu, args):
    mu = 0.5
    lam = max(mu * (2 * nu / (1 - 2 * nu) - 1), 0.0)
    # --mixed: the multigrid is the springs-only one; the cell term enters through the pressures
    sizes, fr, ops, interps = hierarchy(n, 0.0 if args.mixed else lam, args.coarse, args.levels)
    smoothers = [Chebyshev(a, None if args.smoother == "jacobi" else schwarz(a, sizes[l], fr[l], args.smoother),
                           args.fraction, args.steps) for l, a in enumerate(ops[:-1])]
    coarsest = spla.splu(ops[-1].tocsc())

    def vcycle(l, b):
        if l == len(ops) - 1:
            return coarsest.solve(b)
        x = smoothers[l](b, np.zeros_like(b))
        x = x + interps[l] @ vcycle(l + 1, interps[l].T @ (b - ops[l] @ x))
        return smoothers[l](b, x)

    b = np.zeros(3 * n**3)
    for j in range(n):
        for i in range(n):
            b[3 * node(n, i, j, n - 1) + 2] = 1.0
    b = b[fr[0]]
    count = [0]

    def tick(_):
        count[0] += 1

    if not args.mixed:
        pc = spla.LinearOperator(ops[0].shape, matvec=lambda r: vcycle(0, r))
        return solve(spla.cg, ops[0], b, pc, tick, count)
    div = divergence(n, 1.0)[:, fr[0]].tocsr()
    nu_, nc = ops[0].shape[0], div.shape[0]
    lam = max(lam, 1e-12)  # nu = 1/4: no cell term, the pressures vanish
    k = sp.bmat([[ops[0], div.T], [div, -sp.identity(nc) / lam]]).tocsr()  # V = 1
    schur = 1.0 / args.schur + 1.0 / lam
    pc = spla.LinearOperator(k.shape, matvec=lambda r: np.concatenate([vcycle(0, r[:nu_]), r[nu_:] / schur]))
    return solve(spla.minres, k, np.concatenate([b, np.zeros(nc)]), pc, tick, count)


def solve(method, a, b, pc, tick, count):
    try:
        method(a, b, rtol=1e-8, M=pc, callback=tick, maxiter=2000)
    except TypeError:  # scipy < 1.12
        method(a, b, tol=1e-8, M=pc, callback=tick, maxiter=2000)
    return count[0]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("n", type=int, nargs="?", default=17, help="molecules per edge (2^k + 1)")
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--smoother", choices=("jacobi", "cell", "star"), default="jacobi")
    ap.add_argument("--coarse", choices=("galerkin", "redisc"), default="galerkin")
    ap.add_argument("--steps", type=int, default=2)
    ap.add_argument("--fraction", type=float, default=0.1, help="Chebyshev's lower bound / largest eigenvalue")
    ap.add_argument("--mixed", action="store_true", help="pressures per cell, MINRES with a block preconditioner")
    ap.add_argument("--schur", type=float, default=1.5, help="--mixed: w in the Schur complement V (1/w + 1/lambda_c)")
    args = ap.parse_args()
    counts = [krylov(args.n, nu, args) for nu in (0.25, 0.45, 0.49)]
    print(f"N={args.n} levels={args.levels} smoother={args.smoother} coarse={args.coarse} steps={args.steps} "
          f"fraction={args.fraction}{' mixed schur=%g' % args.schur if args.mixed else ''}: Krylov iterations at nu = 0.25 / 0.45 / 0.49: {counts[0]} / {counts[1]} / {counts[2]}")


if __name__ == "__main__":
    main()
