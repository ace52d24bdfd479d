"""Writes image frames as a ROS 2 bag (rosbag2 folder, MCAP storage) with Python's `rosbags`, to test `roitrack track
--mcap-in` with a bag roitrack did not write.

    python write_image_bag.py OUT_DIR FRAMES_DIR ENCODING WIDTH HEIGHT FX FY CX CY SKEW K1 K2 P1 P2 K3 [INFO_W INFO_H]

FRAMES_DIR holds `frame_NNNNN.png` with, beside each, `frame_NNNNN.raw` (its 8-bit grey pixels, row by row) and
`timestamps.csv` (`t,file`). ENCODING: mono8, rgb8 or bgr8 (the grey value in every channel, rows padded to a step
of 4 bytes more than needed) as sensor_msgs/msg/Image, or png as sensor_msgs/msg/CompressedImage holding the PNG
files' bytes. Topics: /cam/image_raw (or /cam/image_raw/compressed) and /cam/camera_info (one message, first; its
size INFO_W x INFO_H when given, to test a camera info that disagrees with the images).
"""

import csv
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore


def main():
    out, frames_dir, encoding = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
    width, height = int(sys.argv[4]), int(sys.argv[5])
    fx, fy, cx, cy, skew, k1, k2, p1, p2, k3 = (float(x) for x in sys.argv[6:16])
    info_width, info_height = (int(sys.argv[16]), int(sys.argv[17])) if len(sys.argv) > 17 else (width, height)
    store = get_typestore(Stores.ROS2_HUMBLE)
    Time = store.types["builtin_interfaces/msg/Time"]
    Header = store.types["std_msgs/msg/Header"]
    Image = store.types["sensor_msgs/msg/Image"]
    CompressedImage = store.types["sensor_msgs/msg/CompressedImage"]
    CameraInfo = store.types["sensor_msgs/msg/CameraInfo"]
    RegionOfInterest = store.types["sensor_msgs/msg/RegionOfInterest"]

    with open(frames_dir / "timestamps.csv", newline="") as f:
        rows = list(csv.DictReader(f))

    def header(t):
        ns = round(float(t) * 1e9)
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id="cam")

    with Writer(out, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        info_topic = writer.add_connection("/cam/camera_info", CameraInfo.__msgtype__, typestore=store)
        if encoding == "png":
            image_topic = writer.add_connection(
                "/cam/image_raw/compressed", CompressedImage.__msgtype__, typestore=store
            )
        else:
            image_topic = writer.add_connection("/cam/image_raw", Image.__msgtype__, typestore=store)
        t0 = rows[0]["t"]
        info = CameraInfo(
            header=header(t0),
            height=info_height,
            width=info_width,
            distortion_model="plumb_bob",
            d=np.array([k1, k2, p1, p2, k3], dtype=np.float64),
            k=np.array([fx, skew, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64),
            r=np.eye(3).reshape(9),
            p=np.array([fx, skew, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64),
            binning_x=0,
            binning_y=0,
            roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
        )
        stamp_ns = round(float(t0) * 1e9)
        writer.write(info_topic, stamp_ns, store.serialize_cdr(info, CameraInfo.__msgtype__))
        for row in rows:
            name = row["file"]
            ns = round(float(row["t"]) * 1e9)
            if encoding == "png":
                data = np.frombuffer((frames_dir / name).read_bytes(), dtype=np.uint8)
                message = CompressedImage(header=header(row["t"]), format="png", data=data)
                writer.write(image_topic, ns, store.serialize_cdr(message, CompressedImage.__msgtype__))
                continue
            grey = np.fromfile(frames_dir / name.replace(".png", ".raw"), dtype=np.uint8).reshape(height, width)
            if encoding == "mono8":
                pixels, channels = grey, 1
            else:
                pixels, channels = np.repeat(grey[:, :, None], 3, axis=2), 3
            step = width * channels + 4
            padded = np.zeros((height, step), dtype=np.uint8)
            padded[:, : width * channels] = pixels.reshape(height, width * channels)
            message = Image(
                header=header(row["t"]),
                height=height,
                width=width,
                encoding=encoding,
                is_bigendian=0,
                step=step,
                data=padded.reshape(-1),
            )
            writer.write(image_topic, ns, store.serialize_cdr(message, Image.__msgtype__))


if __name__ == "__main__":
    main()
