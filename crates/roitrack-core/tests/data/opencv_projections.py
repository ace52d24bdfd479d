"""Writes opencv_projections.csv: raw pixels of points in the camera frame, projected by OpenCV itself.

Run with opencv-python-headless and numpy in a throwaway virtual environment (not needed by the tests):

    python3 -m venv /tmp/cvvenv && /tmp/cvvenv/bin/pip install opencv-python-headless numpy
    /tmp/cvvenv/bin/python crates/roitrack-core/tests/data/opencv_projections.py > crates/roitrack-core/tests/data/opencv_projections.csv

plumb_bob, rational_polynomial and none go through cv2.projectPoints (which ignores a skew entry of K, so these
cameras have none); equidistant through cv2.fisheye.projectPoints, whose skew `alpha` is skew_px / fx_px.
"""

import math
import sys

import cv2
import numpy as np

CAMERAS = [
    # model, fx, fy, skew, cx, cy, coefficients in ROS / OpenCV order
    ("none", 1500.0, 1500.0, 0.0, 512.0, 512.0, []),
    ("plumb_bob", 1480.0, 1510.0, 0.0, 515.0, 506.0, [-0.28, 0.12, 1.2e-3, -8e-4, -0.03]),
    ("plumb_bob", 812.5, 810.25, 0.0, 320.5, 241.75, [-0.12, 0.05, 5e-4, -3e-4]),
    ("plumb_bob", 812.5, 810.25, 0.0, 320.5, 241.75, [-0.12, 0.05, 5e-4, -3e-4, 0.01]),
    ("rational_polynomial", 1210.0, 1205.0, 0.0, 640.0, 512.0,
     [0.42, -0.11, 7e-4, -4e-4, 0.013, 0.71, -0.05, 0.021]),
    ("equidistant", 402.5, 401.0, 0.4025, 639.5, 479.5, [-0.013, 0.021, -0.011, 0.0023]),
    ("equidistant", 285.3, 285.1, 0.0, 424.2, 400.7, [-0.0052, 0.041, -0.038, 0.0066]),
]


def points(model):
    """Points in the camera frame: a pinhole camera sees out to normalised radius 0.65, a fisheye to 80 degrees."""
    out = []
    for z in (0.45, 1.7, 13.0):
        if model == "equidistant":
            for angle_deg in (0.0, 1e-7, 5.0, 20.0, 40.0, 60.0, 80.0):
                r = math.tan(math.radians(angle_deg))
                for azimuth_deg in (0.0, 37.0, 145.0, 250.0):
                    a = math.radians(azimuth_deg)
                    out.append((r * math.cos(a) * z, r * math.sin(a) * z, z))
        else:
            for x in (-0.65, -0.3, 0.0, 0.17, 0.5):
                for y in (-0.45, 0.0, 0.23, 0.6):
                    out.append((x * z, y * z, z))
    return out


def main():
    w = sys.stdout.write
    w("# Raw pixels computed by OpenCV %s (opencv-python-headless) with opencv_projections.py in this folder:\n"
      % cv2.__version__)
    w("# cv2.projectPoints (none, plumb_bob, rational_polynomial) and cv2.fisheye.projectPoints (equidistant),\n")
    w("# rvec = tvec = 0 so that x y z are in the camera frame (m). coefficients: space-separated, ROS order.\n")
    w("model,fx,fy,skew,cx,cy,coefficients,x,y,z,u,v\n")
    for model, fx, fy, skew, cx, cy, coeffs in CAMERAS:
        pts = np.array(points(model), dtype=np.float64).reshape(-1, 1, 3)
        rvec = np.zeros((3, 1))
        tvec = np.zeros((3, 1))
        if model == "equidistant":
            k = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
            d = np.array(coeffs, dtype=np.float64).reshape(4, 1)
            px, _ = cv2.fisheye.projectPoints(pts, rvec, tvec, k, d, alpha=skew / fx)
        else:
            k = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
            d = np.array(coeffs, dtype=np.float64) if coeffs else None
            px, _ = cv2.projectPoints(pts, rvec, tvec, k, d)
        for p, q in zip(pts.reshape(-1, 3), px.reshape(-1, 2)):
            w(",".join([model] + [repr(v) for v in (fx, fy, skew, cx, cy)]
                       + [" ".join(repr(c) for c in coeffs)]
                       + [repr(float(v)) for v in p] + [repr(float(v)) for v in q]) + "\n")


if __name__ == "__main__":
    main()
