"""Power-law fits for run_scripts/plot_speed_accuracy.py (tested by tests/speed_accuracy_fit_test.py).

power_law_fit(points, x_min): least squares of log y = log c + p log x over the points with x >= x_min and both
coordinates finite and positive; returns (p, c, points used), or None with fewer than two distinct x.
"""
import math


def power_law_fit(points, x_min=0.0):
    pts = [(math.log(x), math.log(y)) for x, y in points
           if x >= x_min and x > 0 and y > 0 and math.isfinite(x) and math.isfinite(y)]
    if len({a for a, _ in pts}) < 2:
        return None
    mx = sum(a for a, _ in pts) / len(pts)
    my = sum(b for _, b in pts) / len(pts)
    p = sum((a - mx) * (b - my) for a, b in pts) / sum((a - mx) ** 2 for a, _ in pts)
    return p, math.exp(my - p * mx), len(pts)
