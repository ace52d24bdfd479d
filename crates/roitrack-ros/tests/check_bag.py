"""Reads a roitrack bag back with two readers that are not roitrack's, and checks it against the run's other files.

    python check_bag.py BAG.mcap POSES.tum TWISTS.csv COVARIANCE.csv|- FRAME_ID CHILD_FRAME_ID [--images N] [--prefix]
        [--measurements MEASUREMENTS.csv] [--rois N] [--distortion MODEL:N] [--rig]

1. `mcap` with `mcap-ros2-support`: the header profile `ros2`; every channel CDR with a `ros2msg` schema and its QoS
   profiles; every message decoded by the decoder built from the bag's own schemas.
2. `rosbags`: its MCAP storage reader (the one `rosbags` uses for rosbag2 folders) and its ROS 2 Humble type store:
   the standard messages decoded by the type store's definitions, not the bag's, and the bag's definitions of them
   hashed (RIHS01) equal to the type store's.

Then, on what both decoded (they must agree): one pose, twist, odometry, tf and status message per line of the TUM
file, each pose equal to it to 1e-9, the twist to the twists CSV, stamps equal to the times to 1.5 ns, frame ids as
given, covariances symmetric and positive semi-definite and equal to the covariance CSV's blocks (the pose's) or
its first-order transformation (the odometry's twist, in the target frame), the camera info once, its distortion
model and number of coefficients those given. `/roitrack/measurements` (roitrack_msgs/msg/BlobMeasurements, decoded
by `rosbags` from the bag's own definition): parallel arrays, and with --measurements, every centroid of the CSV,
in order, at `stamp + dt_s`. With --images, the annotations of each frame: green points (the measured centroids, each
labelled with its id) near the magenta circles of the same ids (the target projected by the estimate). With --rois,
each ROI image with its camera info (the `roi` its offset and size) and annotation (a centroid inside the image, at
a measurement of /roitrack/measurements less the offset, or a rejection). With --rig, the bag of a rig's run: its fused
estimates only, no camera info and no measurements (they belong to each camera). Prints a summary; exits non-zero with
the reason on the first failure.
"""

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np


def fail(message):
    print(f"check_bag: FAIL: {message}", file=sys.stderr)
    sys.exit(1)


def check(condition, message):
    if not condition:
        fail(message)


def read_tum(path):
    rows = []
    for line in Path(path).read_text().splitlines():
        if line.strip():
            rows.append([float(x) for x in line.split()])
    return np.array(rows)


def read_csv(path):
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return [{k: float(v) for k, v in row.items()} for row in reader]


def full_covariance(row):
    c = np.full((12, 12), np.nan)
    for i in range(12):
        for j in range(i, 12):
            c[i, j] = c[j, i] = row[f"c{i}_{j}"]
    return c


def hat(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def rotation(q):
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def stamp_s(stamp):
    return stamp.sec + 1e-9 * stamp.nanosec


def check_psd(c, what):
    check(np.all(np.isfinite(c)), f"{what}: not finite")
    check(np.array_equal(c, c.T), f"{what}: not symmetric")
    scale = max(np.max(np.abs(np.diag(c))), 1e-300)
    check(np.min(np.linalg.eigvalsh(c)) >= -1e-9 * scale, f"{what}: not positive semi-definite")


def read_with_mcap(path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        check(header.profile == "ros2", f"profile {header.profile!r}, not 'ros2'")
        summary = reader.get_summary()
        check(summary is not None and summary.statistics is not None, "no summary with statistics")
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            check(channel.message_encoding == "cdr", f"{channel.topic}: encoding {channel.message_encoding}")
            check(schema.encoding == "ros2msg", f"{channel.topic}: schema encoding {schema.encoding}")
            qos = channel.metadata.get("offered_qos_profiles", "")
            check("reliability:" in qos and "durability:" in qos, f"{channel.topic}: no offered_qos_profiles")
        messages = {}
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            messages.setdefault(channel.topic, []).append((schema.name, message.log_time, decoded))
        check(
            sum(len(v) for v in messages.values()) == summary.statistics.message_count,
            "the summary's message count differs from the messages read",
        )
    return messages


def read_with_rosbags(path):
    from rosbags.rosbag2.storage_mcap import McapReader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    humble = get_typestore(Stores.ROS2_HUMBLE)
    own = get_typestore(Stores.EMPTY)
    reader = McapReader(Path(path))
    reader.open()
    try:
        messages = {}
        connections = reader.connections
        for connection in connections:
            own.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        for connection in connections:
            if connection.msgtype in humble.fielddefs:
                check(
                    own.hash_rihs01(connection.msgtype) == humble.hash_rihs01(connection.msgtype),
                    f"{connection.topic}: the bag's definition of {connection.msgtype} differs from ROS 2 Humble's",
                )
        for connection, timestamp, data in reader.messages(connections):
            store = humble if connection.msgtype in humble.fielddefs else own
            decoded = store.deserialize_cdr(data, connection.msgtype)
            messages.setdefault(connection.topic, []).append((connection.msgtype, timestamp, decoded))
    finally:
        reader.close()
    return messages


ESTIMATE_TOPICS = ["/roitrack/pose", "/roitrack/twist", "/roitrack/odometry", "/tf", "/roitrack/status"]
MEASURED_COLOR = (0.1, 0.9, 0.2)
PROJECTED_COLOR = (1.0, 0.2, 0.9)


def color(c):
    return (round(c.r, 6), round(c.g, 6), round(c.b, 6))


def measurements_of(messages, frame_id):
    """The centroids of /roitrack/measurements as (t, id, u, v), in the order written."""
    rows = []
    for _, log_time, m in messages:
        n = len(m.point_ids)
        check(len(m.u_px) == n and len(m.v_px) == n and len(m.dt_s) == n, "measurements: arrays of unequal length")
        check(len(m.sigma_px) in (0, n), "measurements: sigma_px")
        check(m.header.frame_id == frame_id, f"measurements: frame_id {m.header.frame_id!r}")
        t0 = stamp_s(m.header.stamp)
        check(abs(log_time * 1e-9 - t0) <= 1.5e-9, "measurements: log time is not the stamp")
        check(n > 0 and abs(m.dt_s[0]) <= 1e-9, "measurements: stamped with the first centroid's time")
        rows.extend((t0 + float(m.dt_s[k]), int(m.point_ids[k]), float(m.u_px[k]), float(m.v_px[k])) for k in range(n))
    return rows


def check_frame_annotations(annotations):
    """Measured points (green, labelled) near the projected circles (magenta, labelled) of the same ids."""
    worst = 0.0
    measured_total = 0
    for _, _, a in annotations:
        circles = [c for c in a.circles if color(c.outline_color) == PROJECTED_COLOR]
        projected_labels = [t for t in a.texts if color(t.text_color) == PROJECTED_COLOR]
        measured_labels = [t for t in a.texts if color(t.text_color) == MEASURED_COLOR]
        points = [p for group in a.points if color(group.outline_color) == MEASURED_COLOR and group.type == 1
                  for p in group.points]
        check(len(projected_labels) == len(circles), "annotations: a projected circle without its label")
        check(len(measured_labels) == len(points), "annotations: a measured point without its label")
        measured_total += len(points)
        projected = {t.text: c.position for t, c in zip(projected_labels, circles)}
        for label, p in zip(measured_labels, points):
            if projected:
                check(label.text in projected, f"annotations: measured point {label.text} has no projection")
                q = projected[label.text]
                worst = max(worst, math.hypot(p.x - q.x, p.y - q.y))
    check(measured_total > 0, "annotations: no measured point drawn")
    check(worst < 3.0, f"annotations: a measured point {worst:.2f} px from its projection")
    return worst, measured_total


def check_rois(images, infos, annotations, measured, camera_info):
    """Each ROI image with its camera info (roi = offset and size) and its centroid's annotation."""
    check(len(images) == len(infos) == len(annotations), "ROI topics of unequal length")
    by_time = {}
    for t, point_id, u, v in measured:
        by_time.setdefault(round(t * 1e9), []).append((point_id, u, v))
    centroids = 0
    for (_, log_a, image), (_, log_b, info), (_, log_c, a) in zip(images, infos, annotations):
        check(log_a == log_b == log_c, "ROI image, camera info and annotations at different times")
        check(stamp_s(image.header.stamp) == stamp_s(info.header.stamp), "ROI image and camera info stamps differ")
        check(image.encoding in ("mono8", "mono16") and len(image.data) == image.step * image.height, "ROI image")
        roi = info.roi
        check((roi.width, roi.height) == (image.width, image.height), "ROI camera info: roi size is not the image's")
        check(roi.x_offset + roi.width <= info.width and roi.y_offset + roi.height <= info.height, "ROI off the sensor")
        check((info.width, info.height) == (camera_info.width, camera_info.height), "ROI camera info: sensor size")
        check(list(info.k) == list(camera_info.k), "ROI camera info: intrinsics")
        points = [p for group in a.points for p in group.points]
        if not points:
            check(any("rejected" in t.text for t in a.texts), "a ROI without a centroid nor a rejection")
            continue
        check(len(points) == 1, "a ROI annotated with more than one centroid")
        p = points[0]
        check(0 <= p.x < image.width and 0 <= p.y < image.height, "a ROI's centroid is outside its image")
        u, v = p.x + roi.x_offset, p.y + roi.y_offset
        candidates = [m for key in (log_a - 1, log_a, log_a + 1) for m in by_time.get(key, [])]
        # A rolling shutter's centroid is later than its ROI's first row: then match by place only.
        if not candidates:
            candidates = [m for ms in by_time.values() for m in ms]
        best = min(math.hypot(u - cu, v - cv) for _, cu, cv in candidates)
        check(best <= 1e-9, f"a ROI's centroid ({u}, {v}) is no measurement of /roitrack/measurements")
        centroids += 1
    return centroids


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("bag")
    parser.add_argument("poses")
    parser.add_argument("twists")
    parser.add_argument("covariance")
    parser.add_argument("frame_id")
    parser.add_argument("child_frame_id")
    parser.add_argument("--images", type=int, default=0, help="frames expected on /roitrack/image")
    parser.add_argument(
        "--prefix",
        action="store_true",
        help="the bag of a run that failed: its estimates are the first of the files' (at least one)",
    )
    parser.add_argument("--measurements", help="the measurements CSV the bag's /roitrack/measurements must hold")
    parser.add_argument("--rois", type=int, default=0, help="ROI images expected on /roitrack/roi/image")
    parser.add_argument("--distortion", default="plumb_bob:5", help="the camera info's model and coefficient count")
    parser.add_argument("--rig", action="store_true", help="a rig's bag: estimates only, no camera info or measurements")
    args = parser.parse_args()

    poses = read_tum(args.poses)
    twists = read_csv(args.twists)
    # "-": the run wrote no covariance file (demo); the covariances are then checked symmetric and PSD only.
    covariances = read_csv(args.covariance) if args.covariance != "-" else None
    n = len(poses)
    check(n > 0 and len(twists) == n and (covariances is None or len(covariances) == n),
          "the run's files disagree in length")

    by_reader = {"mcap": read_with_mcap(args.bag), "rosbags": read_with_rosbags(args.bag)}
    expected_types = {
        "/roitrack/pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        "/roitrack/twist": "geometry_msgs/msg/TwistWithCovarianceStamped",
        "/roitrack/odometry": "nav_msgs/msg/Odometry",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/roitrack/status": "diagnostic_msgs/msg/DiagnosticArray",
    }
    if not args.rig:
        expected_types["/roitrack/camera_info"] = "sensor_msgs/msg/CameraInfo"
    if args.images:
        expected_types["/roitrack/image"] = "sensor_msgs/msg/Image"
        expected_types["/roitrack/annotations"] = "foxglove_msgs/msg/ImageAnnotations"
    if args.rois:
        expected_types["/roitrack/roi/image"] = "sensor_msgs/msg/Image"
        expected_types["/roitrack/roi/camera_info"] = "sensor_msgs/msg/CameraInfo"
        expected_types["/roitrack/roi/annotations"] = "foxglove_msgs/msg/ImageAnnotations"
    if not args.rig:
        expected_types["/roitrack/measurements"] = "roitrack_msgs/msg/BlobMeasurements"
    if args.prefix:
        n = len(by_reader["mcap"].get("/roitrack/pose", []))
        check(0 < n <= len(poses), f"{n} poses in the bag of a failed run, {len(poses)} in the files")
    for name, messages in by_reader.items():
        check(set(messages) == set(expected_types), f"{name}: topics {sorted(messages)}")
        for topic, type_name in expected_types.items():
            check(all(m[0] == type_name for m in messages[topic]), f"{name}: {topic} is not {type_name}")
        for topic in ["/roitrack/pose", "/roitrack/twist", "/roitrack/odometry", "/tf", "/roitrack/status"]:
            check(len(messages[topic]) == n, f"{name}: {len(messages[topic])} messages on {topic}, {n} estimates")
        check(args.rig or len(messages["/roitrack/camera_info"]) == 1, f"{name}: camera info not once")
        if args.images:
            check(len(messages["/roitrack/image"]) == args.images, f"{name}: {len(messages['/roitrack/image'])} images")

    mcap_messages, rosbags_messages = by_reader["mcap"], by_reader["rosbags"]
    worst = {"pose": 0.0, "twist": 0.0, "stamp": 0.0, "covariance": 0.0}
    for k in range(n):
        t, tx, ty, tz, qx, qy, qz, qw = poses[k]
        decoded = {topic: (mcap_messages[topic][k], rosbags_messages[topic][k]) for topic in ESTIMATE_TOPICS}
        for topic, ((_, log_a, a), (_, log_b, b)) in decoded.items():
            check(log_a == log_b, f"{topic} {k}: log times differ between the readers")
            check(abs(log_a * 1e-9 - t) <= 1.5e-9, f"{topic} {k}: log time {log_a} ns for t = {t}")
            header_a = a.transforms[0].header if topic == "/tf" else a.header
            header_b = b.transforms[0].header if topic == "/tf" else b.header
            for header in (header_a, header_b):
                worst["stamp"] = max(worst["stamp"], abs(stamp_s(header.stamp) - t))
                check(abs(stamp_s(header.stamp) - t) <= 1.5e-9, f"{topic} {k}: stamp {header.stamp} for t = {t}")
                check(header.frame_id == args.frame_id, f"{topic} {k}: frame_id {header.frame_id!r}")
        for reader_index in (0, 1):
            pose_msg = decoded["/roitrack/pose"][reader_index][2]
            twist_msg = decoded["/roitrack/twist"][reader_index][2]
            odometry = decoded["/roitrack/odometry"][reader_index][2]
            tf = decoded["/tf"][reader_index][2].transforms
            status = decoded["/roitrack/status"][reader_index][2].status
            check(len(tf) == 1 and tf[0].child_frame_id == args.child_frame_id, f"/tf {k}: child frame")
            check(odometry.child_frame_id == args.child_frame_id, f"/roitrack/odometry {k}: child frame")
            p, q = pose_msg.pose.pose.position, pose_msg.pose.pose.orientation
            got = np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w])
            want = np.array([tx, ty, tz, qx, qy, qz, qw])
            worst["pose"] = max(worst["pose"], float(np.max(np.abs(got - want))))
            check(np.max(np.abs(got - want)) <= 1e-9, f"/roitrack/pose {k}: {got} against the TUM {want}")
            for other, name in ((odometry.pose.pose, "odometry"),):
                o = np.array([other.position.x, other.position.y, other.position.z, other.orientation.x,
                              other.orientation.y, other.orientation.z, other.orientation.w])
                check(np.max(np.abs(o - want)) <= 1e-9, f"/roitrack/{name} {k}: pose differs from the TUM")
            tr = tf[0].transform
            o = np.array([tr.translation.x, tr.translation.y, tr.translation.z, tr.rotation.x, tr.rotation.y,
                          tr.rotation.z, tr.rotation.w])
            check(np.max(np.abs(o - want)) <= 1e-9, f"/tf {k}: transform differs from the TUM")
            tw = twist_msg.twist.twist
            v = np.array([tw.linear.x, tw.linear.y, tw.linear.z])
            w = np.array([tw.angular.x, tw.angular.y, tw.angular.z])
            row = twists[k]
            want_twist = np.array([row["vx"], row["vy"], row["vz"], row["wx"], row["wy"], row["wz"]])
            worst["twist"] = max(worst["twist"], float(np.max(np.abs(np.concatenate([v, w]) - want_twist))))
            check(np.max(np.abs(np.concatenate([v, w]) - want_twist)) <= 1e-9, f"/roitrack/twist {k}: differs")
            r = rotation([qx, qy, qz, qw])
            otw = odometry.twist.twist
            v_obj = np.array([otw.linear.x, otw.linear.y, otw.linear.z])
            w_obj = np.array([otw.angular.x, otw.angular.y, otw.angular.z])
            check(np.max(np.abs(v_obj - r.T @ v)) <= 1e-9 and np.max(np.abs(w_obj - r.T @ w)) <= 1e-9,
                  f"/roitrack/odometry {k}: twist not in the target frame")

            c = full_covariance(covariances[k]) if covariances is not None else None
            pose_cov = np.array(pose_msg.pose.covariance).reshape(6, 6)
            twist_cov = np.array(twist_msg.twist.covariance).reshape(6, 6)
            odo_pose_cov = np.array(odometry.pose.covariance).reshape(6, 6)
            odo_twist_cov = np.array(odometry.twist.covariance).reshape(6, 6)
            for m, what in ((pose_cov, "pose"), (twist_cov, "twist"), (odo_pose_cov, "odometry pose"),
                            (odo_twist_cov, "odometry twist")):
                check_psd(m, f"{what} covariance {k}")
            if c is None:
                pass
            elif np.all(np.isfinite(c)):
                j = np.zeros((6, 12))
                j[0:3, 3:6] = r.T @ hat(v)
                j[0:3, 6:9] = r.T
                j[3:6, 3:6] = r.T @ hat(w)
                j[3:6, 9:12] = r.T
                for got_cov, want_cov, what in (
                    (pose_cov, c[0:6, 0:6], "pose"),
                    (odo_pose_cov, c[0:6, 0:6], "odometry pose"),
                    (twist_cov, c[6:12, 6:12], "twist"),
                    (odo_twist_cov, j @ c @ j.T, "odometry twist"),
                ):
                    error = np.max(np.abs(got_cov - want_cov)) / max(np.max(np.abs(want_cov)), 1e-300)
                    worst["covariance"] = max(worst["covariance"], float(error))
                    check(error <= 1e-9, f"{what} covariance {k}: relative error {error:.3g}")
            else:
                check(not np.any(pose_cov) and not np.any(twist_cov), f"covariance {k}: unknown, but not zeros")
            check(len(status) == 1, f"/roitrack/status {k}: {len(status)} statuses")
            values = {kv.key: kv.value for kv in status[0].values}
            for key in ("status", "residual_rms_px", "inverse_condition", "measurements_used"):
                check(key in values, f"/roitrack/status {k}: no {key}")
            check(status[0].message == values["status"], f"/roitrack/status {k}: message and status differ")
    extra = "; a rig's: no camera info, no measurements" if args.rig else check_camera_side(args, mcap_messages,
                                                                                            rosbags_messages)
    print(
        f"check_bag: {args.bag}: {n} estimates read back by mcap and rosbags{extra}; worst differences: pose "
        f"{worst['pose']:.2e}, twist {worst['twist']:.2e}, stamp {worst['stamp']:.2e} s, covariance "
        f"{worst['covariance']:.2e} (relative)"
    )


def check_camera_side(args, mcap_messages, rosbags_messages):
    """A single camera's part of the bag: the camera info, the frames, the measurements, the ROIs; the summary's
    words for them."""
    info_a, info_b = mcap_messages["/roitrack/camera_info"][0][2], rosbags_messages["/roitrack/camera_info"][0][2]
    for info in (info_a, info_b):
        check(info.header.frame_id == args.frame_id, "camera info frame")
        model, count = args.distortion.split(":")
        check(info.distortion_model == model and len(info.d) == int(count),
              f"camera info distortion {info.distortion_model} with {len(info.d)} coefficients, not {args.distortion}")
        check(info.width > 0 and info.height > 0 and info.k[8] == 1.0, "camera info size and matrix")
    if args.images:
        for (_, _, a), (_, _, b) in zip(mcap_messages["/roitrack/image"], rosbags_messages["/roitrack/image"]):
            for image in (a, b):
                check(image.encoding in ("mono8", "mono16"), f"image encoding {image.encoding}")
                check(image.width == info_a.width and image.height == info_a.height, "image size")
                check(len(image.data) == image.step * image.height, "image data size")
                check(image.header.frame_id == args.frame_id, "image frame")
            check(bytes(a.data) == bytes(b.data), "the readers disagree on an image")
    measured = measurements_of(mcap_messages["/roitrack/measurements"], args.frame_id)
    check(measured == measurements_of(rosbags_messages["/roitrack/measurements"], args.frame_id),
          "the readers disagree on the measurements")
    extra = f"; {len(measured)} measurements"
    if args.measurements:
        with open(args.measurements, newline="") as f:
            rows = [(float(r["t"]), int(r["id"]), float(r["u"]), float(r["v"])) for r in csv.DictReader(f)]
        check(len(measured) == len(rows), f"{len(measured)} measurements in the bag, {len(rows)} in the CSV")
        worst_t = max(abs(a[0] - b[0]) for a, b in zip(measured, rows))
        check(worst_t <= 1e-12, f"measurement times differ by {worst_t} s")
        check(all(a[1:] == b[1:] for a, b in zip(measured, rows)), "measurements differ from the CSV")
        extra += f" equal to the CSV's (times to {worst_t:.1e} s)"
    if args.images:
        worst_px, drawn = check_frame_annotations(mcap_messages["/roitrack/annotations"])
        check_frame_annotations(rosbags_messages["/roitrack/annotations"])
        extra += f"; {drawn} measured centroids drawn, at most {worst_px:.2f} px from their projections"
    if args.rois:
        check(len(mcap_messages["/roitrack/roi/image"]) == args.rois, f"{len(mcap_messages['/roitrack/roi/image'])} ROIs")
        centroids = check_rois(mcap_messages["/roitrack/roi/image"], mcap_messages["/roitrack/roi/camera_info"],
                               mcap_messages["/roitrack/roi/annotations"], measured, info_a)
        check(centroids == len(measured), f"{centroids} ROI centroids, {len(measured)} measurements")
        check(len(rosbags_messages["/roitrack/roi/image"]) == args.rois, "rosbags: ROI count")
        extra += f"; {args.rois} ROI images, {centroids} with their centroid"
    return extra


if __name__ == "__main__":
    main()
