#!/usr/bin/env python3
"""Works out the undocumented conventions of the Neural-Fly flight logs.

Data: O'Connell et al., "Neural-Fly enables rapid learning for agile flight
in strong winds", Science Robotics 7(66), 2022 (aerorobotics/neural-fly,
data/experiment). Python 3.11 standard library only.

    python3 scripts/neural_fly_conventions.py FLIGHT.csv [FLIGHT.csv ...]

For each flight it prints:
  quaternion   max |R - R(q)| for q read as (x, y, z, w) and as (w, x, y, z)
  R direction  relative error of the body rates rebuilt as vee(R^T dR/dt)
               (R body->world) and with R transposed
  mass         m in fa_b,xy = m (a - g)_b,xy (the thrust is along body z, so
               the body-x/y part of fa is m times the measured acceleration);
               regression both ways (errors-in-variables bracket)
  fa identity  rms of fa_z - (m a - m g - m g T_sp / hover_throttle)_z: how
               the authors' thrust is defined
  thrust curve fits of the measured thrust m (a - g)_b,z (no wind: the aero
               z force is small) against pwm / 1000 per motor
  motor map    signs of the per-motor columns of the body angular
               acceleration regression (position and spin of each motor)
"""
import csv
import json
import math
import sys

G = 9.81


def load(path):
    with open(path, newline="") as f:
        return [
            {k: (json.loads(v) if v.startswith("[") else float(v)) for k, v in d.items() if k}
            for d in csv.DictReader(f)
        ]


def quat_to_r(q, scalar_last):
    x, y, z, w = q if scalar_last else (q[1], q[2], q[3], q[0])
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


def tr(m):
    return [list(c) for c in zip(*m)]


def mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def mulv(a, v):
    return [sum(a[i][k] * v[k] for k in range(3)) for i in range(3)]


def lstsq(x, y):
    """Least squares by the normal equations (Gauss-Jordan, partial pivoting)."""
    n = len(x[0])
    a = [[sum(r[i] * r[j] for r in x) for j in range(n)] for i in range(n)]
    b = [sum(r[i] * yy for r, yy in zip(x, y)) for i in range(n)]
    for c in range(n):
        p = max(range(c, n), key=lambda k: abs(a[k][c]))
        a[c], a[p], b[c], b[p] = a[p], a[c], b[p], b[c]
        for k in range(n):
            if k != c:
                f = a[k][c] / a[c][c]
                a[k] = [akj - f * acj for akj, acj in zip(a[k], a[c])]
                b[k] -= f * b[c]
    coef = [b[i] / a[i][i] for i in range(n)]
    res = [sum(ci * xi for ci, xi in zip(coef, r)) - yy for r, yy in zip(x, y)]
    return coef, math.sqrt(sum(e * e for e in res) / len(res))


def central(r, i, key, k):
    return (r[i + 1][key][k] - r[i - 1][key][k]) / (r[i + 1]["t"] - r[i - 1]["t"])


def analyse(path):
    r = load(path)
    n = len(r)
    dt = sorted(r[i + 1]["t"] - r[i]["t"] for i in range(n - 1))[n // 2]
    print(f"{path}: {n} rows, {r[-1]['t'] - r[0]['t']:.1f} s, median step {dt * 1e3:.2f} ms")
    for name, last in (("(x, y, z, w)", True), ("(w, x, y, z)", False)):
        e = max(
            abs(quat_to_r(s["q"], last)[i][j] - s["R"][i][j]) for s in r for i in range(3) for j in range(3)
        )
        print(f"  quaternion {name}: max |R - R(q)| = {e:.2e}")
    for name, flip in (("R body->world", False), ("R^T body->world", True)):
        err = tot = 0.0
        for i in range(1, n - 1):
            rm, r1, rp = (tr(r[j]["R"]) if flip else r[j]["R"] for j in (i - 1, i, i + 1))
            h = r[i + 1]["t"] - r[i - 1]["t"]
            w = mul(tr(r1), [[(rp[a][b] - rm[a][b]) / h for b in range(3)] for a in range(3)])
            rebuilt = (w[2][1], w[0][2], w[1][0])
            err += sum((rebuilt[k] - r[i]["w"][k]) ** 2 for k in range(3))
            tot += sum(r[i]["w"][k] ** 2 for k in range(3))
        print(f"  {name}: body rates from vee(R^T dR/dt), relative error {math.sqrt(err / tot):.3f}")
    acc_b, fa_b = [], []
    for i in range(1, n - 1):
        a = [central(r, i, "v", k) for k in range(3)]
        rt = tr(r[i]["R"])
        acc_b.append(mulv(rt, [a[0], a[1], a[2] + G]))
        fa_b.append(mulv(rt, r[i]["fa"]))
    sxy = sum(a[k] * f[k] for a, f in zip(acc_b, fa_b) for k in range(2))
    sxx = sum(a[k] ** 2 for a in acc_b for k in range(2))
    syy = sum(f[k] ** 2 for f in fa_b for k in range(2))
    m = sxy / sxx
    print(f"  mass from body-xy fa = m (a - g): {m:.4f} kg (reverse regression {syy / sxy:.4f} kg)")
    e = [
        m * a[2] - f[2] - m * G * r[i + 1]["T_sp"][0] / r[i + 1]["hover_throttle"][0]
        for i, (a, f) in enumerate(zip(acc_b, fa_b))
    ]
    fz = math.sqrt(sum(f[2] ** 2 for f in fa_b) / len(fa_b))
    print(
        f"  fa_z vs m a_z - m g T_sp/hover_throttle: rms {math.sqrt(sum(x * x for x in e) / len(e)):.3f} N "
        f"(rms fa_z {fz:.3f} N)"
    )
    thrust = [m * a[2] for a in acc_b]
    pwm = [[p / 1000 for p in r[i + 1]["pwm"]] for i in range(len(acc_b))]
    mean_pwm = sum(sum(p) for p in pwm) / (4 * len(pwm)) * 1000
    print(f"  mean pwm {mean_pwm:.0f}, mean thrust {sum(thrust) / len(thrust):.2f} N, m g {m * G:.2f} N")
    fits = {
        "proportional T = b p": lambda p: [sum(p)],
        "square T = c p^2": lambda p: [sum(x * x for x in p)],
        "affine T = a + b p": lambda p: [4, sum(p)],
        "quadratic T = b p + c p^2": lambda p: [sum(p), sum(x * x for x in p)],
    }
    for name, f in fits.items():
        coef, rms = lstsq([f(p) for p in pwm], thrust)
        print(f"  per-motor thrust {name:28s} coef {[round(c, 4) for c in coef]}  rms {rms:.3f} N")
    (c_b, c_c), _ = lstsq([fits["quadratic T = b p + c p^2"](p) for p in pwm], thrust)
    hover = (-c_b + math.sqrt(c_b * c_b + 4 * c_c * m * G / 4)) / (2 * c_c) * 1000
    print(f"  hover pwm from the quadratic curve: {hover:.0f}")
    # Motor map: the body angular acceleration against three thrust mixes
    # written for PX4 quad-x numbering (1 front-right, 2 back-left,
    # 3 front-left, 4 back-right) in the FLU body frame: roll torque
    # y_i T_i (left minus right), pitch torque -x_i T_i (back minus front),
    # yaw (motors 1, 2 minus 3, 4). The numbering is right when each axis
    # loads on its own mix with the sign written, and little on the others.
    mixes = {"left-right": (-1, 1, 1, -1), "back-front": (-1, 1, -1, 1), "m12-m34": (1, 1, -1, -1)}
    for lag in (0, 1):
        for ax, axis in enumerate(("roll", "pitch", "yaw")):
            y = [central(r, i, "w", ax) for i in range(2, n - 1)]
            x = []
            for i in range(2, n - 1):
                t = [c_b * p / 1000 + c_c * (p / 1000) ** 2 for p in r[i - lag]["pwm"]]
                x.append([1] + [sum(s * ti for s, ti in zip(mix, t)) for mix in mixes.values()])
            coef, rms = lstsq(x, y)
            var = sum((v - sum(y) / len(y)) ** 2 for v in y) / len(y)
            loads = ", ".join(f"{k} {c:+7.2f}" for k, c in zip(mixes, coef[1:]))
            print(f"  {axis:5s} acceleration, pwm {lag} row(s) earlier, rad/s^2 per N: {loads}  R^2 {1 - rms * rms / var:.2f}")


if __name__ == "__main__":
    for p in sys.argv[1:]:
        analyse(p)
