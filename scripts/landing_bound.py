#!/usr/bin/env python3
"""An optimistic bound on each Monte Carlo run's touchdown tilt (the wheel-landing target).

Reads the `per_run` records of `atmo-sim fly --runs N` (monte_carlo.json)
and, for each run's drawn truth, integrates the vertical motion of an ideal
tilt-up: from rest at the largest tilt the thrust holds (every rotor at
`--thrust-max`, no attitude control, no motor lag), the tilt rising at the
mechanism's 22.5 deg/s, the ground effect at its largest (the plant's table
at its lowest height, scaled and shifted as the run drew it), until the
fall speed reaches `--impact`. The tilt there is the most any controller
could land at with that impact speed; the real flight loses to the attitude
control's thrust margin, the approach and the commit's timing.

    python3 scripts/landing_bound.py out/wheel_landing/monte_carlo.json

Hover command 0.48 per rotor for the robot file's mass (the scenario's
trim); stdlib only.
"""
import argparse
import json
import math

TILTS_DEG = [40.0, 50.0, 60.0, 70.0]
# config/plant.toml [effects.ground_effect] gain at the lowest height (0.25 m).
GAIN_LOWEST = [0.090, 0.190, 0.070, -0.070]
HOVER_COMMAND = 0.48
TILT_RATE_DEG = 22.5
G = 9.81


def gain(tilt_deg, scale, shift_deg):
    t = min(max(tilt_deg - shift_deg, TILTS_DEG[0]), TILTS_DEG[-1])
    i = min(int((t - TILTS_DEG[0]) // 10.0), len(TILTS_DEG) - 2)
    f = (t - TILTS_DEG[i]) / 10.0
    return scale * (GAIN_LOWEST[i] * (1.0 - f) + GAIN_LOWEST[i + 1] * f)


def bound(draws, thrust_max, impact):
    """(hover-limit tilt, touchdown tilt at `impact`), deg."""
    thrust_to_weight = draws["thrust_scale"] / draws["mass_scale"]
    k = thrust_max / HOVER_COMMAND * thrust_to_weight
    scale, shift = draws["ground_effect_scale"], draws["ground_effect_shift_deg"]

    def lift(tilt):
        return k * math.cos(math.radians(tilt)) * (1.0 + gain(tilt, scale, shift))

    tilt = 40.0
    while tilt < 70.0 and lift(tilt + 0.01) >= 1.0:
        tilt += 0.01
    hover_limit = tilt
    v, dt = 0.0, 1e-4
    while v < impact and tilt < 70.0:
        v += G * (1.0 - lift(tilt)) * dt
        tilt += TILT_RATE_DEG * dt
    return hover_limit, tilt


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("monte_carlo_json")
    ap.add_argument("--thrust-max", type=float, default=0.95)
    ap.add_argument("--impact", type=float, default=0.4, help="m/s")
    ap.add_argument("--tilt", type=float, default=64.0, help="deg, the criterion")
    a = ap.parse_args()
    runs = json.load(open(a.monte_carlo_json))["per_run"]
    rows = []
    for r in runs:
        hover, reach = bound(r["draws"], a.thrust_max, a.impact)
        rows.append((reach, hover, r["touchdown_tilt_deg"], r["seed"]))
    ok = sum(1 for x in rows if x[0] >= a.tilt)
    flown = sum(1 for r in runs if r["landed_past_64_deg"])
    print(f"bound >= {a.tilt} deg at <= {a.impact} m/s: {ok}/{len(rows)}; flown: {flown}/{len(rows)}")
    print("lowest bounds: seed, hover-limit tilt, bound, flown (deg)")
    for reach, hover, flown_tilt, seed in sorted(rows)[:8]:
        print(f"  {seed:5d} {hover:6.1f} {reach:6.1f} {flown_tilt:6.1f}")


if __name__ == "__main__":
    main()
