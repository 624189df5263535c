#!/usr/bin/env bash
# Installs the system packages of the OPTIONAL extras. The README's commands
# (`cargo test --workspace`, `cargo run --release -p atmo-sim -- fly`) need
# none of this: only the Rust toolchain, gcc and Python 3.
#
# - cmake: the OSQP comparison of atmo-mpc's bench
#   (`cargo bench -p atmo-mpc --bench rti --features osqp-compare`) builds
#   OSQP's C sources with it.
#
# The Python peers bring their own tools in venvs under target/ (no system
# packages): scripts/python-peers.sh (MCAP readers, Cyclone DDS) and
# scripts/ros2-peer.sh (rclpy on Fast DDS, cmake and colcon from PyPI).
#
# Idempotent; safe to run on a developer machine and in CI.
set -euo pipefail
need=()
command -v cmake >/dev/null || need+=(cmake)
if ((${#need[@]})); then
    if command -v apt-get >/dev/null; then
        apt-get update -qq && apt-get install -y -qq "${need[@]}"
    else
        echo "install-deps: please install: ${need[*]}" >&2
        exit 1
    fi
fi
