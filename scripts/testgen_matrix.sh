#!/usr/bin/env bash
# The finder on the independent generator, every controller and form:
# clean seeds 1-10 under each controller, then each concealed case at seed
# 1 flown by each controller in each form (drag + wind 96 s). Release
# binaries; recordings and reports in $OUT (default /tmp/testgen_matrix);
# a line per flight on stdout (docs/testgen.md).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p atmo-testgen -p atmo-sim
bin=${CARGO_TARGET_DIR:-target}/release
out=${OUT:-/tmp/testgen_matrix}
mkdir -p "$out"
touch "$out/.atmo-output"
fly() { # controller form effects seed duration
  local name="$1-$2-${3//,/+}-$4"
  "$bin/atmo-testgen" --robot config/atmo.toml --controller "$1" --form "$2" \
    --effects "$3" --seed "$4" --duration "$5" --out "$out/$name.csv" >/dev/null
  "$bin/atmo-sim" explain "$out/$name.csv" --robot config/atmo.toml --out "$out/$name" >/dev/null
  echo "$name"
}
for c in pid lqr; do
  for s in 1 2 3 4 5 6 7 8 9 10; do fly $c first none $s 48; done
  for f in first second; do
    for fx in ground_effect motor_lag com_offset thrust_scale thrust_curve ground_effect,motor_lag; do
      fly $c $f $fx 1 48
    done
    fly $c $f drag,wind 1 96
  done
done | python3 scripts/explain_summary.py "$out"
