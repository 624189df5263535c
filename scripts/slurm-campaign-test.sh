#!/usr/bin/env bash
# The campaign round trip on a real Slurm: starts a one-node cluster on
# this machine (scripts/slurm-cluster.sh: Debian's slurm-wlm and munge),
# submits a small sweep as an sbatch array job, waits, merges the shards,
# and checks the result equals the same campaign flown in one local
# process, byte for byte (campaign.json and cells.md).
#
#   scripts/slurm-campaign-test.sh [ATMO_SIM]   # default: target/debug/atmo-sim
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
sim=$(realpath "${1:-${CARGO_TARGET_DIR:-target}/debug/atmo-sim}")
[ -x "$sim" ] || { echo "$0: no atmo-sim at $sim (cargo build -p atmo-sim)" >&2; exit 1; }
if [ "$(id -u)" != 0 ] && ! sinfo >/dev/null 2>&1; then
  echo "$0: skipped: no Slurm here, and starting one needs root (apt-get, daemons)"
  exit 0
fi
[ "$(id -u)" != 0 ] || bash scripts/slurm-cluster.sh start >/dev/null

work=$(mktemp -d /tmp/atmo-slurm-test.XXXXXX)
trap 'rm -rf "$work"' EXIT
chmod 755 "$work"
cat > "$work/campaign.toml" <<TOML
name = "slurm_round_trip"
scenario = "$repo/config/scenarios/wheel_landing.toml"
base_seed = 970001
runs_per_cell = 3
shards = 4
[[sweep]]
parameter = "thrust_scale"
values = [0.95, 1.05]
[[sweep]]
parameter = "ground_effect_scale"
values = [0.8, 1.2]
[slurm]
cpus_per_task = 1
mem_mib = 1024
time_minutes = 20
TOML

"$sim" campaign slurm "$work/campaign.toml" --out "$work/cluster" --binary "$sim"
job=$(sbatch --parsable --wait "$work/cluster/campaign.sbatch") || {
  echo "$0: the array job failed; its logs:" >&2
  tail -n 20 "$work"/cluster/logs/*.out >&2 || true
  exit 1
}
echo "array job $job done: $(ls "$work/cluster/shards" | wc -l) shard files"
"$sim" campaign merge "$work/cluster/shards" --out "$work/cluster/merged" >/dev/null
"$sim" campaign run "$work/campaign.toml" --jobs 2 --out "$work/local" >/dev/null 2>&1
for f in campaign.json cells.md; do
  cmp "$work/cluster/merged/$f" "$work/local/$f" \
    || { echo "$0: $f differs between the Slurm array job and the local run" >&2; exit 1; }
done
# A shard missing is refused, naming it.
rm "$work/cluster/shards/shard-00002-of-00004.json"
if out=$("$sim" campaign merge "$work/cluster/shards" --out "$work/cluster/partial" 2>&1); then
  echo "$0: a merge with a shard missing succeeded" >&2; exit 1
fi
grep -q "2/4" <<<"$out" || { echo "$0: the missing shard is not named: $out" >&2; exit 1; }
echo "slurm campaign round trip: the array job's merge equals the local run byte for byte"
