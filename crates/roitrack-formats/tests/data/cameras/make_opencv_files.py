"""Writes the OpenCV FileStorage camera files in this folder with OpenCV's own writer (cv2.FileStorage), as a
calibration program would. Run once per OpenCV major version, in throwaway virtual environments (not needed by the
tests), e.g. for OpenCV 4:

    python3 -m venv /tmp/cv4venv && /tmp/cv4venv/bin/pip install "opencv-python-headless<5"
    /tmp/cv4venv/bin/python make_opencv_files.py

The names carry the major version: opencv4_calibration.yaml, opencv5_fisheye.xml, ...
"""

import sys

import cv2
import numpy as np

major = cv2.__version__.split(".")[0]
K = np.array([[812.5, 0.0, 320.5], [0.0, 810.25, 241.75], [0.0, 0.0, 1.0]])
D5 = np.array([[-0.12, 0.05, 5e-4, -3e-4, 0.01]])  # cv2.calibrateCamera gives 1 x 5
K_FISHEYE = np.array([[402.5, 0.4025, 639.5], [0.0, 401.0, 479.5], [0.0, 0.0, 1.0]])
D_FISHEYE = np.array([[-0.013], [0.021], [-0.011], [0.0023]])  # cv2.fisheye.calibrate gives 4 x 1
D8 = np.array([[0.42, -0.11, 7e-4, -4e-4, 0.013, 0.71, -0.05, 0.021]])

for ext in ("yaml", "xml"):
    # As OpenCV's calibration sample writes it (samples/cpp/calibration.cpp): image size, K, distortion.
    fs = cv2.FileStorage(f"opencv{major}_calibration.{ext}", cv2.FILE_STORAGE_WRITE)
    fs.write("calibration_time", "Fri Nov 27 09:00:00 2026")
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("flags", 0)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", D5)
    fs.write("avg_reprojection_error", 0.21)
    fs.release()
    # A fisheye calibration saved as K and D, with the model named, no image size (given by --image-size).
    fs = cv2.FileStorage(f"opencv{major}_fisheye.{ext}", cv2.FILE_STORAGE_WRITE)
    fs.write("K", K_FISHEYE)
    fs.write("D", D_FISHEYE)
    fs.write("distortion_model", "equidistant")
    fs.release()
    # The rational model (CALIB_RATIONAL_MODEL: 8 coefficients).
    fs = cv2.FileStorage(f"opencv{major}_rational.{ext}", cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1280)
    fs.write("image_height", 1024)
    fs.write("camera_matrix", np.array([[1210.0, 0.0, 640.0], [0.0, 1205.0, 512.0], [0.0, 0.0, 1.0]]))
    fs.write("distortion_coefficients", D8)
    fs.release()
print(f"wrote OpenCV {cv2.__version__} files", file=sys.stderr)
