"""Publishes the frames `roitrack simulate --frames` rendered (8- or 16-bit greyscale PNGs, decoded here with the
standard library alone) on the ROS 2 DDS bus as `sensor_msgs/msg/Image` (`mono8` or `mono16`; the DDS topic
`rt/roitrack/image`, type `sensor_msgs::msg::dds_::Image_`), each stamped with its time of timestamps.csv rounded to
the nanosecond, after the camera's `sensor_msgs/msg/CameraInfo` on /roitrack/camera_info (reliable, transient local),
with Eclipse Cyclone DDS: the input of `roitrack ros2-node --image-topic` in its tests.

With --malformed, bad images go out too, which the node must leave out, name, and go on: one before the camera info,
then, before the first good frame, one of another encoding (`yuv422`), one of another size, one whose step does not
match its width, and one whose data is short. With --too-close K, a copy of frame K goes out right after it, stamped
1 ms later: on a rolling-shutter camera, a frame that starts before the previous frame's blobs were read, which the
node must leave out, count, and go on.

With --encoding, the frames go out in another form than their PNG's: `bgr8` (each grey value as three equal
channels, which BT.601 luma turns back into the same grey), `mono16` (each 8-bit value v as 257 v, little-endian: the
frames of the PNGs `roitrack` wrote at 16 bits in the test), or `png`: the PNG files themselves as
`sensor_msgs/msg/CompressedImage` (format `png`, on the topic given, not decoded here).

It waits (up to --wait-s) for a subscriber of the images, and after the camera info for the node's publisher of its
estimates (--wait-for-publisher), publishes reliably at --rate-hz images a second, waits for
every image to be acknowledged, and prints `published N images`.

    python ros2_image_publisher.py FRAMES_DIR TIMESTAMPS.csv CAMERA.yaml [--topic /roitrack/image] [--malformed]
"""

import argparse
import array
import csv
import dataclasses
import os
import struct
import sys
import time
import zlib

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ros2_measurement_publisher import camera_info, publish_paced, wait_until
from ros2_subscriber import LATCHED, CameraInfo, Header, Time, ros_type


@dataclasses.dataclass
class CompressedImage(IdlStruct, typename=ros_type("sensor_msgs", "CompressedImage")):
    header: Header
    format: str
    data: sequence[uint8]


@dataclasses.dataclass
class Image(IdlStruct, typename=ros_type("sensor_msgs", "Image")):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


def read_png(path):
    """(width, height, bit depth, the rows' bytes, big-endian for 16 bits) of a non-interlaced greyscale PNG."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos, idat, header = 8, [], None
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
    width, height, depth, colour, _, _, interlace = header
    if colour != 0 or interlace != 0 or depth not in (8, 16):
        raise ValueError(f"{path}: not an 8- or 16-bit greyscale non-interlaced PNG")
    raw = zlib.decompress(b"".join(idat))
    bpp = depth // 8
    stride = width * bpp
    out = bytearray(stride * height)
    previous = bytearray(stride)
    for y in range(height):
        kind = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        if kind == 1:
            for i in range(bpp, stride):
                line[i] = (line[i] + line[i - bpp]) & 0xFF
        elif kind == 2:
            line = bytearray((a + b) & 0xFF for a, b in zip(line, previous))
        elif kind == 3:
            for i in range(stride):
                left = line[i - bpp] if i >= bpp else 0
                line[i] = (line[i] + ((left + previous[i]) >> 1)) & 0xFF
        elif kind == 4:
            for i in range(stride):
                a = line[i - bpp] if i >= bpp else 0
                b = previous[i]
                c = previous[i - bpp] if i >= bpp else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 0xFF
        elif kind != 0:
            raise ValueError(f"{path}: row {y}: filter {kind}")
        out[y * stride:(y + 1) * stride] = line
        previous = line
    return width, height, depth, bytes(out)


def stamp(t_s):
    """The header of time `t_s` rounded to the nanosecond."""
    sec, nanosec = divmod(round(t_s * 1e9), 1_000_000_000)
    return Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id="camera")


def image(t_s, width, height, depth, pixels, encoding=None, step=None):
    """An Image of the rows `pixels` (PNG's byte order: big-endian for 16 bits)."""
    return Image(
        header=stamp(t_s), height=height, width=width,
        encoding=encoding or ("mono8" if depth == 8 else "mono16"),
        is_bigendian=1 if depth == 16 else 0,
        step=step if step is not None else width * depth // 8,
        data=pixels,
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("frames")
    parser.add_argument("timestamps")
    parser.add_argument("camera")
    parser.add_argument("--domain", type=int, default=0)
    parser.add_argument("--topic", default="/roitrack/image")
    parser.add_argument("--info-topic", default="/roitrack/camera_info")
    parser.add_argument("--rate-hz", type=float, default=30.0)
    parser.add_argument("--wait-s", type=float, default=30.0)
    parser.add_argument("--malformed", action="store_true")
    parser.add_argument("--too-close", type=int, metavar="K",
                        help="after frame K, a copy of it stamped 1 ms later")
    parser.add_argument("--encoding", choices=["bgr8", "mono16", "png"],
                        help="publish the frames in this form (default: mono8 or mono16 as their PNG)")
    parser.add_argument("--wait-for-publisher", default="rt/roitrack/pose",
                        help="the DDS topic of the node's estimates, whose publisher to wait for after the camera info")
    args = parser.parse_args()

    with open(args.timestamps) as f:
        rows = [(float(r[0]), r[1]) for r in csv.reader(f) if r and r[0][0].isdigit()]
    if args.encoding == "png" and (args.malformed or args.too_close is not None):
        parser.error("--encoding png goes without --malformed and --too-close")
    frames = []
    for t_s, name in rows:
        path = os.path.join(args.frames, name)
        if args.encoding == "png":
            frames.append(CompressedImage(header=stamp(t_s), format="png", data=open(path, "rb").read()))
            continue
        width, height, depth, pixels = read_png(path)
        if args.encoding == "bgr8" and depth == 8:
            bgr = bytearray(3 * len(pixels))
            for c in range(3):
                bgr[c::3] = pixels
            frames.append(image(t_s, width, height, 8, bytes(bgr), encoding="bgr8", step=3 * width))
        elif args.encoding == "mono16" and depth == 8:
            wide = array.array("H", (257 * v for v in pixels))
            if sys.byteorder != "little":
                wide.byteswap()
            m = image(t_s, width, height, 16, wide.tobytes())
            m.is_bigendian = 0
            frames.append(m)
        elif args.encoding is None:
            frames.append(image(t_s, width, height, depth, pixels))
        else:
            parser.error(f"--encoding {args.encoding}: {name} is a {depth}-bit PNG")
    print(f"decoded {len(frames)} frames", file=sys.stderr, flush=True)

    participant = DomainParticipant(args.domain)
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=10)), Policy.Durability.Volatile, Policy.History.KeepAll)
    message_type = CompressedImage if args.encoding == "png" else Image
    topic = Topic(participant, "rt" + args.topic, message_type, qos=qos)
    writer = DataWriter(participant, topic, qos=qos)
    if not wait_until(writer.get_matched_subscriptions, args.wait_s, "subscriber"):
        return 1
    # The subscriber's side of the discovery (its matching of this writer).
    time.sleep(0.3)
    first = frames[0]
    if args.malformed:
        # Before any camera info: left out, named.
        writer.write(image(rows[0][0] - 1.0, first.width, first.height, 8, first.data))
        writer.wait_for_acks(duration(seconds=10))
        time.sleep(0.3)
    info_topic = Topic(participant, "rt" + args.info_topic, CameraInfo, qos=LATCHED)
    info_writer = DataWriter(participant, info_topic, qos=LATCHED)
    info_writer.write(camera_info(args.camera))
    # The camera info taken before any frame: a subscriber of it matched, the message acknowledged, then a moment.
    if not wait_until(info_writer.get_matched_subscriptions, args.wait_s, "subscriber of the camera info"):
        return 1
    info_writer.wait_for_acks(duration(seconds=10))
    # The node publishes its estimates best effort: wait until its pose publisher is seen on the bus (then a moment,
    # for every subscriber to match it), so that none of them goes out before a subscriber is there.
    if args.wait_for_publisher:
        publications = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)

        def published():
            return any(p.topic_name == args.wait_for_publisher for p in publications.read(N=1000))

        if not wait_until(published, args.wait_s, f"publisher of {args.wait_for_publisher}"):
            return 1
    time.sleep(1.0)
    messages = list(frames)
    if args.too_close is not None:
        k = args.too_close
        f = frames[k]
        copy = image(rows[k][0] + 1e-3, f.width, f.height, 16 if f.encoding == "mono16" else 8, f.data)
        messages.insert(k + 1, copy)
    if args.malformed:
        w, h, t0 = first.width, first.height, rows[0][0] - 0.5
        bad = [
            image(t0, w, h, 8, first.data, encoding="yuv422", step=2 * w),
            image(t0, w // 2, h, 8, first.data[: w * h // 2]),
            image(t0, w, h, 8, first.data, step=w - 1),
            image(t0, w, h, 8, first.data[: w * (h - 1)]),
        ]
        messages = bad + messages
    publish_paced(writer, messages, args.rate_hz)
    writer.wait_for_acks(duration(seconds=30))
    print(f"published {len(messages)} images", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
