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
  cellsm  additive over cells, each cell's block D_c + lambda_c V b_c b_c^T (D_c the springs' diagonal on the
          cell's 8 molecules times --weight: pou = 1 / cells of the molecule, count = cells of the molecule, so
          that sum_c D_c^-1 = D^-1, or a number), inverted by Sherman-Morrison (~170 flops a cell)
  bs      the same rank-one structure summed over all cells (Woodbury): M^-1 = D^-1 - D^-1 B^T Q B D^-1, Q an
          approximation of T^-1, T = I / (lambda_c V) + B D^-1 B^T the cells' Schur complement (B: each cell's
          divergence b_c as a row). --schur-steps 0: Q = theta diag(T)^-1 (--theta); m > 0: m steps of the
          Neumann series of omega diag(T)^-1 (or, with --schur-block B, of block Jacobi over B^3 cells), omega =
          1 / (1.05 lambda_max), so Q < T^-1 and M stays SPD (m = 1: ~110 flops a cell, 2: ~210); -1: Q = T^-1
          exactly, M = D + B^T lambda_c V B (a sparse direct solve: a bound, not a candidate)
--sm-levels: cellsm/bs on every level, the finest, or the coarse levels (there with the coarse cells'
rediscretized b_c, 2h, and the Galerkin operator); --pre/--post: Chebyshev steps before/after the coarse
correction; --w-levels K: a W-cycle on the finest K levels; --colours 0,1,...,7: instead of Chebyshev, Richardson
over the 8 colours of cells (no two cells of a colour share a molecule; each colour a block Jacobi of the cells'
D_c + lambda_c V b_c b_c^T, damped by 1 / lambda_max), the colours in that order before the coarse correction and
reversed after it (each colour step costs a product for its residual).
Coarse operators: galerkin (P^T A P, what src/solvers/lattice_galerkin.cpp computes) or redisc (springs by
Galerkin, the cell term rediscretized on the coarse cells, same lambda_c, one-point).

--macro M: the volumetric part per macro-cell of M x M x M cells instead of per cell (one volume constraint per
macro-cell, of its mean divergence, i.e. the mean of its cells' one-point divergences; macro-cells aligned with the
coarse levels' cells for M = 2, whose Galerkin operator is then the per-coarse-cell term: --coarse macro instead
rediscretizes the coarse levels per macro-cell of theirs). --coarse-steps S: Chebyshev steps on the coarse levels.

--kind first|fourth|opt4: Chebyshev of the first kind on [f, 1.1] x the largest eigenvalue (the C++ smoother), or
Lottes's fourth kind on [0, 1.1] x it (PETSc 3.19's -ksp_chebyshev_kind fourth, not in 3.18), plain or with his
optimal step weights (opt4).

--mixed [minres|gmres] instead solves the mixed form with one pressure per cell (per macro-cell with --macro),
p = lambda_c div u (the volumetric part kept out of the multigrid): MINRES preconditioned by diag(one V-cycle of the
springs-only, nu = 1/4, operator with the smoother above, the diagonal Schur complement V (1 / w + 1 / lambda_c)),
w = --schur (lambda_s + 2 mu_s = 1.5), or GMRES (right-preconditioned) with the block upper-triangular
[[V-cycle^-1, B^T], [0, -S]]^-1.

Prints, for nu = 0.25 / 0.45 / 0.49, the Krylov iterations to a relative residual of 1e-8, and with --cost the
time-relevant work of the solve in the C++ code's measured costs (work()): the static target of issue 15 is the
work at 0.45 within 1.5x of the default's at 0.25.
Needs numpy and scipy (Debian: python3-numpy python3-scipy). About a minute at N = 17 (star: a few).
  /usr/bin/python3 run_scripts/mg_near_incompressible.py [N] [--smoother jacobi|cell|star|cellsm|bs]
      [--coarse galerkin|redisc] [--steps S] [--fraction F] [--mixed [--schur W]] [--weight pou|count|X]
      [--theta T] [--schur-steps M] [--schur-block B] [--sm-levels all|finest|coarse] [--pre S1] [--post S2]
      [--w-levels K] [--colours C,C,...] [--kind K] [--macro M] [--coarse-steps S] [--mixed minres|gmres] [--cost
      [--macro-product X]]
"""
import argparse

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

MACRO = [0]  # --macro M: the volumetric part per macro-cell of M^3 cells (0: per cell)


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


def macro_divergence(n, h, m=2):
    """Each macro-cell's mean div u (rows: macro-cells of m x m x m cells, fewer at the far faces when the cell
    count is not a multiple of m): the mean of its cells' one-point div, i.e. its boundary flux over its volume;
    returns the rows and each macro-cell's volume (cells x h^3)."""
    nc = n - 1
    nm = (nc + m - 1) // m
    d = divergence(n, h).tocoo()
    i = np.arange(nc ** 3) % nc
    j = (np.arange(nc ** 3) // nc) % nc
    k = np.arange(nc ** 3) // nc ** 2
    macro = i // m + nm * (j // m + nm * (k // m))
    count = np.bincount(macro, minlength=nm ** 3).astype(float)
    out = sp.csr_matrix((d.data / count[macro[d.row]], (macro[d.row], d.col)), shape=(nm ** 3, 3 * n ** 3))
    return out, count * h ** 3


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
    s = springs(n, 1.0)
    if MACRO[0]:  # the volumetric part per macro-cell of MACRO^3 cells: lambda V_M (div_M u)^2 / 2
        dm, vm = macro_divergence(n, 1.0, MACRO[0])
        c = (dm.T @ sp.diags(lam * vm) @ dm).tocsr()
    else:
        c = cells(n, 1.0, lam)
    ops, interps = [(s + c)[fr[0]][:, fr[0]].tocsr()], []
    for l in range(levels - 1):
        p = interpolation(sizes[l])
        pf = p[fr[l]][:, fr[l + 1]].tocsr()
        interps.append(pf)
        if coarse == "galerkin":
            ops.append((pf.T @ ops[-1] @ pf).tocsr())
        elif coarse == "macro":  # springs by Galerkin, the volumetric part rediscretized per coarse macro-cell
            s = (p.T @ s @ p).tocsr()
            dm, vm = macro_divergence(sizes[l + 1], 2.0 ** (l + 1), max(MACRO[0], 2))
            ops.append((s + dm.T @ sp.diags(lam * vm) @ dm)[fr[l + 1]][:, fr[l + 1]].tocsr())
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


class CellShermanMorrison:
    """The smoothers cellsm and bs (module docstring). cellsm: M^-1 r = sum_c R_c^T (D_c + lambda_c V b_c b_c^T)^-1
    R_c r by Sherman-Morrison; a colour given to __call__ restricts the sum to that colour's cells (ColourSweep).
    bs (theta given): D^-1 - D^-1 B^T Q B D^-1 with Q from schur_steps / schur_block."""

    def __init__(self, n, h, fr, lam, dspring, weight, theta=None, schur_steps=0, schur_block=0):
        pos = -np.ones(3 * n**3, int)
        pos[fr] = np.arange(len(fr))
        signs = [(sx, sy, sz) for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)]
        i, j, k = (a.ravel() for a in np.meshgrid(range(n - 1), range(n - 1), range(n - 1), indexing="ij"))
        self.colour = (i % 2) + 2 * (j % 2) + 4 * (k % 2)
        corner = [node(n, i + (s[0] > 0), j + (s[1] > 0), k + (s[2] > 0)) for s in signs]
        dofs = np.stack([3 * corner[a] + d for a in range(8) for d in range(3)], axis=1)
        self.idx = pos[dofs]
        self.mask = self.idx >= 0
        self.idx = np.where(self.mask, self.idx, 0)
        b = np.array([s[d] / (4 * h) for s in signs for d in range(3)])
        self.b = np.where(self.mask, b[None, :], 0.0)
        count = np.bincount(self.idx[self.mask], minlength=len(fr)).astype(float)  # cells per free dof
        if weight == "pou":
            w = 1.0 / count[self.idx]
        elif weight == "count":  # sum_c D_c^-1 = D^-1: Jacobi exactly when lambda_c = 0
            w = count[self.idx]
        else:
            w = float(weight) * np.ones(self.idx.shape)
        self.d = np.where(self.mask, dspring[self.idx] * w, 1.0)
        self.k = lam * h**3
        self.size = len(fr)
        self.theta = theta
        if theta is not None:  # global Braess-Sarazin-like
            self.dinv = 1.0 / dspring
            s = (self.b ** 2 * self.dinv[self.idx]).sum(axis=1)
            self.schur = 1.0 / (1.0 / max(self.k, 1e-300) + s)
            self.steps = schur_steps
            if schur_steps != 0:  # the cells' Schur complement T = 1/k + B D^-1 B^T, assembled
                nc = self.idx.shape[0]
                bm = sp.csr_matrix((self.b.ravel(), (np.repeat(np.arange(nc), 24), self.idx.ravel())),
                                   shape=(nc, self.size))
                self.bm = bm
                t = (bm @ sp.diags(self.dinv) @ bm.T + sp.identity(nc) / max(self.k, 1e-300)).tocsc()
                if schur_steps < 0:
                    self.lu = spla.splu(t)
                elif schur_block > 0:  # block Jacobi of T over schur_block^3 cells, scaled to stay below T^-1
                    nb = n - 1
                    ci, cj, ck = i, j, k
                    blk = (ci // schur_block) + (nb // schur_block + 1) * ((cj // schur_block) + (nb // schur_block + 1) * (ck // schur_block))
                    tc = t.tocoo()
                    keep = blk[tc.row] == blk[tc.col]
                    bd = sp.csr_matrix((tc.data[keep], (tc.row[keep], tc.col[keep])), shape=t.shape).tocsc()
                    self.q = spla.splu(bd)
                    v = np.random.RandomState(1).rand(nc)
                    for _ in range(60):
                        v = self.q.solve(t @ v)
                        top = np.linalg.norm(v)
                        v /= top
                    self.omega = 1.0 / (1.05 * top)
                    self.t = t.tocsr()
                else:
                    self.t = t.tocsr()
                    g = 1.0 / self.t.diagonal()
                    v = np.random.RandomState(1).rand(nc)
                    for _ in range(40):
                        v = g * (self.t @ v)
                        top = np.linalg.norm(v)
                        v /= top
                    self.omega = 1.0 / (1.05 * top)
                    self.g = g
        else:
            self.bd = self.b / self.d
            self.denom = self.k / (1.0 + self.k * (self.b * self.bd).sum(axis=1))

    def __call__(self, r, colour=None):
        if self.theta is not None:
            y = self.dinv * r
            bd = (self.b * y[self.idx]).sum(axis=1)
            if self.steps < 0:
                q = self.lu.solve(bd)
            elif hasattr(self, "q"):
                q = self.omega * self.q.solve(bd)
                for _ in range(self.steps - 1):
                    q = q + self.omega * self.q.solve(bd - self.t @ q)
            elif self.steps > 0:  # Neumann series of Jacobi on T: below T^-1, so M stays SPD
                q = np.zeros_like(bd)
                for _ in range(self.steps):
                    q = q + self.omega * self.g * (bd - self.t @ q)
            else:
                q = bd * self.schur
            corr = np.bincount(self.idx.ravel(), weights=(self.b * q[:, None]).ravel(), minlength=self.size)
            return y - self.theta * self.dinv * corr
        sel = slice(None) if colour is None else (self.colour == colour)
        rc = np.where(self.mask[sel], r[self.idx[sel]], 0.0)
        y = rc / self.d[sel]
        beta = self.denom[sel] * (self.b[sel] * y).sum(axis=1)
        y -= beta[:, None] * self.bd[sel]
        y = np.where(self.mask[sel], y, 0.0)
        return np.bincount(self.idx[sel].ravel(), weights=y.ravel(), minlength=self.size)


def spring_diagonals(sizes, fr, interps, n):
    """The springs' part of each level's diagonal (Galerkin of the springs alone): what D_c is made of."""
    s = springs(n, 1.0)[fr[0]][:, fr[0]].tocsr()
    out = [s.diagonal()]
    for p in interps:
        s = (p.T @ s @ p).tocsr()
        out.append(s.diagonal())
    return out


class ColourSweep:
    """The cells' 8 colours (no two cells of a colour share a molecule) as non-overlapping blocks
    D_c + lambda_c V b_c b_c^T (D_c the springs' diagonal, Sherman-Morrison), one colour per Richardson step:
    x += omega M_colour^-1 (b - A x), omega = 1 / lambda_max(M_colour^-1 A); colours in the given order before the
    coarse correction and reversed after it (a symmetric V-cycle). Each step costs a product (the residual)."""

    def __init__(self, a, cellsm, order):
        self.a, self.m, self.order = a, cellsm, order
        self.omega = []
        for c in range(8):
            v = np.random.RandomState(c).rand(a.shape[0])
            for _ in range(30):
                v = self.m(a @ v, c)
                top = np.linalg.norm(v)
                v /= top
            self.omega.append(1.0 / (1.05 * top))

    def __call__(self, b, x, steps=None, post=False):
        for c in (reversed(self.order) if post else self.order):
            x = x + self.omega[c] * self.m(b - self.a @ x, c)
        return x


KIND = ["first"]
OPT4 = {1: [1.125], 2: [1.02387287570313, 1.26408905371085],
        3: [1.00842544782028, 1.08867839208730, 1.33753125909618],
        4: [1.00391310427285, 1.04035811188593, 1.14863498546254, 1.38268869241000]}


class Chebyshev:
    def __init__(self, a, m, fraction, steps):
        self.a, self.steps = a, steps
        if m is None:
            self.apply = lambda r, d=1.0 / a.diagonal(): d * r
        elif callable(m) and not sp.issparse(m):
            self.apply = m
        else:
            self.apply = lambda r: m @ r
        v = np.random.RandomState(0).rand(a.shape[0])
        for _ in range(30):
            v = self.apply(a @ v)
            top = np.linalg.norm(v)
            v /= top
        self.hi, self.lo = 1.1 * top, fraction * top

    def __call__(self, b, x, steps=None):
        steps = self.steps if steps is None else steps
        if KIND[0] != "first":  # Lottes's fourth kind on [0, hi] (optionally with his optimal weights)
            r = b - self.a @ x
            d = 4.0 / (3.0 * self.hi) * self.apply(r)
            for i in range(steps):
                x = x + (OPT4[steps][i] if KIND[0] == "opt4" else 1.0) * d
                if i == steps - 1:
                    break
                r = r - self.a @ d
                j = i + 1
                d = (2 * j - 1) / (2 * j + 3) * d + (8 * j + 4) / ((2 * j + 3) * self.hi) * self.apply(r)
            return x
        theta, delta = (self.hi + self.lo) / 2, (self.hi - self.lo) / 2
        sigma = theta / delta
        rho = 1 / sigma
        d = self.apply(b - self.a @ x) / theta
        for s in range(steps):
            x = x + d
            if s == steps - 1:
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
    def preconditioner(l, a):
        if args.smoother == "jacobi":
            return None
        if args.smoother in ("cellsm", "bs"):
            if (l > 0 and args.sm_levels == "finest") or (l == 0 and args.sm_levels == "coarse"):
                return None
            h = 2.0 ** l
            dspring = sprdiag[l]
            return CellShermanMorrison(sizes[l], h, fr[l], 0.0 if args.mixed else lam, dspring, args.weight,
                                       args.theta if args.smoother == "bs" else None, args.schur_steps,
                                       args.schur_block)
        return schwarz(a, sizes[l], fr[l], args.smoother)

    sprdiag = spring_diagonals(sizes, fr, interps, n)
    if args.colours:  # Richardson over the cells' colours (ColourSweep), every level
        order = [int(c) for c in args.colours.split(",")]
        smoothers = [ColourSweep(a, CellShermanMorrison(sizes[l], 2.0 ** l, fr[l], lam, sprdiag[l], 1.0), order)
                     for l, a in enumerate(ops[:-1])]
    else:
        smoothers = [Chebyshev(a, preconditioner(l, a), args.fraction, args.steps if l == 0 else args.coarse_steps)
                     for l, a in enumerate(ops[:-1])]
    coarsest = spla.splu(ops[-1].tocsc())

    def vcycle(l, b):
        if l == len(ops) - 1:
            return coarsest.solve(b)
        x = smoothers[l](b, np.zeros_like(b), args.pre if l == 0 else None)
        x = x + interps[l] @ vcycle(l + 1, interps[l].T @ (b - ops[l] @ x))
        if l < args.w_levels:  # a W-cycle here: a second coarse correction
            x = x + interps[l] @ vcycle(l + 1, interps[l].T @ (b - ops[l] @ x))
        return smoothers[l](b, x, args.post, post=True) if args.colours else smoothers[l](b, x, args.post if l == 0 else None)

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
    if MACRO[0]:
        div, vol = macro_divergence(n, 1.0, MACRO[0])
        div = div[:, fr[0]].tocsr()
    else:
        div, vol = divergence(n, 1.0)[:, fr[0]].tocsr(), np.ones((n - 1) ** 3)
    nu_, nc = ops[0].shape[0], div.shape[0]
    lam = max(lam, 1e-12)  # nu = 1/4: no cell term, the pressures vanish
    # p = lambda div_M u per (macro-)cell, scaled by V: rows V div, pressure block -V / lambda
    k = sp.bmat([[ops[0], (sp.diags(vol) @ div).T], [sp.diags(vol) @ div, -sp.diags(vol) / lam]]).tocsr()
    schur = vol * (1.0 / args.schur + 1.0 / lam)
    if args.mixed == "minres":
        pc = spla.LinearOperator(k.shape, matvec=lambda r: np.concatenate([vcycle(0, r[:nu_]), r[nu_:] / schur]))
        return solve(spla.minres, k, np.concatenate([b, np.zeros(nc)]), pc, tick, count)
    bd = sp.diags(vol) @ div  # block upper-triangular [[A, B^T], [0, -S]]^-1 under GMRES (right-preconditioned)
    def tri(r):
        p = -r[nu_:] / schur
        return np.concatenate([vcycle(0, r[:nu_] - bd.T @ p), p])
    pc = spla.LinearOperator(k.shape, matvec=tri)
    return solve(lambda *a, **kw: spla.gmres(*a, restart=200, callback_type="legacy", **kw), k,
                 np.concatenate([b, np.zeros(nc)]), pc, tick, count)


def solve(method, a, b, pc, tick, count):
    try:
        method(a, b, rtol=1e-8, M=pc, callback=tick, maxiter=2000)
    except TypeError:  # scipy < 1.12
        method(a, b, tol=1e-8, M=pc, callback=tick, maxiter=2000)
    return count[0]


# Measured costs of the C++ solver (docs/benchmarks.md, "The nu = 0.45 static solve: a smoother holding the cells'
# volume coupling"; callgrind at N = 20), in instructions of one fine matrix-free product of the springs (1.0):
CELL_PRODUCT = 0.99      # the cell term's share of a fine product at nu = 0.45 (6.75 M against 3.4 M instructions)
OTHER = 7.8              # per CG iteration besides its 5 fine products: coarse levels, transfers, Chebyshev's and
                         # CG's vector work ((43.5 M - 5 x 3.4 M) / 3.4 M at nu = 0.25; the model's iteration at
                         # 0.45 is then 1.39x one at 0.25, against 1.30x measured: the cost is ~7 % high)
WOODBURY = 0.71          # one application of the C++ volume smoother, one Neumann step (2.43 M instructions)
SCHUR_STEP = 0.6         # each further Neumann step (a product of the cells' Schur complement, an exchange)
PATCH = {"cell": 2.0, "star": 9.0}  # additive Schwarz: 24 x 24 / 81 x 81 dense blocks a cell / molecule, streamed
# (their factors take 2.3 kB a cell / 26 kB a molecule: 2.3 / 26 GB at 10^6 molecules, against the whole solve's
# 1.0 GB now), so bounded below by the bytes, ~2x / ~9x a product


MACRO_PRODUCT = CELL_PRODUCT / 8  # --macro 2: the volumetric part's product per macro-cell (an estimate, not built:
                                  # a macro-cell's product does about one cell's work, a 27- instead of 8-corner
                                  # gather for a rank-one-plus-geometric dP/dF; on cubic cells at nu > 1/4 the
                                  # cell term is only its volumetric part); --macro-product overrides it
LEVEL1 = 0.55            # one more Chebyshev step on level 1 (its product, 0.34 of a fine one, and its vectors' work),
                         # in fine springs products: callgrind at N = 20 (3 levels), KSPSolve 51.5 -> 59.1 M
                         # instructions an iteration with 4 instead of 2 steps on level 1 (docs/benchmarks.md "The
                         # nu = 0.45 static solve: macro-cells modelled"); levels 2, 3, .. add 1/8, 1/64, ..: x 8/7
ORTHO = 0.025            # one GMRES basis vector's dot + axpy over 3N doubles, in fine springs products
PRESSURE_OPS = 0.1       # --mixed: B and B^T on the (macro-)cells and the pressure block's vector work


def work(args, nu, krylov_count):
    """The solve's work in fine springs products: Krylov x (finest-level products (2 s + 1 with Chebyshev s steps;
    each 1 + CELL_PRODUCT (or MACRO_PRODUCT) with the cell term) + OTHER + extra level-1 smoothing steps
    + 2 s smoother applications); --mixed: the springs-only V-cycle, the pressures' operators and GMRES's
    orthogonalization (j basis vectors at iteration j)."""
    cells = nu > 0.25
    s = args.steps
    if args.mixed:
        per = (2 * s + 1) + OTHER + (PRESSURE_OPS if cells else 0.0) + 2 * (args.coarse_steps - 2) * LEVEL1 * 8 / 7
        orth = ORTHO * (krylov_count + 1) / 2 if args.mixed == "gmres" else 0.0
        return krylov_count * (per + orth), per + orth
    cell_product = (args.macro_product if args.macro_product is not None else MACRO_PRODUCT) if args.macro \
        else CELL_PRODUCT
    product = 1.0 + (cell_product if cells else 0.0)
    apply = 0.0
    coarse = 2 * (args.coarse_steps - 2) * LEVEL1 * 8 / 7  # every coarse level's extra steps (OTHER has 2)
    if cells and args.smoother == "bs" and args.sm_levels != "coarse":
        apply = WOODBURY + SCHUR_STEP * max(args.schur_steps - 1, 0) if args.schur_steps >= 0 else float("nan")
    elif args.smoother in PATCH:
        apply = PATCH[args.smoother] * product
    per_iteration = (2 * s + 1) * product + OTHER + coarse + 2 * s * apply
    return krylov_count * per_iteration, per_iteration


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("n", type=int, nargs="?", default=17, help="molecules per edge (2^k + 1)")
    ap.add_argument("--levels", type=int, default=3)
    ap.add_argument("--smoother", choices=("jacobi", "cell", "star", "cellsm", "bs"), default="jacobi")
    ap.add_argument("--weight", default="pou", help="cellsm: D_c's weight, pou or a number")
    ap.add_argument("--theta", type=float, default=0.125, help="bs: the Schur correction's weight")
    ap.add_argument("--schur-steps", type=int, default=0, help="bs: Jacobi steps on the cells' Schur complement (0: its diagonal; -1: exact)")
    ap.add_argument("--schur-block", type=int, default=0, help="bs: the Schur steps use block Jacobi over B^3 cells")
    ap.add_argument("--colours", default="", help="Richardson over cell colours in this order, e.g. 0,7 or 0,1,2,3,4,5,6,7")
    ap.add_argument("--sm-levels", choices=("all", "finest", "coarse"), default="all",
                    help="cellsm/bs on every level, the finest only, or the coarse levels only")
    ap.add_argument("--pre", type=int, default=None, help="Chebyshev steps before the coarse correction (default --steps)")
    ap.add_argument("--post", type=int, default=None, help="Chebyshev steps after it (default --steps)")
    ap.add_argument("--w-levels", type=int, default=0, help="W-cycle on the finest K levels (0: V-cycle)")
    ap.add_argument("--coarse", choices=("galerkin", "redisc", "macro"), default="galerkin")
    ap.add_argument("--steps", type=int, default=2)
    ap.add_argument("--coarse-steps", type=int, default=None, help="Chebyshev steps on the coarse levels (default --steps)")
    ap.add_argument("--fraction", type=float, default=0.1, help="Chebyshev's lower bound / largest eigenvalue")
    ap.add_argument("--mixed", nargs="?", const="minres", default=None, choices=("minres", "gmres"),
                    help="pressures per cell (or macro-cell), MINRES with a block-diagonal or GMRES with a "
                         "block-triangular preconditioner")
    ap.add_argument("--macro", type=int, default=0, help="the volumetric part per macro-cell of M^3 cells")
    ap.add_argument("--macro-product", type=float, default=None, help="--cost: the macro-cells' product (fine springs products)")
    ap.add_argument("--schur", type=float, default=1.5, help="--mixed: w in the Schur complement V (1/w + 1/lambda_c)")
    ap.add_argument("--kind", choices=("first", "fourth", "opt4"), default="first", help="Chebyshev's kind")
    ap.add_argument("--cost", action="store_true", help="print the work of the solves in the C++ code's costs")
    args = ap.parse_args()
    MACRO[0] = args.macro
    KIND[0] = args.kind
    args.coarse_steps = args.steps if args.coarse_steps is None else args.coarse_steps
    args.pre = args.steps if args.pre is None else args.pre
    args.post = args.steps if args.post is None else args.post
    counts = [krylov(args.n, nu, args) for nu in (0.25, 0.45, 0.49)]
    print(f"N={args.n} levels={args.levels} smoother={args.smoother} coarse={args.coarse} steps={args.steps} "
          f"fraction={args.fraction}{' colours=' + args.colours if args.colours else ''} pre/post={args.pre}/{args.post} w_levels={args.w_levels}{' weight=%s theta=%g schur_steps=%d schur_block=%d sm_levels=%s' % (args.weight, args.theta, args.schur_steps, args.schur_block, args.sm_levels) if args.smoother in ('cellsm', 'bs') else ''}{' mixed=%s schur=%g' % (args.mixed, args.schur) if args.mixed else ''}{' macro=%d' % args.macro if args.macro else ''}: Krylov iterations at nu = 0.25 / 0.45 / 0.49: {counts[0]} / {counts[1]} / {counts[2]}")
    if args.cost:
        default = 8 * (5 + OTHER)  # the default's work at nu = 0.25 (8 Krylov iterations at N = 17)
        w = [work(args, nu, k) for nu, k in zip((0.25, 0.45, 0.49), counts)]
        print("  work (fine springs products) / iteration: " + " / ".join(f"{p:.2f}" for _, p in w) +
              "; solve: " + " / ".join(f"{t:.0f}" for t, _ in w) +
              "; against the default at 0.25: " + " / ".join(f"{t / default:.2f}x" for t, _ in w) + " (target at 0.45: <= 1.5x)")


if __name__ == "__main__":
    main()
