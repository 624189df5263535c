"""The SITL wheel landing with the motion capture played by rclpy on Fast DDS.

Three processes on loopback, in a domain of their own: the UNMODIFIED
atmo-daemon binary; `atmo-sim serve` (the plant, every driver, the pilot),
told to publish its motion capture on a side topic (`--estimate-topic
/atmo/sim/odom`) that the daemon does not read, and its pilot inputs on
another (`--pilot-topic /atmo/sim/pilot`); and this rclpy node, which plays
both to the daemon: every nav_msgs/Odometry from the side topic is
republished, as rclpy's own message, on the daemon's estimate topic
(/atmo/mocap/odom, ROS 2 default QoS), and the pilot inputs on /atmo/pilot
once estimates flow. The landing can only succeed if the daemon flies on
what rclpy sent.

A second flight loses the motion capture for good: the daemon's config
also reads PX4's estimate (`autopilot_estimate`, px4_msgs/VehicleOdometry
on /fmu/out/vehicle_odometry, which `atmo-sim serve` publishes as PX4's
bridge would), and rclpy stops relaying the motion capture once the
daemon is morphing. The daemon must go to failsafe and come down level
onto its wheels on PX4's estimate (without it the failsafe's open-loop
trim crashes: crates/atmo-sim/tests/sim/faults.rs).

Run by scripts/ros2-peer.sh (which builds the venv):

    scripts/ros2-peer.sh sitl [path/to/atmo-daemon [path/to/atmo-sim]]

Prints PASS/FAIL lines and `N passed, M failed`; exit 1 on any failure.
"""

import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from rclpy_peer import Checks, daemon_config, sitl_arguments  # noqa: E402

SIDE_TOPIC = "/atmo/sim/odom"
ESTIMATE_TOPIC = "/atmo/mocap/odom"
PILOT_SIDE_TOPIC = "/atmo/sim/pilot"
PILOT_TOPIC = "/atmo/pilot"
# The pilot (with its arm switch) is played only once this many estimates
# went through, so the daemon never arms before it has an estimate.
ESTIMATES_BEFORE_PILOT = 20
STATUS_TOPIC = "/atmo/status"
AUTOPILOT_TOPIC = "/fmu/out/vehicle_odometry"
# The motion capture is cut when the daemon reports this mode.
CUT_IN_MODE = "morphing"
# failsafe.estimate_timeout (0.05 s) + a few ticks + DDS.
FAILSAFE_WITHIN_S = 0.5


def autopilot_config(tmp: Path, tag: str) -> Path:
    """The test's daemon config with PX4's estimate read as the fallback."""
    path = daemon_config(tmp, tag)
    text = path.read_text()
    line = (f'autopilot_estimate = {{ name = "{AUTOPILOT_TOPIC}", '
            'type = "px4_msgs/msg/VehicleOdometry", enabled = false }')
    assert text.count(line) == 1, f"config/daemon.toml has no line {line!r}"
    path.write_text(text.replace(line, line.replace(", enabled = false }", " }")))
    return path


def fly(args, c, lose_estimate):
    """One SITL flight; with `lose_estimate`, the motion capture cut for good."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, qos_profile_sensor_data
    from nav_msgs.msg import Odometry
    from atmo_msgs.msg import MpcStatus, PilotInput

    name = "estimate lost" if lose_estimate else "landing"
    domain = random.Random(os.getpid() ^ int(time.time()) ^ lose_estimate).randrange(200, 232)
    tmp = Path(tempfile.mkdtemp(prefix="atmo-rclpy-sitl-"))
    tag = f"rsitl{os.getpid()}{int(lose_estimate)}"
    config = autopilot_config(tmp, tag) if lose_estimate else daemon_config(tmp, tag)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    print(f"rclpy_sitl ({name}): domain {domain}, run folder {tmp}", flush=True)

    rclpy.init(domain_id=domain)
    node = rclpy.create_node("atmo_mocap_relay")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    relay = node.create_publisher(Odometry, ESTIMATE_TOPIC, QoSProfile(depth=10))
    relayed = []
    modes = []  # (monotonic time, mode name)
    cut = []  # when the motion capture was cut

    def play(msg):
        if cut:
            return
        out = Odometry()  # rclpy's own message, field by field
        out.header = msg.header
        out.child_frame_id = msg.child_frame_id
        out.pose = msg.pose
        out.twist = msg.twist
        relay.publish(out)
        relayed.append(time.monotonic())

    node.create_subscription(Odometry, SIDE_TOPIC, play, qos_profile_sensor_data)
    pilot_relay = node.create_publisher(PilotInput, PILOT_TOPIC, QoSProfile(depth=10))
    pilots = []

    def play_pilot(msg):
        if len(relayed) >= ESTIMATES_BEFORE_PILOT:
            pilot_relay.publish(msg)
            pilots.append(time.monotonic())

    node.create_subscription(PilotInput, PILOT_SIDE_TOPIC, play_pilot, qos_profile_sensor_data)

    def on_status(s):
        now = time.monotonic()
        if not modes or modes[-1][1] != s.mode_name:
            modes.append((now, s.mode_name))
        if lose_estimate and not cut and s.mode_name == CUT_IN_MODE:
            cut.append(now)

    node.create_subscription(MpcStatus, STATUS_TOPIC, on_status, qos_profile_sensor_data)

    def spawn(name, argv):
        return subprocess.Popen(argv, cwd=tmp, env=env, stdin=subprocess.DEVNULL,
                                stdout=open(tmp / f"{name}.stdout", "w"),
                                stderr=open(tmp / f"{name}.stderr", "w"))

    daemon = spawn("atmo-daemon", [str(Path(args.daemon).resolve()), "run", "--config",
                                   str(config), "--log", str(tmp / "flight.mcap")])
    server = spawn("atmo-sim", [str(Path(args.sim).resolve()), "serve", args.scenario,
                                "--config", str(config), "--out", str(tmp / "out"),
                                "--estimate-topic", SIDE_TOPIC, "--pilot-topic", PILOT_SIDE_TOPIC,
                                "--quiet"])
    try:
        deadline = time.monotonic() + 180.0
        while server.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.002)
        if server.poll() is None:
            server.kill()
        code = server.wait()
        summary_path = tmp / "out" / "summary.json"
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
        s = summary.get("summary", {})
        numbers = ", ".join(f"{k} {s[k]}" for k in sorted(s)
                            if isinstance(s[k], (int, float)))[:600]
        rate = 0.0
        if len(relayed) > 1:
            rate = (len(relayed) - 1) / (relayed[-1] - relayed[0])
        c.check(len(relayed) > 100, f"{name}: rclpy played the motion capture to the daemon",
                f"{len(relayed)} Odometry republished on {ESTIMATE_TOPIC} ({rate:.0f} Hz), "
                f"{len(pilots)} PilotInput on {PILOT_TOPIC}")
        if not lose_estimate:
            c.check(code == 0 and summary.get("succeeded") is True,
                    "the SITL wheel landing succeeded on rclpy's estimates",
                    f"serve exit {code}; {numbers}")
        else:
            failsafe = next((m for m in modes if cut and m[0] >= cut[0] and m[1] == "failsafe"),
                            None)
            c.check(failsafe is not None and failsafe[0] - cut[0] <= FAILSAFE_WITHIN_S,
                    f"motion capture cut for good in {CUT_IN_MODE}: failsafe",
                    (f"failsafe {failsafe[0] - cut[0]:.2f} s after the cut" if failsafe else
                     f"cut {'at ' + CUT_IN_MODE if cut else 'never'}; modes "
                     f"{[m[1] for m in modes]}"))
            after = [m[1] for m in modes if failsafe and m[0] >= failsafe[0]]
            tilt, speed = s.get("touchdown_tilt_deg"), s.get("impact_speed_mps")
            c.check(s.get("crashed") is False and tilt is not None and tilt > 30.0
                    and speed is not None and speed < 0.35
                    and not set(after) & {"takeoff", "flight", "morphing", "transition"},
                    "down level onto the wheels on PX4's estimate (no crash, > 30 deg, "
                    "< 0.35 m/s, never flying again)",
                    f"serve exit {code}; modes from the failsafe on {after}; {numbers}")
        daemon.send_signal(signal.SIGTERM)
        try:
            daemon_code = daemon.wait(timeout=20)
        except subprocess.TimeoutExpired:
            daemon_code = None
        c.check(daemon_code == 0, f"{name}: daemon exits 0 on SIGTERM",
                f"exit code {daemon_code}")
    finally:
        for p in (server, daemon):
            if p.poll() is None:
                p.kill()
                p.wait()
        node.destroy_node()
        rclpy.shutdown()
    return tmp


def main():
    args = sitl_arguments(__doc__, "rclpy_sitl")
    c = Checks()
    runs = [fly(args, c, lose_estimate) for lose_estimate in (False, True)]
    print(f"{c.passed} passed, {c.failed} failed", flush=True)
    if c.failed:
        for tmp in runs:
            for name in ("atmo-sim", "atmo-daemon"):
                print(f"--- {tmp} {name} stderr:\n{(tmp / f'{name}.stderr').read_text()[-2000:]}")
    return 1 if c.failed else 0


if __name__ == "__main__":
    sys.exit(main())
