#!/usr/bin/env bash
# Leave-one-controller-out (and one generator form out) check of the
# finder's older thresholds: MIN_GAIN, PREDICTION_MARGIN, SWAP_RECOVERY,
# COMBINED_CORRELATION (docs/explain.md, "Leave one controller out").
#
# Each rule's decisive number (the selection's gains, the best calibration
# swap's recovery, every parameter pair's correlation) is printed by a
# build with rules_instrumentation.patch applied, made in a temporary git
# worktree so that this tree is not touched. Needs the generator's matrix
# recordings (scripts/testgen_matrix.sh, in $MATRIX, default
# /tmp/testgen_matrix) and the Neural-Fly flights ($NEURAL_FLY, default
# ../shared/data/neural-fly). Usage: bash scripts/loco/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
root=$PWD
matrix=${MATRIX:-/tmp/testgen_matrix}
nf=${NEURAL_FLY:-$root/../shared/data/neural-fly}
out=${OUT:-/tmp/loco_rules}
tree=$(mktemp -d)
trap 'git -C "$root" worktree remove --force "$tree"' EXIT
git worktree add --detach -q "$tree" HEAD
git -C "$tree" apply "$root/scripts/loco/rules_instrumentation.patch"
(cd "$tree" && CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$root/target/loco} cargo build --release -q -p atmo-sim)
sim=${CARGO_TARGET_DIR:-$root/target/loco}/release/atmo-sim
rm -rf "$out"; mkdir -p "$out"
for f in "$matrix"/*.csv; do
  n=$(basename "$f" .csv)
  ATMO_DEBUG_RULES=1 "$sim" explain "$f" --robot config/atmo.toml --out "$out/g_$n" >"$out/g_$n.txt" 2>&1
done
for c in L1 indi NF-C; do
  for fl in nowind 35wind 70wind 100wind 70p20sint; do
    ATMO_DEBUG_RULES=1 "$sim" explain "$nf/custom_figure8_${c}_$fl.csv" \
      --robot config/neural_fly_quadrotor.toml --out "$out/n_${c}_$fl" >"$out/n_${c}_$fl.txt" 2>&1
  done
done
python3 scripts/loco/loco_rules.py "$out"
