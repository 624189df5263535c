#!/usr/bin/env python3
"""A ROS 2 peer written with Eclipse Cyclone DDS (no ROS 2 installed): it
receives the daemon's status topic and publishes motion-capture odometry
the way a ROS 2 node does (`rt/` topic names, `pkg::msg::dds_::Type_` type
names, classic CDR). Driven by crates/atmo-io/tests/ros2_python_peer.rs,
which judges what this script prints (JSON lines on stdout):

  {"kind": "status", "msg": {...}}     each status received (floats as their
                                       IEEE-754 bits, non-finite floats: null)
  {"kind": "odom", "msg": {...}}       each odometry sent, exactly as sent
  {"kind": "done", ...}                the end

Usage: dds_peer.py DOMAIN [--statuses N] [--odometry N] [--timeout S]
Needs CYCLONEDDS_URI pointing at tests/python/cyclonedds-loopback.xml.
"""

import argparse
import dataclasses
import json
import math
import struct
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from ros2_types import MpcStatus, Odometry, Header, Time


def plain(value):
    """A decoded IDL value as JSON-ready data. Floats travel exactly, as the
    integer of their IEEE-754 bits (a decimal text would be re-parsed
    inexactly by some readers); non-finite floats become None."""
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, float):
        if not math.isfinite(value):
            return None
        return struct.unpack("<Q", struct.pack("<d", value))[0]
    return value


def emit(kind, **fields):
    print(json.dumps({"kind": kind, **fields}), flush=True)


def odometry(k, stamp_sec):
    """Motion capture in ENU/FLU: yaw 0.4 rad about up, flying forward."""
    odom = Odometry(header=Header(stamp=Time(sec=stamp_sec, nanosec=0), frame_id="odom"),
                    child_frame_id="base_link")
    odom.pose.pose.position.x = 0.1 * k
    odom.pose.pose.position.y = 2.0
    odom.pose.pose.position.z = 1.5
    odom.pose.pose.orientation.z = math.sin(0.2)
    odom.pose.pose.orientation.w = math.cos(0.2)
    odom.twist.twist.linear.x = 1.0
    odom.twist.twist.linear.y = 0.5
    odom.twist.twist.angular.z = 0.2
    return odom


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("domain", type=int)
    ap.add_argument("--statuses", type=int, default=30)
    ap.add_argument("--odometry", type=int, default=40)
    ap.add_argument("--timeout", type=float, default=25.0)
    args = ap.parse_args()

    # Best effort, volatile; classic CDR (XCDR1), which is what ROS 2 and RustDDS speak.
    qos = Qos(
        Policy.Reliability.BestEffort,
        Policy.Durability.Volatile,
        Policy.History.KeepLast(1),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )
    reader_qos = Qos(
        Policy.Reliability.BestEffort,
        Policy.Durability.Volatile,
        Policy.History.KeepLast(1000),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )
    dp = DomainParticipant(args.domain)
    status_reader = DataReader(dp, Topic(dp, "rt/atmo/status", MpcStatus), qos=reader_qos)
    odom_writer = DataWriter(dp, Topic(dp, "rt/atmo/mocap/odom", Odometry), qos=qos)

    deadline = time.monotonic() + args.timeout
    statuses = 0
    sent = 0
    bad_sent = False

    def take_statuses():
        nonlocal statuses
        for sample in status_reader.take(N=1000):
            if statuses < args.statuses:
                emit("status", msg=plain(sample))
            statuses += 1

    # Discovery: the daemon's status reaches us, and our writer is matched.
    while statuses == 0 or not odom_writer.get_matched_subscriptions():
        if time.monotonic() > deadline:
            emit("done", ok=False, reason="no discovery", statuses=statuses)
            return 1
        take_statuses()
        time.sleep(0.01)

    while sent < args.odometry or statuses < args.statuses or not bad_sent:
        if time.monotonic() > deadline:
            emit("done", ok=False, reason="timeout", statuses=statuses, sent=sent)
            return 1
        take_statuses()
        if sent < args.odometry:
            odom = odometry(sent, 200 + sent)
            odom_writer.write(odom)
            emit("odom", msg=plain(odom))
            sent += 1
        elif not bad_sent:
            # Bad inputs the daemon must count and survive: NaN, a stamp going
            # backwards (each three times: best effort), then good data again.
            for i in range(3):
                nan = odometry(0, 300 + i)
                nan.pose.pose.position.x = float("nan")
                odom_writer.write(nan)
                time.sleep(0.02)
            for _ in range(3):
                odom_writer.write(odometry(0, 100))
                time.sleep(0.02)
            for i in range(3):
                odom = odometry(sent + i, 400 + i)
                odom_writer.write(odom)
                emit("odom", msg=plain(odom))
                time.sleep(0.02)
            bad_sent = True
        time.sleep(0.02)
    emit("done", ok=True, statuses=statuses, sent=sent)
    return 0


if __name__ == "__main__":
    sys.exit(main())
