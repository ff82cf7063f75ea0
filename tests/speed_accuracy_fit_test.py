#!/usr/bin/env python3
"""The exponent fit of run_scripts/plot_speed_accuracy.py (run_scripts/speed_accuracy_fit.py) against known power
laws: y = 3 x^1.25 exactly (exponent and prefactor to 1e-12), the points below x_min ignored (a different law
there must not move the fit), noise of +-1 % alternating (the exponent within 0.01 of the true one, an
independent bound: the noise's log amplitude over the log range), fewer than two usable points (None), and zero
or non-finite values skipped.

Usage: speed_accuracy_fit_test.py --build BUILD_DIR --source SOURCE_DIR      Prints 'N passed, M failed'."""
import argparse
import math
import os
import sys

ap = argparse.ArgumentParser()
ap.add_argument("--build")
ap.add_argument("--source", required=True)
args = ap.parse_args()
sys.path.insert(0, os.path.join(args.source, "run_scripts"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from checks import check, report  # noqa: E402
from speed_accuracy_fit import power_law_fit  # noqa: E402

xs = [1e3, 8e3, 6.4e4, 2.62e5, 1e6, 2e7]
exact = [(x, 3.0 * x ** 1.25) for x in xs]
p, c, n = power_law_fit(exact)
check(abs(p - 1.25) < 1e-12 and abs(c - 3.0) < 1e-9 and n == 6, f"exact law: p {p}, c {c}, n {n}")

# below x_min another law (a fixed cost): ignored
mixed = [(x, 50.0) for x in (1e2, 1e3)] + [(x, 2e-6 * x ** 0.8) for x in (1e4, 1e5, 1e6)]
p, c, n = power_law_fit(mixed, 1e4)
check(abs(p - 0.8) < 1e-12 and n == 3, f"x_min: p {p}, n {n}")
p_all, _, _ = power_law_fit(mixed)
check(abs(p_all - 0.8) > 0.1, f"without x_min the fixed cost moves the fit (p {p_all}): the filter is exercised")

# +-1 % noise: |dp| <= max |log noise| * 2 / log range
noisy = [(x, 7.0 * x ** 1.1 * (1.01 if i % 2 else 0.99)) for i, x in enumerate(xs)]
p, _, _ = power_law_fit(noisy)
bound = 2 * math.log(1.01 / 0.99) / math.log(xs[-1] / xs[0])
check(abs(p - 1.1) <= bound and bound < 0.01, f"noisy: p {p}, bound {bound}")

check(power_law_fit([(1e4, 1.0)]) is None, "one point: None")
check(power_law_fit([(1e4, 1.0), (1e4, 2.0)]) is None, "one distinct x: None")
p, _, n = power_law_fit([(1e4, 1e4), (1e5, 0.0), (1e6, float("nan")), (1e7, 1e7)])
check(n == 2 and abs(p - 1.0) < 1e-12, f"zero and NaN skipped: p {p}, n {n}")
sys.exit(report())
