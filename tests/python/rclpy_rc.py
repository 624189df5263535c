"""The SITL wheel landing flown on the radio, PX4 played by rclpy on Fast DDS.

Three processes on loopback, in a domain of their own: the UNMODIFIED
atmo-daemon binary, configured as on the robot (estimate
px4_msgs/VehicleOdometry on /fmu/out/vehicle_odometry, pilot
px4_msgs/InputRc on /fmu/out/input_rc, the atmo_msgs pilot topic off);
`atmo-sim serve` (the plant, every driver), publishing its estimate and its
scenario's pilot on side topics; and this rclpy node, which plays PX4's
uXRCE-DDS bridge: each VehicleOdometry is republished on
/fmu/out/vehicle_odometry and each pilot input becomes an InputRc frame
(the authors' Futaba T18SZ channels and pulse range, config/daemon.toml
[rc]) on /fmu/out/input_rc, best effort like PX4.

Checks, against the daemon's /atmo/status:
- the daemon arms on the radio and flies;
- the radio silent for 0.8 s in the air: failsafe, then flight again;
- PX4's rc_lost flag for 0.8 s in the air: failsafe, then flight again;
- on the ground after the landing, the kill switch: disarmed at once
  (the status's transition says why);
- the daemon exits 0 on SIGTERM.

Run by scripts/ros2-peer.sh (which builds the venv, atmo_msgs and the
test's px4_msgs):

    scripts/ros2-peer.sh rc [path/to/atmo-daemon [path/to/atmo-sim]]

Prints PASS/FAIL lines and `N passed, M failed`; exit 1 on any failure.
"""

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

ODOM_SIDE = "/atmo/sim/odom"
PILOT_SIDE = "/atmo/sim/pilot"
ODOM_TOPIC = "/fmu/out/vehicle_odometry"
RC_TOPIC = "/fmu/out/input_rc"
STATUS_TOPIC = "/atmo/status"

# config/daemon.toml [rc] defaults (the authors' Futaba T18SZ mapping).
MIN_US, CENTER_US, MAX_US, DEADBAND_US = 1094, 1514, 1934, 10
MAX_H, MAX_V, MAX_YAW = 0.75, 0.75, 45.0 * 3.141592653589793 / 180.0
CH_ROLL, CH_PITCH, CH_THROTTLE, CH_YAW = 1, 2, 3, 4
CH_KILL, CH_MPC, CH_OFFBOARD = 5, 8, 9
CH_TILT_LEVER, CH_ENCODER_RESET = 10, 12  # auxiliary: the encoder reset stays off (low)

LOSS_S = 0.8        # how long the radio is lost each time
FAILSAFE_WITHIN_S = 0.6   # rc.timeout_ms (300) + ticks + DDS
RECOVER_WITHIN_S = 4.0    # failsafe hold 0.5 s + tilting back


def pulse(norm):
    """The pulse (us) the daemon's mapping reads as `norm` in [-1, 1]."""
    norm = max(-1.0, min(1.0, norm))
    if norm == 0.0:
        return CENTER_US
    if norm > 0.0:
        return round(CENTER_US + DEADBAND_US + norm * (MAX_US - CENTER_US - DEADBAND_US))
    return round(CENTER_US - DEADBAND_US + norm * (CENTER_US - MIN_US - DEADBAND_US))


def rc_config(tmp: Path, tag: str) -> Path:
    """The test's daemon config with the robot's sources (config/daemon-robot.toml's)."""
    path = daemon_config(tmp, tag)
    text = path.read_text()
    shipped = text
    text = text.replace(
        'estimate = { name = "/atmo/mocap/odom", type = "nav_msgs/msg/Odometry" }',
        f'estimate = {{ name = "{ODOM_TOPIC}", type = "px4_msgs/msg/VehicleOdometry" }}')
    text = text.replace(
        'pilot = { name = "/atmo/pilot", type = "atmo_msgs/msg/PilotInput" }',
        'pilot = { name = "/atmo/pilot", type = "atmo_msgs/msg/PilotInput", enabled = false }')
    text = text.replace(
        f'rc = {{ name = "{RC_TOPIC}", type = "px4_msgs/msg/InputRc", enabled = false }}',
        f'rc = {{ name = "{RC_TOPIC}", type = "px4_msgs/msg/InputRc" }}')
    # The estimate's own line (the disabled autopilot_estimate names the
    # same topic and stays off).
    estimate_lines = [line for line in text.splitlines()
                      if line.startswith(f'estimate = {{ name = "{ODOM_TOPIC}"')]
    assert len(estimate_lines) == 1 and "enabled = false }" in text and text != shipped
    path.write_text(text)
    return path


def main():
    args = sitl_arguments(__doc__, "rclpy_rc")

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from atmo_msgs.msg import MpcStatus, PilotInput
    from px4_msgs.msg import InputRc, VehicleOdometry

    c = Checks()
    domain = random.Random(os.getpid() ^ int(time.time())).randrange(200, 232)
    tmp = Path(tempfile.mkdtemp(prefix="atmo-rclpy-rc-"))
    config = rc_config(tmp, f"rrc{os.getpid()}")
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    print(f"rclpy_rc: domain {domain}, run folder {tmp}", flush=True)

    rclpy.init(domain_id=domain)
    node = rclpy.create_node("px4_bridge_player")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    odom_pub = node.create_publisher(VehicleOdometry, ODOM_TOPIC, qos_profile_sensor_data)
    rc_pub = node.create_publisher(InputRc, RC_TOPIC, qos_profile_sensor_data)
    state = {"odom": 0, "rc": 0, "silent": False, "lost_flag": False, "kill": False}
    modes = []  # (monotonic time, mode name, transition)

    def play_odom(msg):
        odom_pub.publish(msg)
        state["odom"] += 1

    def play_pilot(p):
        if state["odom"] < 20 or state["silent"]:
            return
        rc = InputRc()
        now_us = int(time.monotonic() * 1e6)
        rc.timestamp = now_us
        rc.timestamp_last_signal = now_us
        rc.channel_count = 16
        rc.rssi = 100
        rc.rc_lost = state["lost_flag"]
        rc.input_source = InputRc.RC_INPUT_SOURCE_PX4FMU_SBUS
        values = [MIN_US] * 18
        # The mapping's signs: north and east and yaw reversed, up not.
        values[CH_PITCH - 1] = pulse(-p.velocity[0] / MAX_H)
        values[CH_ROLL - 1] = pulse(-p.velocity[1] / MAX_H)
        values[CH_THROTTLE - 1] = pulse(-p.velocity[2] / MAX_V)
        values[CH_YAW - 1] = pulse(-p.yaw_rate / MAX_YAW)
        values[CH_OFFBOARD - 1] = MAX_US if (p.arm and p.offboard) else MIN_US
        values[CH_MPC - 1] = MAX_US if p.mpc_enabled else MIN_US
        values[CH_KILL - 1] = MAX_US if state["kill"] else MIN_US
        values[CH_TILT_LEVER - 1] = CENTER_US  # the manual tilt lever at rest
        rc.values = values
        rc.link_quality = -1
        rc.rssi_dbm = float("nan")
        rc_pub.publish(rc)
        state["rc"] += 1

    def on_status(s):
        name = s.mode_name
        if not modes or modes[-1][1] != name:
            modes.append((time.monotonic(), name, s.transition))

    node.create_subscription(VehicleOdometry, ODOM_SIDE, play_odom, qos_profile_sensor_data)
    node.create_subscription(PilotInput, PILOT_SIDE, play_pilot, qos_profile_sensor_data)
    node.create_subscription(MpcStatus, STATUS_TOPIC, on_status, qos_profile_sensor_data)

    def spawn(name, argv):
        return subprocess.Popen(argv, cwd=tmp, env=env, stdin=subprocess.DEVNULL,
                                stdout=open(tmp / f"{name}.stdout", "w"),
                                stderr=open(tmp / f"{name}.stderr", "w"))

    def spin_until(pred, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.002)
            if pred():
                return True
        return False

    def mode():
        return modes[-1][1] if modes else None

    def mode_since(t, names):
        return next((m for m in modes if m[0] >= t and m[1] in names), None)

    def lose_radio(how):
        """The radio lost for LOSS_S in the air, `how` = silent | flag."""
        spin_until(lambda: mode() in ("flight", "morphing"), 10.0)
        before = mode()
        start = time.monotonic()
        state["silent" if how == "silent" else "lost_flag"] = True
        spin_until(lambda: False, LOSS_S)
        state["silent"] = state["lost_flag"] = False
        back = time.monotonic()
        failsafe = mode_since(start, ("failsafe",))
        c.check(failsafe is not None and failsafe[0] - start <= FAILSAFE_WITHIN_S,
                f"radio lost ({how}) in the air: failsafe",
                f"from {before}: " + (f"failsafe {failsafe[0] - start:.2f} s after the loss"
                                      if failsafe else f"modes {[m[1] for m in modes][-5:]}"))
        spin_until(lambda: mode() in ("flight", "morphing", "transition"), RECOVER_WITHIN_S)
        recovered = mode_since(back, ("flight", "morphing", "transition"))
        c.check(recovered is not None, f"radio back ({how}): flying again",
                f"{recovered[1]} {recovered[0] - back:.2f} s after" if recovered else f"mode {mode()}")

    daemon = spawn("atmo-daemon", [str(Path(args.daemon).resolve()), "run", "--config",
                                   str(config), "--log", str(tmp / "flight.mcap")])
    server = spawn("atmo-sim", [str(Path(args.sim).resolve()), "serve", args.scenario,
                                "--config", str(config), "--out", str(tmp / "out"),
                                "--estimate-topic", ODOM_SIDE, "--pilot-topic", PILOT_SIDE,
                                "--quiet"])
    try:
        armed = spin_until(lambda: mode() not in (None, "disarmed"), 60.0)
        c.check(armed, "the daemon arms on the radio",
                f"{state['odom']} VehicleOdometry and {state['rc']} InputRc played; modes "
                f"{[m[1] for m in modes]}")
        if armed:
            lose_radio("silent")
            lose_radio("flag")
            landed = spin_until(lambda: mode() == "drive", 30.0)
            c.check(landed, "landed on the wheels on the radio (drive)", f"modes {[m[1] for m in modes]}")
            kill = time.monotonic()
            state["kill"] = True
            spin_until(lambda: mode() == "disarmed", 2.0)
            off = mode_since(kill, ("disarmed",))
            c.check(off is not None and off[0] - kill < 0.2, "kill switch: disarmed at once",
                    f"{off[0] - kill:.3f} s, transition '{off[2]}'" if off else f"mode {mode()}")
        daemon.send_signal(signal.SIGTERM)
        try:
            daemon_code = daemon.wait(timeout=20)
        except subprocess.TimeoutExpired:
            daemon_code = None
        c.check(daemon_code == 0, "daemon exits 0 on SIGTERM", f"exit code {daemon_code}")
    finally:
        for p in (server, daemon):
            if p.poll() is None:
                p.kill()
                p.wait()
        node.destroy_node()
        rclpy.shutdown()
    print(f"{c.passed} passed, {c.failed} failed", flush=True)
    if c.failed:
        for name in ("atmo-sim", "atmo-daemon"):
            print(f"--- {name} stderr:\n{(tmp / f'{name}.stderr').read_text()[-2000:]}")
    return 1 if c.failed else 0


if __name__ == "__main__":
    sys.exit(main())
