"""Publishes a measurements CSV (`t,id,u,v`, as `roitrack simulate` writes it) on the ROS 2 DDS bus as
`roitrack_msgs/msg/BlobMeasurements` messages (the DDS topic `rt/roitrack/measurements`, type
`roitrack_msgs::msg::dds_::BlobMeasurements_`), with Eclipse Cyclone DDS: the input of `roitrack ros2-node` in its
tests. Each message holds --per-message centroids in the CSV's order, stamped with the first one's time rounded to
the nanosecond (as roitrack's bags are), the others at `dt_s` from it.

With --malformed, three malformed messages go out too, before the first good one and in the middle: `u_px` one
entry short, a point id the target does not have, a `v_px` that is NaN; the node must leave each out, name it, and
track the rest to the same estimates.

With --camera-info CAMERA.yaml (a ROS camera_info YAML as `roitrack simulate` writes it), the camera goes out first
on /roitrack/camera_info, reliable and transient local (latched), for a node without --camera.

It waits (up to --wait-s) for a subscriber, publishes reliably at --rate-hz messages a second, waits for every
message to be acknowledged, and prints `published N messages`.

    python ros2_measurement_publisher.py measurements.csv [--domain 0] [--rate-hz 400] [--malformed]
"""

import argparse
import csv
import dataclasses
import math
import re
import sys
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, sequence, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ros2_subscriber import LATCHED, CameraInfo, Header, RegionOfInterest, Time, ros_type


@dataclasses.dataclass
class BlobMeasurements(IdlStruct, typename=ros_type("roitrack_msgs", "BlobMeasurements")):
    header: Header
    point_ids: sequence[uint32]
    u_px: sequence[float64]
    v_px: sequence[float64]
    dt_s: sequence[float64]
    sigma_px: sequence[float64]


def camera_info(path):
    """The CameraInfo of a ROS camera_info YAML (its size, camera matrix and distortion; read by pattern)."""
    text = open(path).read()

    def number(key):
        return int(re.search(rf"^{key}: (\d+)$", text, re.M).group(1))

    def data(key):
        block = re.search(rf"^{key}:\n(?:  .*\n)*?  data: \[(.*)\]", text, re.M).group(1)
        return [float(x) for x in block.split(",")]

    k = data("camera_matrix")
    return CameraInfo(
        header=Header(stamp=Time(sec=0, nanosec=0), frame_id="camera"),
        height=number("image_height"), width=number("image_width"),
        distortion_model=re.search(r"^distortion_model: (\w+)$", text, re.M).group(1),
        d=data("distortion_coefficients"), k=k, r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p=[k[0], k[1], k[2], 0.0, k[3], k[4], k[5], 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x=0, binning_y=0,
        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


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


def wait_until(seen, wait_s, what):
    """Waits until `seen()` holds (a reader matched, a publisher discovered), at most `wait_s`: whether it did (if
    not, says `no WHAT`)."""
    start = time.monotonic()
    while not seen():
        if time.monotonic() - start > wait_s:
            print(f"no {what}", file=sys.stderr)
            return False
        time.sleep(0.01)
    return True


def publish_paced(writer, messages, rate_hz):
    """Writes `messages` at `rate_hz` from now, each when it is due (one that is late at once)."""
    start = time.monotonic()
    for k, m in enumerate(messages):
        due = start + k / rate_hz
        now = time.monotonic()
        if due > now:
            time.sleep(due - now)
        writer.write(m)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("measurements")
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--topic", default="/roitrack/measurements")
    parser.add_argument("--per-message", type=int, default=10)
    parser.add_argument("--rate-hz", type=float, default=400.0)
    parser.add_argument("--wait-s", type=float, default=30.0)
    parser.add_argument("--malformed", action="store_true")
    parser.add_argument("--camera-info", help="a camera_info YAML to publish, latched, on /roitrack/camera_info")
    args = parser.parse_args()

    with open(args.measurements) as f:
        rows = [(float(r[0]), int(r[1]), float(r[2]), float(r[3])) for r in csv.reader(f) if r and r[0][0].isdigit()]
    messages = [message(rows[k:k + args.per_message]) for k in range(0, len(rows), args.per_message)]
    if args.malformed:
        bad = malformed(rows[: args.per_message])
        middle = len(messages) // 2
        messages = [bad[0]] + messages[:middle] + bad[1:] + messages[middle:]

    participant = DomainParticipant(args.domain)
    if args.camera_info:
        info_topic = Topic(participant, "rt/roitrack/camera_info", CameraInfo, qos=LATCHED)
        info_writer = DataWriter(participant, info_topic, qos=LATCHED)
        info_writer.write(camera_info(args.camera_info))
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.Durability.Volatile, Policy.History.KeepAll)
    topic = Topic(participant, "rt" + args.topic, BlobMeasurements, qos=qos)
    writer = DataWriter(participant, topic, qos=qos)
    if not wait_until(writer.get_matched_subscriptions, args.wait_s, "subscriber"):
        return 1
    # The subscriber's side of the discovery (its matching of this writer).
    time.sleep(0.3)
    publish_paced(writer, messages, args.rate_hz)
    writer.wait_for_acks(duration(seconds=10))
    print(f"published {len(messages)} messages", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
