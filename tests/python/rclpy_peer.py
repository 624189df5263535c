"""rclpy on Fast DDS (ROS 2 Kilted from PyPI) as a peer of the UNMODIFIED
atmo-daemon binary, on loopback, in a domain of its own.

Run by scripts/ros2-peer.sh (which builds the venv and atmo_msgs):

    scripts/ros2-peer.sh test [path/to/atmo-daemon]

Checks, each printed PASS/FAIL with its numbers, then `N passed, M failed`
(exit 1 on any failure):
- the daemon's node, topics and type names appear in rclpy's graph;
- /diagnostics and /atmo/status arrive with ROS 2's default QoS (reliable)
  and with sensor-data QoS (best effort), nearly every tick;
- 120 Hz odometry (reliable and best-effort publishers) is accepted and
  shows in the status converted ENU -> NED; a pilot input is echoed exactly;
- a ground height on /atmo/ground (PointStamped, ENU) sets status.height,
  which falls back to the config's ground_z once the topic is silent for
  longer than ground_timeout_ms;
- header stamps are within 0.1 s of this machine's wall clock;
- the RIHS01 type hashes the daemon computes equal rclpy's;
- after SIGTERM the daemon exits 0, logs no RustDDS removal errors, and no
  endpoint of it is left in the graph 2 s later (the node's farewell SPDP
  dispose, atmo-io src/ros2/farewell.rs; ATMO_PEER_MEASURE_GHOSTS=1 measures
  how long they stay when they do).
"""

import argparse
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
NODE = "atmo_daemon"
TOPICS = {
    "/atmo/status": "atmo_msgs/msg/MpcStatus",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/atmo/mocap/odom": "nav_msgs/msg/Odometry",
    "/atmo/pilot": "atmo_msgs/msg/PilotInput",
    "/atmo/cmd_drive": "geometry_msgs/msg/Twist",
    "/atmo/ground": "geometry_msgs/msg/PointStamped",
}
STAMP_TOLERANCE_S = 0.1
GHOST_DEADLINE_S = 2.0
GROUND_ENU_Z = 1.0     # m, the ground height the peer publishes
GROUND_TIMEOUT_S = 1.0  # config/daemon.toml ground_timeout_ms


# Checks known to fail, with why; a failure of one is reported as XFAIL and
# not counted as failed, a pass as XPASS and counted as failed (remove it here).
KNOWN_FAILURES: dict[str, str] = {}


class Checks:
    def __init__(self):
        self.passed = 0
        self.failed = 0
        self.known = 0

    def check(self, ok, name, detail=""):
        known = next((why for k, why in KNOWN_FAILURES.items() if name.startswith(k)), None)
        if known is None:
            verdict = "PASS" if ok else "FAIL"
        else:
            verdict = "XPASS" if ok else "XFAIL"
        print(f"{verdict} {name}{': ' + detail if detail else ''}", flush=True)
        if known is not None and not ok:
            print(f"  known failure: {known}", flush=True)
            self.known += 1
        elif ok and known is None:
            self.passed += 1
        else:
            self.failed += 1
        return ok


def daemon_config(tmp: Path, tag: str) -> Path:
    """The shipped config with loopback-only DDS, absolute paths and an
    iceoryx2 prefix of its own (as crates/atmo-sim/tests/sim/sitl.rs does)."""
    config_dir = REPO / "config"
    text = (config_dir / "daemon.toml").read_text()
    shipped = text
    for key in ("robot", "flight", "mpc"):
        name = f"{'atmo' if key == 'robot' else key}.toml"
        text = text.replace(f'{key} = "{name}"', f'{key} = "{config_dir / name}"')
    if os.environ.get("ATMO_PEER_ALL_INTERFACES") != "1":  # 1: a one-off probe, not CI
        text = text.replace("loopback_only = false", "loopback_only = true")
    text = text.replace('iceoryx_prefix = ""', f'iceoryx_prefix = "{tag}_"')
    assert text != shipped
    path = tmp / "daemon.toml"
    path.write_text(text)
    return path


def sitl_arguments(doc: str, name: str):
    """The SITL tests' command line (--daemon, --sim, --scenario), the two
    binaries checked to exist."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--daemon", required=True)
    ap.add_argument("--sim", required=True)
    ap.add_argument("--scenario", default=str(REPO / "config/scenarios/wheel_landing.toml"))
    args = ap.parse_args()
    for binary in (args.daemon, args.sim):
        if not Path(binary).exists():
            sys.exit(f"{name}: {binary} does not exist: build it (cargo build)")
    return args


def odom_now(Odometry, yaw_enu):
    """The test's odometry: ENU position (1, 2, 3), yaw `yaw_enu`, stamped now."""
    odom = Odometry()
    odom.header.stamp.sec, odom.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
    odom.header.frame_id = "odom"
    odom.child_frame_id = "base_link"
    odom.pose.pose.position.x, odom.pose.pose.position.y = 1.0, 2.0
    odom.pose.pose.position.z = 3.0
    odom.pose.pose.orientation.z = math.sin(yaw_enu / 2)
    odom.pose.pose.orientation.w = math.cos(yaw_enu / 2)
    return odom


def stamp_s(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--daemon", required=True, help="the atmo-daemon binary")
    args = ap.parse_args()
    daemon_bin = Path(args.daemon).resolve()
    if not daemon_bin.exists():
        sys.exit(f"rclpy_peer: {daemon_bin} does not exist: build it (cargo build -p atmo-daemon)")

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, qos_profile_sensor_data
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PointStamped, Twist
    from nav_msgs.msg import Odometry
    from atmo_msgs.msg import MpcStatus, PilotInput

    c = Checks()
    domain = random.Random(os.getpid() ^ int(time.time())).randrange(110, 200)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    tmp = Path(tempfile.mkdtemp(prefix="atmo-rclpy-peer-"))
    tag = f"rclpy{os.getpid()}"
    config = daemon_config(tmp, tag)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
               RUST_LOG=os.environ.get("ATMO_PEER_RUST_LOG", "info,rustdds=warn"))
    stderr_path = tmp / "daemon.stderr"
    print(f"rclpy_peer: domain {domain}, run folder {tmp}, rmw "
          f"{os.environ.get('RMW_IMPLEMENTATION', '(default)')}", flush=True)

    rclpy.init(domain_id=domain)
    node = rclpy.create_node("atmo_rclpy_peer")
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def spin_for(seconds, until=None):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.005)
            if until is not None and until():
                return True
        return until() if until is not None else True

    # Subscriptions first (ROS 2 default QoS = reliable, keep last 10; and
    # sensor-data QoS = best effort), so they match as soon as the daemon is up.
    got = {k: [] for k in ("status_reliable", "status_best_effort",
                           "diag_reliable", "diag_best_effort")}

    def keep(key):
        return lambda msg: got[key].append((time.time(), msg))

    default_qos = QoSProfile(depth=10)
    node.create_subscription(MpcStatus, "/atmo/status", keep("status_reliable"), default_qos)
    node.create_subscription(MpcStatus, "/atmo/status", keep("status_best_effort"),
                             qos_profile_sensor_data)
    node.create_subscription(DiagnosticArray, "/diagnostics", keep("diag_reliable"), default_qos)
    node.create_subscription(DiagnosticArray, "/diagnostics", keep("diag_best_effort"),
                             qos_profile_sensor_data)
    odom_reliable = node.create_publisher(Odometry, "/atmo/mocap/odom", default_qos)
    odom_best_effort = node.create_publisher(Odometry, "/atmo/mocap/odom",
                                             qos_profile_sensor_data)
    pilot_pub = node.create_publisher(PilotInput, "/atmo/pilot", default_qos)
    node.create_publisher(Twist, "/atmo/cmd_drive", default_qos)  # for its type hash
    ground_pub = node.create_publisher(PointStamped, "/atmo/ground", default_qos)

    started = time.monotonic()
    daemon = subprocess.Popen(
        [str(daemon_bin), "run", "--config", str(config), "--log", str(tmp / "flight.mcap")],
        cwd=tmp, env=env, stdin=subprocess.DEVNULL,
        stdout=open(tmp / "daemon.stdout", "w"), stderr=open(stderr_path, "w"))
    try:
        run_checks(c, node, spin_for, got, daemon, started, stderr_path,
                   odom_reliable, odom_best_effort, pilot_pub, Odometry, PilotInput,
                   ground_pub, PointStamped)
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.wait()
        node.destroy_node()
        rclpy.shutdown()
    print(f"{c.passed} passed, {c.failed} failed"
          + (f" ({c.known} known failures, XFAIL above)" if c.known else ""), flush=True)
    if c.failed:
        print(f"daemon stderr ({stderr_path}):\n{stderr_path.read_text()[-3000:]}")
    return 1 if c.failed else 0


def daemon_endpoints(node):
    """(topic, kind, topic_type, type hash) of every endpoint on the daemon's
    topics that is not this peer's own."""
    own = node.get_fully_qualified_name()
    out = []
    for topic in TOPICS:
        for kind, infos in (("pub", node.get_publishers_info_by_topic(topic)),
                            ("sub", node.get_subscriptions_info_by_topic(topic))):
            for info in infos:
                if f"{info.node_namespace.rstrip('/')}/{info.node_name}" != own:
                    out.append((topic, kind, info.topic_type, str(info.topic_type_hash),
                                info.node_name))
    return out


def own_type_hashes(node):
    """rclpy's RIHS01 hash of each topic's type, from its own endpoints."""
    own = node.get_fully_qualified_name()
    hashes = {}
    for topic in TOPICS:
        infos = node.get_publishers_info_by_topic(topic) + node.get_subscriptions_info_by_topic(topic)
        for info in infos:
            if f"{info.node_namespace.rstrip('/')}/{info.node_name}" == own:
                hashes[topic] = str(info.topic_type_hash)
    return hashes


def run_checks(c, node, spin_for, got, daemon, started, stderr_path,
               odom_reliable, odom_best_effort, pilot_pub, Odometry, PilotInput,
               ground_pub, PointStamped):
    # --- graph: node, topics, type names.
    def graph_complete():
        names = {n for n, _ in node.get_node_names_and_namespaces()}
        types = dict(node.get_topic_names_and_types())
        endpoints = {(t, ty) for t, _, ty, _, _ in daemon_endpoints(node)}
        return NODE in names and all(
            want in types.get(t, []) and (t, want) in endpoints for t, want in TOPICS.items())

    seen = spin_for(20.0, graph_complete)
    discovery = time.monotonic() - started
    c.check(seen, "graph: daemon node, topics and type names seen",
            f"{discovery:.2f} s after the daemon started")
    if not seen:
        print(f"  graph: nodes {node.get_node_names_and_namespaces()}, "
              f"topics {node.get_topic_names_and_types()}")
        return

    # --- inputs: 120 Hz odometry (reliable and best effort) and 50 Hz pilot.
    # ENU position (1, 2, 3) is NED (2, 1, -3); ENU/FLU yaw +0.3 rad is NED/FRD
    # yaw pi/2 - 0.3.
    yaw_enu = 0.3
    pilot = PilotInput(velocity=[0.25, -0.5, 0.125], yaw_rate=0.0625, throttle=0.375,
                       arm=False, offboard=False, mpc_enabled=True)
    period = 1.0 / 120.0
    next_odom = time.monotonic()
    next_pilot = next_odom
    k = 0
    send_end = time.monotonic() + 3.0
    for key in got:
        got[key].clear()
    t_window = time.time()
    # The ground (ENU z = 1 m, up) from the window's second half on.
    ground_from = time.monotonic() + 1.5
    next_ground = ground_from
    ground = PointStamped()
    ground.header.frame_id = "odom"
    ground.point.x, ground.point.y, ground.point.z = 1.0, 2.0, GROUND_ENU_Z
    first_ground_wall = None
    while time.monotonic() < send_end:
        now = time.monotonic()
        if now >= next_ground:
            ground.header.stamp.sec, ground.header.stamp.nanosec = divmod(time.time_ns(), 10**9)
            ground_pub.publish(ground)
            first_ground_wall = first_ground_wall or time.time()
            next_ground += 0.05
        if now >= next_odom:
            odom = odom_now(Odometry, yaw_enu)
            (odom_reliable if k % 2 == 0 else odom_best_effort).publish(odom)
            k += 1
            next_odom += period
        if now >= next_pilot:
            pilot_pub.publish(pilot)
            next_pilot += 0.02
        node.executor.spin_once(timeout_sec=0.001)
    window = time.time() - t_window
    last_ground_wall = time.time()

    # --- status and diagnostics, both QoS.
    diag_values = {}  # the node's own counters, from its last diagnostics
    for _, arr in got["diag_reliable"] + got["diag_best_effort"]:
        for st in arr.status:
            if st.name == "atmo/ros2":
                diag_values = {kv.key: kv.value for kv in st.values}
    for key, label in (("status_reliable", "reliable (ROS 2 default)"),
                       ("status_best_effort", "best effort (sensor data)")):
        msgs = got[key]
        ticks = [m.tick for _, m in msgs]
        span = (max(ticks) - min(ticks) + 1) if ticks else 0
        ratio = len(set(ticks)) / span if span else 0.0
        rate = len(msgs) / window
        c.check(len(msgs) > 0 and ratio >= 0.9,
                f"/atmo/status received, {label}",
                f"{len(msgs)} in {window:.2f} s ({rate:.0f} Hz), {ratio:.1%} of the ticks "
                f"{min(ticks) if ticks else '-'}..{max(ticks) if ticks else '-'}; the node: "
                f"publish_errors {diag_values.get('publish_errors')} (reliable window full), "
                f"publish_dropped {diag_values.get('publish_dropped')}")
    for key, label in (("diag_reliable", "reliable (ROS 2 default)"),
                       ("diag_best_effort", "best effort (sensor data)")):
        c.check(len(got[key]) >= 2, f"/diagnostics received, {label}",
                f"{len(got[key])} arrays in {window:.2f} s")

    statuses = [m for _, m in got["status_reliable"]] or [m for _, m in got["status_best_effort"]]
    if not statuses:
        return
    last = statuses[-1]

    # --- odometry accepted and converted, pilot echoed.
    want = [2.0, 1.0, -3.0, math.pi / 2 - yaw_enu]
    state = list(last.state[:4])
    c.check(all(abs(a - b) < 1e-9 for a, b in zip(state, want)),
            "odometry accepted, ENU -> NED in status.state",
            f"x y z yaw = {[round(v, 6) for v in state]}, want {[round(v, 6) for v in want]}")
    c.check(0.0 <= last.estimate_age < 0.5, "status.estimate_age of a live estimate",
            f"{last.estimate_age:.4f} s")
    accepted = int(diag_values.get("estimates_accepted", "0"))
    c.check(accepted >= 0.8 * k and int(diag_values.get("invalid", "1")) == 0,
            "odometry over reliable and best-effort publishers accepted (diagnostics)",
            f"estimates_accepted {accepted} of {k} sent, invalid {diag_values.get('invalid')}, "
            f"malformed {diag_values.get('malformed')}")
    echoed = (list(last.pilot.velocity), last.pilot.yaw_rate, last.pilot.throttle,
              last.pilot.arm, last.pilot.offboard, last.pilot.mpc_enabled)
    sent = (list(pilot.velocity), pilot.yaw_rate, pilot.throttle,
            pilot.arm, pilot.offboard, pilot.mpc_enabled)
    c.check(echoed == sent, "pilot input echoed exactly in status.pilot", f"{echoed}")

    # --- ground height: NED z -3 over ground_z 0 is 3 m; over the topic's
    # ground (ENU z 1) 2 m; the config again once the topic is stale.
    before = [m.height for recv, m in got["status_reliable"]
              if recv < first_ground_wall and abs(m.state[2] + 3.0) < 1e-9]
    c.check(bool(before) and all(abs(h - 3.0) < 1e-9 for h in before)
            and abs(last.height - (3.0 - GROUND_ENU_Z)) < 1e-9,
            "ground height from /atmo/ground (ENU) in status.height",
            f"before the topic {sorted(set(round(h, 6) for h in before))}, "
            f"with it {last.height:.6f}, want 3.0 then {3.0 - GROUND_ENU_Z}")

    # --- stamps: ROS time (wall clock) within 0.1 s of reception.
    offsets = [recv - stamp_s(m.header.stamp) for recv, m in got["status_reliable"]]
    diag_offsets = [recv - stamp_s(m.header.stamp)
                    for recv, m in got["diag_reliable"] + got["diag_best_effort"]]
    # Reception is when the Python callback ran: on a loaded machine it can
    # lag the arrival, so the median is held to the tolerance and every stamp
    # to "not after its reception" (one clock; 1 ms for the two readings).
    def judge(offs):
        if not offs:
            return False, "none received"
        med = sorted(offs)[len(offs) // 2]
        ok = abs(med) <= STAMP_TOLERANCE_S and min(offs) >= -1e-3
        return ok, (f"reception - stamp: median {med * 1e3:.2f} ms, min {min(offs) * 1e3:.2f} ms, "
                    f"max {max(offs) * 1e3:.2f} ms over {len(offs)}")
    c.check(*judge(offsets)[:1], "status header.stamp is wall-clock ROS time", judge(offsets)[1])
    c.check(*judge(diag_offsets)[:1], "diagnostics header.stamp is wall-clock ROS time",
            judge(diag_offsets)[1])
    ticks_clock = [m.clock_ns for m in statuses]
    c.check(all(b > a for a, b in zip(ticks_clock, ticks_clock[1:])) and ticks_clock[0] < 600e9,
            "status.clock_ns is the stack's monotonic clock",
            f"{ticks_clock[0] * 1e-9:.3f} .. {ticks_clock[-1] * 1e-9:.3f} s since start")

    # --- ground height again, once its topic is stale.
    stale_heights = []
    keep_odom_until = time.monotonic() + GROUND_TIMEOUT_S + 0.5
    got["status_reliable"].clear()
    while time.monotonic() < keep_odom_until:
        odom_reliable.publish(odom_now(Odometry, yaw_enu))
        spin_for(period)
    stale_heights = [m.height for recv, m in got["status_reliable"]
                     if recv > last_ground_wall + GROUND_TIMEOUT_S + 0.1]
    c.check(bool(stale_heights) and all(abs(h - 3.0) < 1e-9 for h in stale_heights),
            f"status.height back on the config's ground_z {GROUND_TIMEOUT_S:.0f} s after "
            "the ground topic went silent",
            f"{sorted(set(round(h, 6) for h in stale_heights))} over {len(stale_heights)} statuses")

    # --- type hashes: the daemon's (diagnostics) against rclpy's own.
    rclpy_hashes = own_type_hashes(node)
    daemon_hashes = {k[len("type_hash "):]: v for k, v in diag_values.items()
                     if k.startswith("type_hash ")}
    mismatched = {t: (daemon_hashes.get(t), h) for t, h in rclpy_hashes.items()
                  if daemon_hashes.get(t) != h}
    c.check(len(rclpy_hashes) == len(TOPICS) and not mismatched
            and all(h.startswith("RIHS01_") for h in rclpy_hashes.values()),
            "RIHS01 type hashes: the daemon's equal rclpy's",
            f"{len(rclpy_hashes)} topics" + (f", mismatched {mismatched}" if mismatched else ""))
    announced = sorted({h for _, _, _, h, _ in daemon_endpoints(node)})
    print(f"note: the daemon's endpoints announce type hash {announced} in discovery "
          "(RustDDS 0.15 sends no endpoint USER_DATA)", flush=True)

    # --- shutdown: exit 0, no removal errors, no ghost endpoints after 2 s.
    before = len(daemon_endpoints(node))
    daemon.send_signal(signal.SIGTERM)
    t_term = time.monotonic()
    gone = spin_for(GHOST_DEADLINE_S, lambda: not daemon_endpoints(node))
    gone_after = time.monotonic() - t_term
    left = daemon_endpoints(node)
    if left and os.environ.get("ATMO_PEER_MEASURE_GHOSTS") == "1":
        spin_for(120.0, lambda: not daemon_endpoints(node))
        print(f"measured: the daemon's endpoints left the graph "
              f"{time.monotonic() - t_term:.1f} s after SIGTERM", flush=True)
    c.check(gone, f"no daemon endpoint in the graph {GHOST_DEADLINE_S:.0f} s after SIGTERM",
            f"{before} endpoints before, gone after {gone_after:.2f} s" if gone
            else f"{len(left)} of {before} left: {left}")
    try:
        code = daemon.wait(timeout=20)
    except subprocess.TimeoutExpired:
        code = None
    c.check(code == 0, "daemon exits 0 on SIGTERM", f"exit code {code}")
    stderr = stderr_path.read_text()
    errors = [ln for ln in stderr.splitlines() if "Cannot remove" in ln or " ERROR " in ln]
    c.check(not errors, "no RustDDS removal errors at shutdown (RUST_LOG=rustdds=warn)",
            f"{len(errors)} lines" + (f", first: {errors[0][:200]}" if errors else ""))


if __name__ == "__main__":
    sys.exit(main())
