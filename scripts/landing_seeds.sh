#!/usr/bin/env bash
# Flies the wheel landing's Monte Carlo on several base seeds and prints one
# table: each seed set's count at the wheel-landing target (>= 64 deg,
# <= 0.4 m/s, no crash) with its Wilson 95 % interval, and the pooled row.
#
#   scripts/landing_seeds.sh [--controller nominal] [--runs 200] [SEED...]
#
# Without seeds: the judging set of docs/landing.md (3100001 ... 3500001).
# Uses target/release/atmo-sim (built if missing); outputs under
# out/landing_seeds/<seed>/.
set -euo pipefail
cd "$(dirname "$0")/.."
runs=200
controller=()
seeds=()
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) runs=$2; shift 2 ;;
    --controller) controller=(--controller "$2"); shift 2 ;;
    *) seeds+=("$1"); shift ;;
  esac
done
[ ${#seeds[@]} -gt 0 ] || seeds=(3100001 3200001 3300001 3400001 3500001)
bin=${CARGO_TARGET_DIR:-target}/release/atmo-sim
[ -x "$bin" ] || cargo build --release -p atmo-sim
files=()
for s in "${seeds[@]}"; do
  out=out/landing_seeds/$s
  "$bin" fly --runs "$runs" --seed "$s" "${controller[@]}" --out "$out" > /dev/null
  files+=("$(find "$out" -name monte_carlo.json | head -n1)")
done
python3 - "${files[@]}" <<'PY'
import json, math, sys
sys.path.insert(0, "scripts")
from wilson import wilson
# The pooled row's interval (each seed set's comes from its monte_carlo.json).
rows = []
print("| base seed | runs | target (>= 64 deg, <= 0.4 m/s) | Wilson 95 % | low | fast | success | crashes | prediction bias (m/s, deg) | spread (m/s, deg) |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
tot = dict(n=0, k=0, low=0, fast=0, ok=0, crash=0)
for f in sys.argv[1:]:
    r = json.load(open(f)); pr = r["per_run"]
    n, k = r["runs"], r["landed_past_64_deg"]
    low = sum(1 for x in pr if x["touchdown_tilt_deg"] is not None and x["touchdown_tilt_deg"] < 64)
    fast = sum(1 for x in pr if x["impact_speed_mps"] is not None and x["impact_speed_mps"] > 0.4)
    p = r.get("prediction") or {}
    lo, hi = r["criteria_met"]["wheel_landing_target"]["wilson_95"]
    # Without a decision (the paper's tilt law) there is no prediction.
    if "impact_speed_bias_mps" in p:
        bias = f"{p['impact_speed_bias_mps']:+.3f}, {p['touchdown_tilt_bias_deg']:+.2f}"
        spread = f"{p['impact_speed_spread_mps']:.3f}, {p['touchdown_tilt_spread_deg']:.2f}"
    else:
        bias, spread = "-", "-"
    print(f"| {r['base_seed']} | {n} | {k} ({100*k/n:.1f} %) | {100*lo:.1f}-{100*hi:.1f} % | {low} | {fast} | {r['successes']} | {r['crashes']} | {bias} | {spread} |")
    for key, v in (("n", n), ("k", k), ("low", low), ("fast", fast), ("ok", r["successes"]), ("crash", r["crashes"])):
        tot[key] += v
    rows.append((pr, p))
lo, hi = wilson(tot["k"], tot["n"])
pairs = [(x["impact_speed_mps"] - x["predicted_touchdown"]["impact_speed_mps"], x["touchdown_tilt_deg"] - x["predicted_touchdown"]["tilt_deg"])
         for pr, _ in rows for x in pr if x["predicted_touchdown"] and x["impact_speed_mps"] is not None]
m = len(pairs)
if m:
    bv = sum(a for a, _ in pairs) / m; bt = sum(b for _, b in pairs) / m
    sv = math.sqrt(sum((a - bv) ** 2 for a, _ in pairs) / m); st = math.sqrt(sum((b - bt) ** 2 for _, b in pairs) / m)
    bias, spread = f"{bv:+.3f}, {bt:+.2f} ({m} decided)", f"{sv:.3f}, {st:.2f}"
else:
    bias, spread = "- (no decision)", "-"
print(f"| all | {tot['n']} | {tot['k']} ({100*tot['k']/tot['n']:.1f} %) | {100*lo:.1f}-{100*hi:.1f} % | {tot['low']} | {tot['fast']} | {tot['ok']} | {tot['crash']} | {bias} | {spread} |")
PY
