#!/usr/bin/env python3
"""Which drag law explains the fan's force on the Neural-Fly flights, and what
wind speed it implies (docs/explain.md, "Limits"; the history:
docs/decisions/2026-12-05-explain-history.md, wind at high fan).

Data: O'Connell et al., "Neural-Fly enables rapid learning for agile flight in
strong winds", Science Robotics 7(66), 2022 (conventions: docs/neural_fly.md).

Per row (every second row): the measured body-frame force m (a - g)_b (a the
central difference of v, z-up world, R body to world) against a model built
from the pwm (u = pwm / 2000, k_T = 12.53 N per unit command as in
config/neural_fly_quadrotor.toml):

  body x, y:  -k_r U v_air,b           (rotor drag in the disc plane, U = sum u_i)
  body z:     k_T U (1 + s) + f k_T sum(u_i^2 - u_i) - k_a U v_air,b,z  (with --axial)

v_air = v - (w_x, 0, 0). For each trial wind w_x on a 0.5 m/s grid the
coefficients are least squares; the wind of the least residual is printed
with the coefficients and the residual left as a fraction of the force.

  python3 scripts/neural_fly_wind_fit.py [--axial] FLIGHT.csv ...

Python 3.11 standard library only.
"""
import ast
import csv
import math
import sys

from neural_fly_conventions import lstsq

M, G, K_T = 2.67, 9.81, 12.53


def load(path):
    raw = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            raw.append((float(r["t"]), ast.literal_eval(r["R"]), ast.literal_eval(r["v"]),
                        ast.literal_eval(r["pwm"])))
    out = []
    for k in range(1, len(raw) - 1, 2):
        t0, _, v0, _ = raw[k - 1]
        t2, _, v2, _ = raw[k + 1]
        _, rot, v, pwm = raw[k]
        a = [(v2[i] - v0[i]) / (t2 - t0) for i in range(3)]
        f = [M * a[0], M * a[1], M * (a[2] + G)]
        fb = [sum(rot[i][j] * f[i] for i in range(3)) for j in range(3)]
        out.append((rot, v, fb, [p / 2000.0 for p in pwm]))
    return out


def design(rows, wx, axial):
    x, y = [], []
    for rot, v, fb, u in rows:
        va = [v[0] - wx, v[1], v[2]]
        vb = [sum(rot[i][j] * va[i] for i in range(3)) for j in range(3)]
        total = sum(u)
        t0 = K_T * total
        curve = K_T * sum(c * c - c for c in u)
        for j in range(3):
            row = [-total * vb[j] if j < 2 else 0.0]
            if axial:
                row.append(-total * vb[j] if j == 2 else 0.0)
            row += [t0 if j == 2 else 0.0, curve if j == 2 else 0.0]
            x.append(row)
            y.append(fb[j] - (t0 if j == 2 else 0.0))
    return x, y


def main():
    axial = "--axial" in sys.argv
    for path in [a for a in sys.argv[1:] if not a.startswith("--")]:
        rows = load(path)
        _, y0 = design(rows, 0.0, axial)
        total = sum(v * v for v in y0)
        best = None
        for wx in [0.5 * i for i in range(-50, 11)]:
            x, y = design(rows, wx, axial)
            c, _ = lstsq(x, y)
            rss = sum((b - sum(p * q for p, q in zip(r, c))) ** 2 for r, b in zip(x, y))
            if best is None or rss < best[0]:
                best = (rss, wx, c)
        rss, wx, c = best
        names = ["k_r"] + (["k_a"] if axial else []) + ["s", "f"]
        coef = ", ".join(f"{n} = {v:.3f}" for n, v in zip(names, c))
        print(f"{path.rsplit('/', 1)[-1]}: wind x = {wx:+.1f} m/s, {coef}, "
              f"residual {rss / total:.3f} of the uncorrected force")


if __name__ == "__main__":
    main()
