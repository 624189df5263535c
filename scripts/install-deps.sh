#!/usr/bin/env bash
# Installs what the build and tests need beyond the Rust toolchain.
# Idempotent; safe to run on a developer machine and in CI.
set -euo pipefail
need=()
# (system packages the tests need are added here as the project grows)
# cmake: osqp-sys (atmo-mpc's dev-dependency for the QP solver comparison) builds OSQP with it.
command -v cmake >/dev/null || need+=(cmake)
if ((${#need[@]})); then
    if command -v apt-get >/dev/null; then
        apt-get update -qq && apt-get install -y -qq "${need[@]}"
    else
        echo "install-deps: please install: ${need[*]}" >&2
        exit 1
    fi
fi
