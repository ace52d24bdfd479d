"""Publishes a measurements CSV (`t,id,u,v`, as `roitrack simulate` writes it) on the ROS 2 DDS bus as
`roitrack_msgs/msg/BlobMeasurements` messages (the DDS topic `rt/roitrack/measurements`, type
`roitrack_msgs::msg::dds_::BlobMeasurements_`), with Eclipse Cyclone DDS: the input of `roitrack ros2-node` in its
tests. Each message holds --per-message centroids in the CSV's order, stamped with the first one's time rounded to
the nanosecond (as roitrack's bags are), the others at `dt_s` from it.

With --malformed, three malformed messages go out too, before the first good one and in the middle: `u_px` one
entry short, a point id the target does not have, a `v_px` that is NaN; the node must leave each out, name it, and
track the rest to the same estimates.

It waits (up to --wait-s) for a subscriber, publishes reliably at --rate-hz messages a second, waits for every
message to be acknowledged, and prints `published N messages`.

    python ros2_measurement_publisher.py measurements.csv [--domain 0] [--rate-hz 400] [--malformed]
"""

import argparse
import csv
import dataclasses
import math
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, sequence, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ros2_subscriber import Header, Time, ros_type


@dataclasses.dataclass
class BlobMeasurements(IdlStruct, typename=ros_type("roitrack_msgs", "BlobMeasurements")):
    header: Header
    point_ids: sequence[uint32]
    u_px: sequence[float64]
    v_px: sequence[float64]
    dt_s: sequence[float64]
    sigma_px: sequence[float64]


def message(rows, frame_id="camera"):
    """A BlobMeasurements of `rows` (t, id, u, v), stamped with the first time rounded to the nanosecond."""
    stamp_ns = round(rows[0][0] * 1e9)
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    stamp_s = sec + nanosec * 1e-9
    return BlobMeasurements(
        header=Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame_id),
        point_ids=[r[1] for r in rows],
        u_px=[r[2] for r in rows],
        v_px=[r[3] for r in rows],
        dt_s=[r[0] - stamp_s for r in rows],
        sigma_px=[],
    )


def malformed(rows):
    """Three messages that roitrack must leave out: an array short, an unknown id, a NaN."""
    short = message(rows)
    short.u_px = short.u_px[:-1]
    unknown = message(rows)
    unknown.point_ids = [9999] + unknown.point_ids[1:]
    nan = message(rows)
    nan.v_px = [math.nan] + nan.v_px[1:]
    return [short, unknown, nan]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("measurements")
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--topic", default="/roitrack/measurements")
    parser.add_argument("--per-message", type=int, default=10)
    parser.add_argument("--rate-hz", type=float, default=400.0)
    parser.add_argument("--wait-s", type=float, default=30.0)
    parser.add_argument("--malformed", action="store_true")
    args = parser.parse_args()

    with open(args.measurements) as f:
        rows = [(float(r[0]), int(r[1]), float(r[2]), float(r[3])) for r in csv.reader(f) if r and r[0][0].isdigit()]
    messages = [message(rows[k:k + args.per_message]) for k in range(0, len(rows), args.per_message)]
    if args.malformed:
        bad = malformed(rows[: args.per_message])
        middle = len(messages) // 2
        messages = [bad[0]] + messages[:middle] + bad[1:] + messages[middle:]

    participant = DomainParticipant(args.domain)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepAll)
    topic = Topic(participant, "rt" + args.topic, BlobMeasurements, qos=qos)
    writer = DataWriter(participant, topic, qos=qos)
    start = time.monotonic()
    while not writer.get_matched_subscriptions():
        if time.monotonic() - start > args.wait_s:
            print("no subscriber", file=sys.stderr)
            return 1
        time.sleep(0.01)
    # The subscriber's side of the discovery (its matching of this writer).
    time.sleep(0.3)
    start = time.monotonic()
    for k, m in enumerate(messages):
        due = start + k / args.rate_hz
        now = time.monotonic()
        if due > now:
            time.sleep(due - now)
        writer.write(m)
    writer.wait_for_acks(duration(seconds=10))
    print(f"published {len(messages)} messages", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
