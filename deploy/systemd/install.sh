#!/usr/bin/env bash
# Installs the ATMO units (docs/fly-the-robot.md, "Deployment"):
#   sudo deploy/systemd/install.sh [--realtime]
# Binaries from target/release (cargo build --release -p atmo-daemon
# -p atmo-roboclaw), config/ to /etc/atmo (existing files are kept), the
# units to /etc/systemd/system. --realtime also installs the SCHED_FIFO
# drop-ins (only on a host that grants real-time scheduling).
set -euo pipefail
cd "$(dirname "$0")/../.."
target=${CARGO_TARGET_DIR:-target}/release
for bin in atmo-daemon atmo-roboclaw; do
    install -m 0755 "$target/$bin" /usr/local/bin/
done
install -d /etc/atmo /usr/local/share/doc/atmo
cp -rn config/. /etc/atmo/
install -m 0644 docs/fly-the-robot.md /usr/local/share/doc/atmo/
install -m 0644 deploy/systemd/atmo-daemon.service deploy/systemd/atmo-roboclaw@.service /etc/systemd/system/
if [[ ${1:-} == --realtime ]]; then
    for unit in atmo-daemon.service atmo-roboclaw@.service; do
        install -d "/etc/systemd/system/$unit.d"
        install -m 0644 "deploy/systemd/$unit.d/realtime.conf" "/etc/systemd/system/$unit.d/"
    done
fi
systemctl daemon-reload
echo "installed; enable with: systemctl enable atmo-roboclaw@tilt atmo-roboclaw@wheels atmo-daemon"
