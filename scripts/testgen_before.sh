#!/bin/bash
# Generate with atmo-testgen and analyse with today's explain.
set -e
cd "$(dirname "$0")/.."
G=${OUT:-/tmp/testgen_before}/gen; E=${OUT:-/tmp/testgen_before}/ex; mkdir -p $G $E
for s in 1 2 3 4 5 6 7 8 9 10; do
  target/debug/atmo-testgen --robot config/atmo.toml --effects none --seed $s --out $G/clean_s$s.csv >/dev/null
  target/debug/atmo-sim explain $G/clean_s$s.csv --robot config/atmo.toml --out $E/clean_s$s >/dev/null
done
for fx in ground_effect motor_lag drag,wind com_offset thrust_scale thrust_curve ground_effect,motor_lag; do
  n=${fx/,/+}
  target/debug/atmo-testgen --robot config/atmo.toml --effects $fx --seed 1 --out $G/$n.csv >/dev/null
  target/debug/atmo-sim explain $G/$n.csv --robot config/atmo.toml --out $E/$n >/dev/null
done
