#!/bin/bash
# Generate with atmo-testgen and analyse with this explain
# (the same recordings as scripts/testgen_before.sh; outputs in $OUT).
set -e
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/testgen_after} ./scripts/testgen_before.sh
