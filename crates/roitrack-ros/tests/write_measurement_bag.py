"""Writes blob centroids as a ROS 2 bag (rosbag2 folder, MCAP storage) of roitrack's own message
`roitrack_msgs/msg/BlobMeasurements`, with Python's `rosbags` and the message's definition as docs/ros2.md gives it,
to test `roitrack track --mcap-in BAG --measurement-topic TOPIC` with a bag roitrack did not write.

    python write_measurement_bag.py OUT_DIR MEASUREMENTS.csv TOPIC PER_MESSAGE [DAMAGE]

MEASUREMENTS.csv and TOPIC may be comma-separated lists of the same length: one topic per file (the cameras of a rig
in one bag), their messages written in the order of their stamps. Each message holds the next PER_MESSAGE centroids of the CSV (t,id,u,v): stamped with the first one's time (rounded
to the nanosecond), each centroid's time as its offset from the stamp, sigma_px 0.1 px each. DAMAGE, to test the
errors: `unknown-id` (the 3rd message's 2nd id made 9999) or `short-u` (the 3rd message's u_px one entry short).
"""

import csv
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

# The definition of docs/ros2.md.
BLOB_MEASUREMENTS = """std_msgs/Header header
uint32[] point_ids
float64[] u_px
float64[] v_px
float64[] dt_s
float64[] sigma_px
"""


def main():
    out, csv_path, topic, per_message = Path(sys.argv[1]), sys.argv[2], sys.argv[3], int(sys.argv[4])
    damage = sys.argv[5] if len(sys.argv) > 5 else None
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(BLOB_MEASUREMENTS, "roitrack_msgs/msg/BlobMeasurements"))
    Time = store.types["builtin_interfaces/msg/Time"]
    Header = store.types["std_msgs/msg/Header"]
    BlobMeasurements = store.types["roitrack_msgs/msg/BlobMeasurements"]
    batches = []
    for topic_index, (one_csv, topic) in enumerate(zip(csv_path.split(","), topic.split(","), strict=True)):
        with open(one_csv, newline="") as f:
            rows = [(float(r["t"]), int(r["id"]), float(r["u"]), float(r["v"])) for r in csv.DictReader(f)]
        for index, start in enumerate(range(0, len(rows), per_message)):
            batches.append((round(rows[start][0] * 1e9), topic_index, topic, index, rows[start : start + per_message]))
    with Writer(out, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for _, _, topic, _, _ in batches:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, BlobMeasurements.__msgtype__, typestore=store)
        for ns, _, topic, index, batch in sorted(batches, key=lambda b: (b[0], b[1], b[3])):
            stamp_s = (ns // 1_000_000_000) + 1e-9 * (ns % 1_000_000_000)
            ids = np.array([r[1] for r in batch], dtype=np.uint32)
            u = np.array([r[2] for r in batch], dtype=np.float64)
            if index == 2 and damage == "unknown-id":
                ids[1] = 9999
            if index == 2 and damage == "short-u":
                u = u[:-1]
            message = BlobMeasurements(
                header=Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id="cam"),
                point_ids=ids,
                u_px=u,
                v_px=np.array([r[3] for r in batch], dtype=np.float64),
                dt_s=np.array([r[0] - stamp_s for r in batch], dtype=np.float64),
                sigma_px=np.full(len(batch), 0.1),
            )
            writer.write(connections[topic], ns, store.serialize_cdr(message, BlobMeasurements.__msgtype__))

if __name__ == "__main__":
    main()
