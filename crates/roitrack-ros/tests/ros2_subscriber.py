"""An independent ROS 2 subscriber of roitrack's estimates: Eclipse Cyclone DDS (the PyPI package `cyclonedds`, one of
ROS 2's middlewares), with the ROS 2 topic and type names (`/roitrack/pose` is the DDS topic `rt/roitrack/pose` of
type `geometry_msgs::msg::dds_::PoseWithCovarianceStamped_`) and the types declared here from their `.msg`
definitions, as rosidl maps them to IDL. No ROS install.

It subscribes to every topic roitrack publishes with the QoS a ROS 2 subscriber would ask for (best effort for the
estimates and the status, reliable for /tf, reliable and transient local for the camera info), decodes every
message and writes one JSON object a line to --out: the topic, the time it was taken (ns, wall clock), the DDS
source timestamp (ns, the publisher's wall clock at the write) and the message's fields. It prints `ready` once its
readers exist, and ends when --count estimates (pose messages) have come, when no message has come for --idle-s
after the first estimate (a camera info latched by another node, which comes long before, does not start the
count), or after --timeout-s.

    python ros2_subscriber.py --domain 0 --out received.jsonl [--namespace /robot1] [--count N]
"""

import argparse
import dataclasses
import json
import sys
import time

from cyclonedds.core import Policy, Qos, ReadCondition, SampleState, ViewState, InstanceState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


def ros_type(package, name):
    """The DDS type name rosidl gives `package/msg/name`."""
    return f"{package}::msg::dds_::{name}_"


@dataclasses.dataclass
class Time(IdlStruct, typename=ros_type("builtin_interfaces", "Time")):
    sec: int32
    nanosec: uint32


@dataclasses.dataclass
class Header(IdlStruct, typename=ros_type("std_msgs", "Header")):
    stamp: Time
    frame_id: str


@dataclasses.dataclass
class Point(IdlStruct, typename=ros_type("geometry_msgs", "Point")):
    x: float64
    y: float64
    z: float64


@dataclasses.dataclass
class Vector3(IdlStruct, typename=ros_type("geometry_msgs", "Vector3")):
    x: float64
    y: float64
    z: float64


@dataclasses.dataclass
class Quaternion(IdlStruct, typename=ros_type("geometry_msgs", "Quaternion")):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclasses.dataclass
class Pose(IdlStruct, typename=ros_type("geometry_msgs", "Pose")):
    position: Point
    orientation: Quaternion


@dataclasses.dataclass
class PoseWithCovariance(IdlStruct, typename=ros_type("geometry_msgs", "PoseWithCovariance")):
    pose: Pose
    covariance: array[float64, 36]


@dataclasses.dataclass
class PoseWithCovarianceStamped(IdlStruct, typename=ros_type("geometry_msgs", "PoseWithCovarianceStamped")):
    header: Header
    pose: PoseWithCovariance


@dataclasses.dataclass
class Twist(IdlStruct, typename=ros_type("geometry_msgs", "Twist")):
    linear: Vector3
    angular: Vector3


@dataclasses.dataclass
class TwistWithCovariance(IdlStruct, typename=ros_type("geometry_msgs", "TwistWithCovariance")):
    twist: Twist
    covariance: array[float64, 36]


@dataclasses.dataclass
class TwistWithCovarianceStamped(IdlStruct, typename=ros_type("geometry_msgs", "TwistWithCovarianceStamped")):
    header: Header
    twist: TwistWithCovariance


@dataclasses.dataclass
class Odometry(IdlStruct, typename=ros_type("nav_msgs", "Odometry")):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclasses.dataclass
class Transform(IdlStruct, typename=ros_type("geometry_msgs", "Transform")):
    translation: Vector3
    rotation: Quaternion


@dataclasses.dataclass
class TransformStamped(IdlStruct, typename=ros_type("geometry_msgs", "TransformStamped")):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclasses.dataclass
class TFMessage(IdlStruct, typename=ros_type("tf2_msgs", "TFMessage")):
    transforms: sequence[TransformStamped]


@dataclasses.dataclass
class RegionOfInterest(IdlStruct, typename=ros_type("sensor_msgs", "RegionOfInterest")):
    x_offset: uint32
    y_offset: uint32
    height: uint32
    width: uint32
    do_rectify: bool


@dataclasses.dataclass
class CameraInfo(IdlStruct, typename=ros_type("sensor_msgs", "CameraInfo")):
    header: Header
    height: uint32
    width: uint32
    distortion_model: str
    d: sequence[float64]
    k: array[float64, 9]
    r: array[float64, 9]
    p: array[float64, 12]
    binning_x: uint32
    binning_y: uint32
    roi: RegionOfInterest


@dataclasses.dataclass
class KeyValue(IdlStruct, typename=ros_type("diagnostic_msgs", "KeyValue")):
    key: str
    value: str


@dataclasses.dataclass
class DiagnosticStatus(IdlStruct, typename=ros_type("diagnostic_msgs", "DiagnosticStatus")):
    level: uint8
    name: str
    message: str
    hardware_id: str
    values: sequence[KeyValue]


@dataclasses.dataclass
class DiagnosticArray(IdlStruct, typename=ros_type("diagnostic_msgs", "DiagnosticArray")):
    header: Header
    status: sequence[DiagnosticStatus]


# Best effort as roitrack offers; a history deeper than the sensor-data profile's 5, so that a subscriber that wakes
# late (Python) loses nothing to its own history.
BEST_EFFORT = Qos(Policy.Reliability.BestEffort, Policy.Durability.Volatile, Policy.History.KeepLast(1000))
# A ROS 2 subscriber's default (reliable, volatile, keep last 10), larger here so that nothing is lost to the history.
RELIABLE = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.Durability.Volatile,
               Policy.History.KeepLast(1000))
LATCHED = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.Durability.TransientLocal,
              Policy.History.KeepLast(1))

TOPICS = [
    ("/roitrack/pose", PoseWithCovarianceStamped, BEST_EFFORT),
    ("/roitrack/twist", TwistWithCovarianceStamped, BEST_EFFORT),
    ("/roitrack/odometry", Odometry, BEST_EFFORT),
    ("/tf", TFMessage, RELIABLE),
    ("/roitrack/status", DiagnosticArray, BEST_EFFORT),
    ("/roitrack/camera_info", CameraInfo, LATCHED),
]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--namespace", default="")
    parser.add_argument("--out", required=True)
    parser.add_argument("--count", type=int, default=0, help="estimates after which to end (0: no limit)")
    parser.add_argument("--idle-s", type=float, default=3.0)
    parser.add_argument("--timeout-s", type=float, default=120.0)
    parser.add_argument("--keep-all", action="store_true",
                        help="keep every sample until taken (else the last 1000 of each topic): for rates Python "
                             "cannot take as they come, so that only what the network lost is missing")
    args = parser.parse_args()
    namespace = args.namespace.strip().rstrip("/")
    if namespace and not namespace.startswith("/"):
        namespace = "/" + namespace

    participant = DomainParticipant(args.domain)
    readers = []
    waitset = WaitSet(participant)
    any_sample = SampleState.Any | ViewState.Any | InstanceState.Any
    for name, message_type, qos in TOPICS:
        if args.keep_all and qos is not LATCHED:
            qos = Qos(*[p for p in qos if not isinstance(p, Policy.History.KeepLast)], Policy.History.KeepAll)
        # ROS 2's mapping of a topic to DDS: the prefix rt/ before the fully qualified name, less its first slash.
        topic = Topic(participant, "rt" + namespace + name, message_type, qos=qos)
        reader = DataReader(participant, topic, qos=qos)
        waitset.attach(ReadCondition(reader, any_sample))
        readers.append((name, reader))
    print("ready", flush=True)

    # Samples are kept as they are taken, each with the time its take returned, and written out at the end: the
    # loop does nothing else, so that the time taken is close to the time received.
    taken = []
    start = time.monotonic()
    last = None
    estimates = 0
    while True:
        waitset.wait(duration(milliseconds=100))
        for name, reader in readers:
            samples = reader.take(N=256)
            if not samples:
                continue
            taken_ns = time.time_ns()
            taken.append((name, taken_ns, samples))
            last = time.monotonic()
            if name == "/roitrack/pose":
                estimates += sum(1 for s in samples if s.sample_info.valid_data)
        now = time.monotonic()
        if args.count and estimates >= args.count:
            break
        if estimates and now - last > args.idle_s:
            break
        if now - start > args.timeout_s:
            break
    with open(args.out, "w") as out:
        for name, taken_ns, samples in taken:
            for sample in samples:
                if not sample.sample_info.valid_data:
                    continue
                record = {
                    "topic": name,
                    "taken_ns": taken_ns,
                    "source_ns": sample.sample_info.source_timestamp,
                    "msg": dataclasses.asdict(sample),
                }
                out.write(json.dumps(record) + "\n")
    print(f"received {estimates} estimates", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
