#!/usr/bin/env python3
"""The fibre laws on meshes (docs/anisotropy.md, "Fibre laws"): the toe and tension_only through the tetrahedron
term, at finite strain, against this file's own solution of the same continuum energy (issue 17).

A Gmsh unit cube (tests/meshes/cube_h0.5.msh), `homogenized`, fibres along x, a roller on x- and a force on x+ (a
dead load: the nominal stress sigma = force / 1 m^2). Every tetrahedron then holds the same affine state F =
diag(l1, l2, l2), and its equilibrium is dW/dl1 = sigma, dW/dl2 = 0 for the energy per reference volume

    W = mu/2 (J^-2/3 I1 - 3) + kappa/4 (J^2 - 1 - 2 ln J) + W_f(l1) + alpha/2 (l1^2 - 1)(J - 1)

(the matrix (mu, kappa) = (C44, C23 + 2 C44 / 3), alpha = C12 - C23, E_f = C11 - C23 - 2 C44 - 2 alpha from the
transversely isotropic stiffness C, the fibre-shear term zero along the fibres; W_f the toe's integral of
s = c3 (exp(c4 (l - 1)) - 1), or E_f/8 (l1^2 - 1)^2 without toe; with tension_only W_f and the coupling vanish for
l1 < 1). Solved here by Newton with complex-step derivatives, independent of the C++ law code.
  a. toe, tension through the toe into the linear part (strain ~ 5 %), 4 load steps: l1 and l2 from the written
     positions equal the solution to 1e-7 (relative to the strain) at 1, 2 and 3 ranks;
  b. toe, the small-strain limit: E measured = the closed-form E_L times the toe's slope at rest, c3 c4 / E_f;
  c. tension_only, 3 % compression along the fibres: the matrix alone (the fibre and coupling off), l1 and l2
     against the solution; and at strain 1e-6 E_m = mu (3 lambda + 2 mu) / (lambda + mu) to 1e-5.

Usage: fibre_laws_mesh_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import json
import os
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import arguments_and_work, check, report, run_scene  # noqa: E402

# The test material of docs/anisotropy.md: E_L, E_T, nu_LT, nu_TT, G_L.
E_L, E_T, NU_LT, NU_TT, G_L = 20000.0, 1000.0, 0.35, 0.3, 800.0
TOE_STRETCH, TOE_EXPONENT = 1.03, 40.0


def moduli():
    """(mu, lambda, alpha, E_f) of the split, from the stiffness of the compliance (fibre axis 1)."""
    G_T = E_T / (2 * (1 + NU_TT))
    S = np.zeros((6, 6))
    S[0, 0], S[1, 1], S[2, 2] = 1 / E_L, 1 / E_T, 1 / E_T
    S[0, 1] = S[1, 0] = S[0, 2] = S[2, 0] = -NU_LT / E_L
    S[1, 2] = S[2, 1] = -NU_TT / E_T
    S[3, 3], S[4, 4], S[5, 5] = 1 / G_T, 1 / G_L, 1 / G_L
    C = np.linalg.inv(S)
    mu, lam = C[3, 3], C[1, 2]
    alpha = C[0, 1] - lam
    return mu, lam, alpha, C[0, 0] - lam - 2 * mu - 2 * alpha


def energy(l1, l2, toe, tension_only):
    """W per reference volume at F = diag(l1, l2, l2) (complex-safe for complex-step derivatives)."""
    mu, lam, alpha, E_f = moduli()
    kappa = lam + 2 * mu / 3
    J = l1 * l2 * l2
    W = 0.5 * mu * (J ** (-2.0 / 3.0) * (l1 * l1 + 2 * l2 * l2) - 3) + 0.25 * kappa * (J * J - 1 - 2 * np.log(J))
    if tension_only and l1.real < 1:
        return W
    if toe:
        c4, lt = TOE_EXPONENT, TOE_STRETCH
        c3 = E_f / (c4 * np.exp(c4 * (lt - 1)))
        part = lambda s: c3 * ((np.exp(c4 * (s - 1)) - 1) / c4 - (s - 1))  # noqa: E731
        if l1.real <= lt:
            W = W + part(l1)
        else:
            d = l1 - lt
            W = W + part(lt) + c3 * np.expm1(c4 * (lt - 1)) * d + 0.5 * E_f * d * d
    else:
        W = W + 0.125 * E_f * (l1 * l1 - 1) ** 2
    return W + 0.5 * alpha * (l1 * l1 - 1) * (J - 1)


def gradient(l, toe, tension_only):
    h = 1e-30
    return np.array([energy(l[0] + 1j * h, l[1] + 0j, toe, tension_only).imag / h,
                     energy(l[0] + 0j, l[1] + 1j * h, toe, tension_only).imag / h])


def solve(sigma, toe, tension_only):
    """(l1, l2) with dW/dl1 = sigma, dW/dl2 = 0 (dW/dl2 is the sum of the two lateral P's, each zero)."""
    l = np.array([1.0, 1.0])
    for _ in range(100):
        r = gradient(l, toe, tension_only) - [sigma, 0.0]
        e = 1e-7
        K = np.column_stack([(gradient(l + e * np.eye(2)[k], toe, tension_only) -
                              gradient(l - e * np.eye(2)[k], toe, tension_only)) / (2 * e) for k in range(2)])
        step = np.linalg.solve(K, -r)
        l = l + step
        if np.max(np.abs(step)) < 1e-15:
            break
    return l


def scene(mesh, force, toe, tension_only, load_steps):
    law = f'toe = {{ law = "exp-linear", stretch = {TOE_STRETCH}, exponent = {TOE_EXPONENT} }}\n' if toe else ""
    return f"""title = "fibre laws on a mesh"
[body]
shape = "mesh"
file = "{mesh}"
youngs_modulus = {E_T}
poisson_ratio = {NU_TT}
[body.fibres]
direction = [1.0, 0.0, 0.0]
youngs_modulus = {E_L}
poisson_ratio = {NU_LT}
shear_modulus = {G_L}
tension_only = {"true" if tension_only else "false"}
{law}[calibration]
method = "homogenized"
[[fix]]
face = "x-"
mode = "roller"
[[load]]
face = "x+"
force = [{force}, 0.0, 0.0]
[solver]
kind = "static"
tolerance = 1e-12
load_steps = {load_steps}
[output]
fields = ["displacements"]
progress = false
"""


def stretches(out):
    with h5py.File(os.path.join(out, "final.h5"), "r") as f:
        x = f["/molecules/positions"][()]
        u = f["/molecules/displacements"][()]
    rest = x - u
    return [(x[:, a].max() - x[:, a].min()) / (rest[:, a].max() - rest[:, a].min()) for a in range(3)]


def run(a, work, label, ranks, force, toe, tension_only, load_steps=1):
    mesh = os.path.join(a.source, "tests", "meshes", "cube_h0.5.msh")
    out, r = run_scene(a.build, work, label, ranks, scene(mesh, force, toe, tension_only, load_steps))
    check(r.returncode == 0, f"{label}: exit {r.returncode}: {r.stderr[-400:]}")
    return out if r.returncode == 0 else None


def compare(out, label, sigma, toe, tension_only):
    l1, l2 = solve(sigma, toe, tension_only)
    s = stretches(out)
    check(abs((s[0] - l1) / (l1 - 1)) < 1e-7, f"{label}: l1 {s[0]!r} against {l1!r}")
    for axis in (1, 2):
        check(abs((s[axis] - l2) / (l2 - 1)) < 1e-7, f"{label}: l{axis + 1} {s[axis]!r} against {l2!r}")
    return s


def main():
    a, work = arguments_and_work("fibre_laws_mesh")
    mu, lam, alpha, E_f = moduli()

    # a. Through the toe into its linear part: nominal stress for about 5 % strain along the fibres.
    sigma = 0.7 * E_L * 0.05
    l1, _ = solve(sigma, True, False)
    check(l1 > TOE_STRETCH + 0.01, f"toe: the load {sigma} Pa goes past the toe's stretch: l1 = {l1}")
    result = {}
    for ranks in (1, 2, 3):
        out = run(a, work, f"toe_np{ranks}", ranks, sigma, True, False, load_steps=4)
        if out:
            result[ranks] = compare(out, f"toe at {ranks} ranks", sigma, True, False)
    if len(result) == 3:
        check(max(abs(result[r][k] - result[1][k]) for r in (2, 3) for k in range(3)) < 1e-10,
              f"toe: the same stretches at 1-3 ranks: {result}")

    # b. The toe's small-strain modulus: the fibre's slope at rest is c3 c4 = E_f exp(-c4 (lambda1 - 1)).
    c3c4 = E_f * np.exp(-TOE_EXPONENT * (TOE_STRETCH - 1))
    l1, l2 = solve(1e-3, True, False)
    E_toe = 1e-3 / (l1 - 1)
    out = run(a, work, "toe_small", 2, 1e-3, True, False)
    if out:
        with open(os.path.join(out, "summary.json")) as f:
            measured = json.load(f)["youngs_modulus_measured"]
        check(abs(measured / E_toe - 1) < 1e-6, f"toe at small strain: E {measured} against {E_toe}")
        # The closed form at rest: the matrix and coupling with the fibre's slope c3 c4 in place of E_f.
        S = np.linalg.inv(np.array([[lam + 2 * mu + 2 * alpha + c3c4, lam + alpha, lam + alpha],
                                    [lam + alpha, lam + 2 * mu, lam], [lam + alpha, lam, lam + 2 * mu]]))
        check(abs(measured * S[0, 0] - 1) < 1e-5, f"toe at small strain: E {measured} against {1 / S[0, 0]}")

    # c. tension_only in compression: the matrix alone.
    sigma = -0.03 * E_T
    out = run(a, work, "tension_only", 3, sigma, False, True, load_steps=2)
    if out:
        compare(out, "tension_only, 3 % compression", sigma, False, True)
    E_m = mu * (3 * lam + 2 * mu) / (lam + mu)
    out = run(a, work, "tension_only_small", 1, -1e-6 * E_m, False, True)
    if out:
        with open(os.path.join(out, "summary.json")) as f:
            measured = json.load(f)["youngs_modulus_measured"]
        check(abs(measured / E_m - 1) < 1e-5, f"tension_only at small compression: E {measured} against E_m {E_m}")
    return report()


if __name__ == "__main__":
    sys.exit(main())
