#!/usr/bin/env python3
"""Side by side with OpenCV on random PnP families: roitrack's static pose solver against solvePnP.

Run through `bash bench/pnp_families.sh`, which makes the virtual environment (opencv-python-headless, numpy) and
builds `roitrack`. This script, written independently of roitrack's own simulator (numpy and OpenCV only):

1. draws, seeded, `--per-family` problems in each family (FAMILIES): a target, a camera with a true lens, a pose
   that keeps the target in the image, Gaussian noise on the raw (distorted) pixels, and the user's model of the
   rig, off the truth (intrinsics, k1, every target coordinate); the solvers get only the user's model: the raw
   pixels undistorted with it, and the user's target coordinates;
2. computes per problem, from the truth, the reference pose `p_model` (what the user's model gives on noise-free
   data: Levenberg-Marquardt from the true pose, cv2.solvePnPRefineLM with tight criteria) and the Cramer-Rao
   covariance of the 6-dof pose at p_model for the noise (numerical Jacobian, central differences); the normalised
   error of a pose is max(|t - t_model| / sqrt(trace S_t), angle(R, R_model) / sqrt(trace S_rot)), and a solve is
   correct when it is at most 10;
3. writes the problems as a suite (format roitrack-pnp-suite/1) to a temporary file and runs `roitrack lab pnp-bench
   --suite FILE --json`; solves the same numbers with OpenCV (SQPNP; IPPE on planar targets; EPNP then
   solvePnPRefineLM; AP3P's first solution for 3 points), each timed as the median of 20 calls minus the median of
   an empty call; when roitrack flags a problem ambiguous its answer is the set of poses it returns, correct when
   the truth is among them (OpenCV returns one pose and never flags);
4. prints a table per family and, with --check, fails naming the family and figure where roitrack does worse than
   the best OpenCV method (correct rate lower by more than one problem, median normalised error above 1.25 x, or
   more wrong answers given without a flag). Times are reported, never checked.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import cv2
import numpy as np

SUITE_FORMAT = "roitrack-pnp-suite/1"
PROBLEM_FORMAT = "roitrack-pnp-problem/1"

FAMILIES = [
    "3 points",
    "4-5 planar",
    "4-5 3-D",
    "6-40 planar",
    "6-40 off-plane 0.1-1%",
    "6-40 off-plane 1-10%",
    "6-40 3-D",
    "symmetric grids",
]
# Families whose user's target is planar (up to the user's 0.5 mm coordinate errors): IPPE is run on them. The
# off-plane families are treated as non-planar (IPPE skipped), as a user who knows the target is not flat would.
PLANAR_FAMILIES = {"4-5 planar", "6-40 planar", "symmetric grids"}
OFF_PLANE_RANGE = {"6-40 off-plane 0.1-1%": (0.001, 0.01), "6-40 off-plane 1-10%": (0.01, 0.1)}

IMAGE_SIZES_PX = [(320, 240), (640, 480), (800, 600), (1280, 960), (1920, 1080), (2448, 2048), (4096, 3000)]
SIZE_RANGE_M = (0.01, 1.0)
FOCAL_RANGE_PX = (300.0, 3000.0)
DISTANCE_RANGE_M = (0.2, 5.0)
NOISE_RANGE_PX = (0.03, 1.0)
MAX_TILT_DEG = 70.0
SPAN_RANGE = (0.05, 0.90)  # the target's image span over the image's smaller side
MARGIN_PX = 2.0
DISTANCE_TRIES = 50
RIG_TRIES = 10_000
# The user's model, off the truth.
INTRINSICS_OFF = 0.02  # fx, fy relative; cx, cy relative to the image size
K1_OFF = 0.05
POINT_OFF_M = 0.0005
# A lens whose radial map folds (d r_distorted / d r <= this) at a point of the target is not a lens a calibration
# would give: such a pose is redrawn, for the true lens and for the user's.
MIN_RADIAL_SLOPE = 0.2
# A solve is correct within this many standard deviations (of the Cramer-Rao bound) of p_model.
CORRECT_BELOW = 10.0
TIMED_CALLS = 20
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
REFINE_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-15)


# --- geometry (numpy only) -------------------------------------------------------------------------------------------


def hat(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def exp_so3(w: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(w))
    if angle < 1e-300:
        return np.eye(3)
    k = hat(w / angle)
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def angle_between_rad(ra: np.ndarray, rb: np.ndarray) -> float:
    """Geodesic angle between two rotations, accurate for small angles too (atan2 of sine and cosine)."""
    d = ra.T @ rb
    sine = 0.5 * np.linalg.norm([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]])
    cosine = 0.5 * (np.trace(d) - 1.0)
    return float(np.arctan2(sine, cosine))


def align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector a to unit vector b."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        # Opposite: half a turn about any axis perpendicular to a.
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return exp_so3(np.pi * perp / np.linalg.norm(perp))
    return exp_so3(axis / s * np.arctan2(s, c))


def log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def unit_vector(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


# --- targets ---------------------------------------------------------------------------------------------------------


def spread_points(rng: np.random.Generator, n: int, sides: np.ndarray) -> np.ndarray:
    """n points uniform in a box of these sides (2 or 3), none closer to another than a third of the mean spacing
    (dart throwing): distinct blobs, as on a real target."""
    min_distance = 0.3 * (np.prod(sides) / n) ** (1.0 / len(sides))
    while True:
        points: list[np.ndarray] = []
        for _ in range(200 * n):
            p = rng.uniform(0.0, 1.0, len(sides)) * sides
            if all(np.linalg.norm(p - q) >= min_distance for q in points):
                points.append(p)
                if len(points) == n:
                    return np.array(points)


def flat_extents(points: np.ndarray) -> np.ndarray:
    """Singular values of the centred points, largest first: how far the layout is from a line (2nd) or a plane
    (3rd)."""
    return np.linalg.svd(points - points.mean(axis=0), compute_uv=False)


def random_planar(rng: np.random.Generator, n: int) -> np.ndarray:
    """n points in a rectangle of aspect U(0.3, 1), in the plane z = 0, not nearly on one line."""
    while True:
        xy = spread_points(rng, n, np.array([1.0, rng.uniform(0.3, 1.0)]))
        s = flat_extents(xy)
        if s[1] >= 0.15 * s[0]:
            return np.c_[xy, np.zeros(n)]


def random_box(rng: np.random.Generator, n: int) -> np.ndarray:
    """n points in a box whose smallest side is at least 30 % of the largest, and truly spread in depth (the
    points' own smallest extent at least 10 % of their largest: four points of a box can by chance be nearly
    coplanar)."""
    while True:
        sides = rng.permutation(np.array([1.0, rng.uniform(0.3, 1.0), rng.uniform(0.3, 1.0)]))
        points = spread_points(rng, n, sides)
        s = flat_extents(points)
        if s[2] >= 0.1 * s[0]:
            return points


def grid(rng: np.random.Generator) -> tuple[np.ndarray, str]:
    """A square or hexagonal circle grid of 3 to 7 rows and 3 to 8 columns, unit spacing, id 0 at the origin (ids row
    by row, as `roitrack target grid` numbers them), no marked point."""
    rows, cols = int(rng.integers(3, 8)), int(rng.integers(3, 9))
    hexagonal = bool(rng.integers(0, 2))
    points = []
    for r in range(rows):
        for c in range(cols):
            if hexagonal:
                points.append([c + 0.5 * (r % 2), r * np.sqrt(3.0) / 2.0, 0.0])
            else:
                points.append([float(c), float(r), 0.0])
    return np.array(points), f"{'hexagonal' if hexagonal else 'square'} {rows}x{cols}"


def make_target(family: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, str]:
    """The true target (m), its normal in its own frame (a random direction for a 3-D target) and a description."""
    if family == "3 points":
        points, kind = random_planar(rng, 3), "triangle"
    elif family == "4-5 planar":
        points, kind = random_planar(rng, int(rng.integers(4, 6))), "random planar"
    elif family in ("4-5 3-D", "6-40 3-D"):
        n = int(rng.integers(4, 6)) if family == "4-5 3-D" else int(rng.integers(6, 41))
        points, kind = random_box(rng, n), "random 3-D"
    elif family == "6-40 planar":
        points, kind = random_planar(rng, int(rng.integers(6, 41))), "random planar"
    elif family in OFF_PLANE_RANGE:
        points = random_planar(rng, int(rng.integers(6, 41)))
        lo, hi = OFF_PLANE_RANGE[family]
        a = log_uniform(rng, lo, hi)
        # Off the plane by uniform(-a, a) x the largest extent (made 1 below; the displacement does not change it).
        extent = np.ptp(points[:, :2], axis=0).max()
        points[:, 2] = rng.uniform(-a, a, len(points)) * extent
        kind = f"random planar, off-plane +-{100 * a:.2f} %"
    elif family == "symmetric grids":
        points, kind = grid(rng)
    else:
        raise ValueError(f"unknown family {family!r}")
    if family in ("4-5 3-D", "6-40 3-D"):
        normal = unit_vector(rng)
    else:
        normal = np.array([0.0, 0.0, 1.0])
    if family != "symmetric grids":
        # Random layouts: origin at the centre of their bounding box.
        points = points - 0.5 * (points.min(axis=0) + points.max(axis=0))
    size_m = log_uniform(rng, *SIZE_RANGE_M)
    points = points * (size_m / np.ptp(points, axis=0).max())
    return points, normal, f"{kind}, {len(points)} points, size {size_m * 100:.2f} cm"


# --- camera and lens -------------------------------------------------------------------------------------------------


def radial_slope(k1: float, k2: float, r2: np.ndarray) -> np.ndarray:
    """d r_distorted / d r of plumb_bob's radial part at squared normalised radii r2."""
    return 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2


def draw_rig(family: str, rng: np.random.Generator) -> dict:
    """Camera with its true lens, the user's model of it, the target (true and the user's)."""
    width_px, height_px = IMAGE_SIZES_PX[int(rng.integers(len(IMAGE_SIZES_PX)))]
    fx = log_uniform(rng, *FOCAL_RANGE_PX)
    fy = fx * rng.uniform(0.98, 1.02)
    cx = width_px / 2.0 + rng.uniform(-0.05, 0.05) * width_px
    cy = height_px / 2.0 + rng.uniform(-0.05, 0.05) * height_px
    if rng.integers(0, 2):
        k1, k2 = rng.uniform(-0.3, 0.1), rng.uniform(-0.05, 0.05)
    else:
        k1, k2 = 0.0, 0.0
    points, normal, description = make_target(family, rng)
    user = {
        "fx": fx * (1.0 + rng.uniform(-INTRINSICS_OFF, INTRINSICS_OFF)),
        "fy": fy * (1.0 + rng.uniform(-INTRINSICS_OFF, INTRINSICS_OFF)),
        "cx": cx + rng.uniform(-INTRINSICS_OFF, INTRINSICS_OFF) * width_px,
        "cy": cy + rng.uniform(-INTRINSICS_OFF, INTRINSICS_OFF) * height_px,
        "k1": k1 + rng.uniform(-K1_OFF, K1_OFF),
        "k2": k2,
    }
    user_points = points + rng.uniform(-POINT_OFF_M, POINT_OFF_M, points.shape)
    return {
        "image_px": (width_px, height_px),
        "k": np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]),
        "dist": np.array([k1, k2, 0.0, 0.0, 0.0]),
        "user_k": np.array([[user["fx"], 0.0, user["cx"]], [0.0, user["fy"], user["cy"]], [0.0, 0.0, 1.0]]),
        "user_dist": np.array([user["k1"], user["k2"], 0.0, 0.0, 0.0]),
        "points": points,
        "user_points": user_points,
        "normal": normal,
        "description": description,
    }


def undistort(raw_px: np.ndarray, k: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Ideal pixels of raw pixels through a camera model (OpenCV's iterative inverse, run to convergence)."""
    out = cv2.undistortPoints(raw_px.reshape(-1, 1, 2), k, dist, R=None, P=k, criteria=UNDISTORT_CRITERIA)
    return out.reshape(-1, 2)


def project(points: np.ndarray, r: np.ndarray, t: np.ndarray, k: np.ndarray, dist) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(r)
    px, _ = cv2.projectPoints(points, rvec, t.reshape(3, 1), k, dist)
    return px.reshape(-1, 2)


def pose_fits(rig: dict, r: np.ndarray, t: np.ndarray) -> tuple[bool, str]:
    """Whether the posed target is in front of the camera, inside the image (margin), spans 5 % to 90 % of the
    smaller side, and sits where both lenses (true and the user's) are one-to-one."""
    cam = rig["points"] @ r.T + t
    if np.any(cam[:, 2] <= 1e-3):
        return False, "behind"
    xy = cam[:, :2] / cam[:, 2:3]
    r2 = np.sum(xy * xy, axis=1)
    for dist in (rig["dist"], rig["user_dist"]):
        if np.any(radial_slope(dist[0], dist[1], r2) <= MIN_RADIAL_SLOPE):
            return False, "lens folds"
    raw = project(rig["points"], r, t, rig["k"], rig["dist"])
    width_px, height_px = rig["image_px"]
    inside = (
        (raw[:, 0] >= MARGIN_PX)
        & (raw[:, 0] <= width_px - 1 - MARGIN_PX)
        & (raw[:, 1] >= MARGIN_PX)
        & (raw[:, 1] <= height_px - 1 - MARGIN_PX)
    )
    if not np.all(inside):
        return False, "outside"
    span = max(np.linalg.norm(raw[i] - raw[j]) for i in range(len(raw)) for j in range(i + 1, len(raw)))
    fraction = span / min(width_px, height_px)
    if fraction < SPAN_RANGE[0]:
        return False, "small"
    if fraction > SPAN_RANGE[1]:
        return False, "large"
    return True, ""


def draw_problem(family: str, seed: int, family_index: int, k: int) -> dict:
    """One problem, from its own generator (seed, family, k): the first N problems of a family do not depend on
    --per-family."""
    rng = np.random.default_rng([seed, family_index, k])
    for _ in range(RIG_TRIES):
        rig = draw_rig(family, rng)
        width_px, height_px = rig["image_px"]
        k_true = rig["k"]
        # Where the target sits: its centre on the ray of a pixel drawn uniformly over the image.
        u, v = rng.uniform(0, width_px), rng.uniform(0, height_px)
        ray = np.array([(u - k_true[0, 2]) / k_true[0, 0], (v - k_true[1, 2]) / k_true[1, 1], 1.0])
        sight = ray / np.linalg.norm(ray)
        # The target's normal tilted from the line of sight, then a random roll about it.
        tilt_rad = np.radians(rng.uniform(0.0, MAX_TILT_DEG))
        perp = np.cross(sight, unit_vector(rng))
        perp /= np.linalg.norm(perp)
        normal_cam = np.cos(tilt_rad) * sight + np.sin(tilt_rad) * perp
        roll = exp_so3(rig["normal"] * rng.uniform(0.0, 2.0 * np.pi))
        r = align(rig["normal"], normal_cam) @ roll
        centre_obj = rig["points"].mean(axis=0)
        for _ in range(DISTANCE_TRIES):
            distance_m = log_uniform(rng, *DISTANCE_RANGE_M)
            t = distance_m * sight - r @ centre_obj
            fits, _ = pose_fits(rig, r, t)
            if not fits:
                continue
            raw = project(rig["points"], r, t, rig["k"], rig["dist"])
            noise_px = log_uniform(rng, *NOISE_RANGE_PX)
            noisy = raw + rng.normal(0.0, noise_px, raw.shape)
            ideal = undistort(noisy, rig["user_k"], rig["user_dist"])
            ideal_clean = undistort(raw, rig["user_k"], rig["user_dist"])
            # The user's inverse must have converged: its ideal pixels map back onto the raw ones.
            back = project_ideal_to_raw(ideal, rig["user_k"], rig["user_dist"])
            if not np.all(np.isfinite(ideal)) or np.abs(back - noisy).max() > 1e-6:
                continue
            return {
                "family": family,
                "seed": seed,
                "k": k,
                "rig": rig,
                "r_true": r,
                "t_true": t,
                "distance_m": distance_m,
                "tilt_deg": float(np.degrees(tilt_rad)),
                "noise_px": noise_px,
                "raw_px": noisy,
                "ideal_px": ideal,
                "ideal_clean_px": ideal_clean,
            }
    raise RuntimeError(f"no pose fits the image for {family} problem {k} after {RIG_TRIES} rigs")


def project_ideal_to_raw(ideal_px: np.ndarray, k: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Raw pixels of ideal pixels through a camera model (the forward lens)."""
    n = np.c_[(ideal_px[:, 0] - k[0, 2]) / k[0, 0], (ideal_px[:, 1] - k[1, 2]) / k[1, 1], np.ones(len(ideal_px))]
    return project(n, np.eye(3), np.zeros(3), k, dist)


# --- reference and bound ---------------------------------------------------------------------------------------------


def pinhole(points: np.ndarray, r: np.ndarray, t: np.ndarray, k: np.ndarray) -> np.ndarray:
    cam = points @ r.T + t
    uvw = cam @ k.T
    return uvw[:, :2] / uvw[:, 2:3]


def pose_jacobian(points: np.ndarray, r: np.ndarray, t: np.ndarray, k: np.ndarray) -> np.ndarray:
    """d pixels / d (t, w) of the pinhole projection, R = Exp(w) R0, t = t0 + dt, by central differences."""
    columns = []
    step_m = 1e-6 * max(np.linalg.norm(t), 1e-3)
    step_rad = 1e-6
    for i in range(6):
        d = np.zeros(6)
        d[i] = step_m if i < 3 else step_rad
        plus = pinhole(points, exp_so3(d[3:]) @ r, t + d[:3], k)
        minus = pinhole(points, exp_so3(-d[3:]) @ r, t - d[:3], k)
        columns.append(((plus - minus) / (2.0 * d[i])).reshape(-1))
    return np.array(columns).T


def reference(problem: dict) -> dict:
    """p_model (the user's model on noise-free data, LM from the truth) and the Cramer-Rao bound there."""
    rig = problem["rig"]
    points, k = rig["user_points"], rig["user_k"]
    rvec, _ = cv2.Rodrigues(problem["r_true"])
    tvec = problem["t_true"].reshape(3, 1).copy()
    rvec, tvec = cv2.solvePnPRefineLM(
        points, problem["ideal_clean_px"], k, None, rvec.copy(), tvec, criteria=REFINE_CRITERIA
    )
    r_model, _ = cv2.Rodrigues(rvec)
    t_model = tvec.reshape(3)
    j = pose_jacobian(points, r_model, t_model, k)
    information = j.T @ j / problem["noise_px"] ** 2
    covariance = np.linalg.pinv(information)
    return {
        "r_model": r_model,
        "t_model": t_model,
        "sigma_t_m": float(np.sqrt(np.trace(covariance[:3, :3]))),
        "sigma_rot_rad": float(np.sqrt(np.trace(covariance[3:, 3:]))),
        "model_residual_rms_px": float(
            np.sqrt(np.mean((pinhole(points, r_model, t_model, k) - problem["ideal_clean_px"]) ** 2))
        ),
    }


def normalised_error(ref: dict, r: np.ndarray, t: np.ndarray) -> float:
    return max(
        float(np.linalg.norm(t - ref["t_model"])) / ref["sigma_t_m"],
        angle_between_rad(r, ref["r_model"]) / ref["sigma_rot_rad"],
    )


# --- OpenCV ----------------------------------------------------------------------------------------------------------


def cv_methods(family: str, n: int) -> list[str]:
    methods = ["SQPNP"]
    if family in PLANAR_FAMILIES and n >= 4:
        methods.append("IPPE")
    if n >= 4:
        methods.append("EPNP+LM")
    if n == 3:
        methods.append("AP3P")
    return methods


def cv_solver(method: str, points: np.ndarray, ideal: np.ndarray, k: np.ndarray):
    """A call that solves with `method` and returns (rvec, tvec) or None; every array made beforehand."""
    if method == "SQPNP":
        return lambda: _solved(cv2.solvePnP(points, ideal, k, None, flags=cv2.SOLVEPNP_SQPNP))
    if method == "IPPE":
        return lambda: _solved(cv2.solvePnP(points, ideal, k, None, flags=cv2.SOLVEPNP_IPPE))
    if method == "EPNP+LM":

        def epnp_lm():
            found = _solved(cv2.solvePnP(points, ideal, k, None, flags=cv2.SOLVEPNP_EPNP))
            if found is None:
                return None
            return cv2.solvePnPRefineLM(points, ideal, k, None, found[0], found[1])

        return epnp_lm
    if method == "AP3P":

        def ap3p():
            count, rvecs, tvecs = cv2.solveP3P(points, ideal, k, None, flags=cv2.SOLVEPNP_AP3P)
            return (rvecs[0], tvecs[0]) if count > 0 else None

        return ap3p
    raise ValueError(method)


def _solved(result):
    ok, rvec, tvec = result
    return (rvec, tvec) if ok and rvec is not None and tvec is not None else None


def median_time_us(call, calls: int) -> float:
    clock = time.perf_counter_ns
    times = []
    for _ in range(calls):
        start = clock()
        call()
        times.append(clock() - start)
    return float(np.median(times)) / 1e3


def run_opencv(problem: dict, ref: dict, empty_us: float) -> dict:
    rig = problem["rig"]
    points = np.ascontiguousarray(rig["user_points"], dtype=np.float64)
    ideal = np.ascontiguousarray(problem["ideal_px"], dtype=np.float64)
    k = np.ascontiguousarray(rig["user_k"], dtype=np.float64)
    out = {}
    for method in cv_methods(problem["family"], len(points)):
        call = cv_solver(method, points, ideal, k)
        try:
            found = call()
        except cv2.error as e:
            found, error = None, str(e).strip().splitlines()[-1]
        else:
            error = None if found is not None else "no solution"
        if found is None:
            out[method] = {"ok": False, "error": error, "error_norm": float("inf"), "time_us": float("nan")}
            continue
        r, _ = cv2.Rodrigues(found[0])
        t = np.asarray(found[1], dtype=float).reshape(3)
        try:
            time_us = median_time_us(call, TIMED_CALLS) - empty_us
        except cv2.error:
            time_us = float("nan")
        out[method] = {"ok": True, "error_norm": normalised_error(ref, r, t), "time_us": time_us}
    return out


# --- roitrack --------------------------------------------------------------------------------------------------------


def suite_entry(problem: dict, ref: dict) -> dict:
    rig = problem["rig"]
    k = rig["user_k"]
    return {
        "family": problem["family"],
        "problem": {
            "format": PROBLEM_FORMAT,
            "description": (
                f"pnp_families.py seed {problem['seed']}, {problem['family']} #{problem['k']}: the user's model "
                "(pinhole intrinsics, target) and the noisy raw pixels undistorted with it; the pose is p_model"
            ),
            "noise_px": problem["noise_px"],
            "intrinsics": {"fx_px": k[0, 0], "fy_px": k[1, 1], "skew_px": 0.0, "cx_px": k[0, 2], "cy_px": k[1, 2]},
            "model_points": [{"id": i, "xyz_m": p.tolist()} for i, p in enumerate(rig["user_points"])],
            "instances": [
                {
                    "cam_r_obj": ref["r_model"].tolist(),
                    "cam_t_obj_m": ref["t_model"].tolist(),
                    "pixels": problem["ideal_px"].tolist(),
                }
            ],
        },
    }


def run_roitrack(binary: str, suite_path: str, repeats: int) -> dict:
    cmd = [binary, "lab", "pnp-bench", "--suite", suite_path, "--json", "--repeats", str(repeats)]
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"pnp_families: {' '.join(cmd)} failed (status {out.returncode}):\n{out.stderr}")
    return json.loads(out.stdout)


def roitrack_result(solve: dict, ref: dict) -> dict:
    if not solve["ok"]:
        return {"ok": False, "error": solve["error"], "error_norm": float("inf"), "time_us": solve["median_time_us"]}
    errors = [normalised_error(ref, np.array(p["cam_r_obj"]), np.array(p["cam_t_obj_m"])) for p in solve["poses"]]
    # Flagged ambiguous, roitrack's answer is the set of poses it returns: it is right when the truth is among them,
    # and as accurate as the nearest. Unflagged, its answer is its best pose.
    return {
        "ok": True,
        "error_norm": min(errors) if solve["ambiguous"] else errors[0],
        "best_error_norm": errors[0],
        "all_error_norms": errors,
        "ambiguous": solve["ambiguous"],
        "pose_count": solve["pose_count"],
        "time_us": solve["median_time_us"],
    }


# --- figures ---------------------------------------------------------------------------------------------------------


def figures(results: list[dict], roitrack: bool) -> dict:
    """Correct %, wrong-and-unflagged % (a wrong pose given without a flag: roitrack flags by saying ambiguous,
    OpenCV never flags; a failure is no pose and counts in fail %), median normalised error (a failure counts as
    infinite), median time."""
    n = len(results)
    correct = sum(1 for r in results if r["ok"] and r["error_norm"] <= CORRECT_BELOW)
    failed = sum(1 for r in results if not r["ok"])
    unflagged = sum(
        1
        for r in results
        if r["ok"] and r.get("best_error_norm", r["error_norm"]) > CORRECT_BELOW and not (roitrack and r["ambiguous"])
    )
    times = [r["time_us"] for r in results if r["ok"] and np.isfinite(r["time_us"])]
    out = {
        "n": n,
        "correct": correct,
        "wrong_unflagged": unflagged,
        "failed": failed,
        "correct_pct": 100.0 * correct / n,
        "wrong_unflagged_pct": 100.0 * unflagged / n,
        "failed_pct": 100.0 * failed / n,
        "median_error": float(np.median([r["error_norm"] for r in results])),
        "median_time_us": float(np.median(times)) if times else float("nan"),
    }
    if roitrack:
        ambiguous = [r for r in results if r["ok"] and r["ambiguous"]]
        among = sum(1 for r in ambiguous if min(r["all_error_norms"]) <= CORRECT_BELOW)
        out["ambiguous"] = len(ambiguous)
        out["ambiguous_pct"] = 100.0 * len(ambiguous) / n
        out["truth_among_when_ambiguous_pct"] = 100.0 * among / len(ambiguous) if ambiguous else float("nan")
    return out


def check_family(family: str, ours: dict, theirs: dict[str, dict]) -> list[str]:
    """The --check failures of one family, each naming the family and the figure."""
    failures = []
    best_correct = max(theirs.items(), key=lambda kv: kv[1]["correct"])
    if ours["correct"] < best_correct[1]["correct"] - 1:
        failures.append(
            f"{family}: correct {ours['correct']}/{ours['n']} ({ours['correct_pct']:.1f} %), below cv2 "
            f"{best_correct[0]}'s {best_correct[1]['correct']}/{ours['n']} by more than one problem"
        )
    best_error = min(theirs.items(), key=lambda kv: kv[1]["median_error"])
    if ours["median_error"] > 1.25 * best_error[1]["median_error"]:
        failures.append(
            f"{family}: median normalised error {ours['median_error']:.3g}, above 1.25 x cv2 {best_error[0]}'s "
            f"{best_error[1]['median_error']:.3g}"
        )
    best_unflagged = min(theirs.items(), key=lambda kv: kv[1]["wrong_unflagged"])
    if ours["wrong_unflagged"] > best_unflagged[1]["wrong_unflagged"]:
        failures.append(
            f"{family}: wrong and unflagged {ours['wrong_unflagged']}/{ours['n']} "
            f"({ours['wrong_unflagged_pct']:.1f} %), above cv2 {best_unflagged[0]}'s "
            f"{best_unflagged[1]['wrong_unflagged']}/{ours['n']}"
        )
    return failures


def describe(problem: dict, ref: dict) -> str:
    rig = problem["rig"]
    k, (w, h) = rig["k"], rig["image_px"]
    return (
        f"{rig['description']}; camera {w}x{h}, fx {k[0, 0]:.0f} px, k1 {rig['dist'][0]:+.3f} "
        f"(user {rig['user_dist'][0]:+.3f}); distance {problem['distance_m']:.3f} m, tilt {problem['tilt_deg']:.1f} "
        f"deg; noise {problem['noise_px']:.3f} px; CRB sqrt(tr) {ref['sigma_t_m'] * 1e3:.3g} mm, "
        f"{np.degrees(ref['sigma_rot_rad']):.3g} deg; p_model residual {ref['model_residual_rms_px']:.3f} px"
    )


def print_family_table(family: str, ours: dict, theirs: dict[str, dict]) -> None:
    print(f"\n## {family}: {ours['n']} problems")
    header = (
        f"  {'method':<12} {'correct %':>9} {'wrong-unflagged %':>17} {'fail %':>6} {'median err':>10} "
        f"{'median us':>9}"
    )
    print(header)
    for name, f in [("roitrack", ours)] + [(f"cv2 {m}", f) for m, f in theirs.items()]:
        print(
            f"  {name:<12} {f['correct_pct']:>9.1f} {f['wrong_unflagged_pct']:>17.1f} {f['failed_pct']:>6.1f} "
            f"{f['median_error']:>10.3g} {f['median_time_us']:>9.1f}"
        )
    among = ours["truth_among_when_ambiguous_pct"]
    print(
        f"  roitrack ambiguous {ours['ambiguous_pct']:.1f} % ({ours['ambiguous']}); truth among its poses when "
        f"ambiguous: {'-' if np.isnan(among) else f'{among:.1f} %'}"
    )


def finite_or_none(value):
    """The JSON report with a failure's infinite error as null (JSON has no infinity)."""
    if isinstance(value, float) and not np.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_none(v) for v in value]
    return value


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--roitrack", required=True, help="path of the roitrack binary (release build)")
    parser.add_argument("--seed", type=int, default=34)
    parser.add_argument("--per-family", type=int, default=40, help="problems drawn in each family")
    parser.add_argument("--json", dest="json_out", help="also write every problem's figures and the summary here")
    parser.add_argument("--suite-out", help="keep the suite file here (default: a temporary file, removed)")
    parser.add_argument(
        "--check",
        action="store_true",
        help="exit 1, naming family and figure, where roitrack does worse than the best OpenCV method",
    )
    parser.add_argument(
        "--list-wrong", action="store_true", help="list every problem roitrack got wrong, with its parameters"
    )
    args = parser.parse_args()
    if args.per_family < 1:
        parser.error("--per-family must be at least 1")
    start_s = time.monotonic()

    problems, refs = [], []
    for family_index, family in enumerate(FAMILIES):
        for k in range(args.per_family):
            problem = draw_problem(family, args.seed, family_index, k)
            problems.append(problem)
            refs.append(reference(problem))
    suite = {"format": SUITE_FORMAT, "problems": [suite_entry(p, r) for p, r in zip(problems, refs)]}

    if args.suite_out:
        suite_path = args.suite_out
        with open(suite_path, "w") as f:
            json.dump(suite, f)
        report = run_roitrack(args.roitrack, suite_path, TIMED_CALLS)
    else:
        with tempfile.TemporaryDirectory(prefix="pnp_families_") as folder:
            suite_path = os.path.join(folder, "suite.json")
            with open(suite_path, "w") as f:
                json.dump(suite, f)
            report = run_roitrack(args.roitrack, suite_path, TIMED_CALLS)
    if len(report["problems"]) != len(problems):
        sys.exit(f"pnp_families: roitrack answered {len(report['problems'])} problems of {len(problems)}")

    # The Python cost of a timed call: an empty cv2 call timed the same way, subtracted from every OpenCV time.
    empty_us = float(np.median([median_time_us(cv2.getTickCount, TIMED_CALLS) for _ in range(100)]))
    ours_all = [roitrack_result(s, ref) for s, ref in zip(report["problems"], refs)]
    cv_all = [run_opencv(p, ref, empty_us) for p, ref in zip(problems, refs)]

    print(f"# roitrack vs OpenCV on random PnP families, {datetime.datetime.now().astimezone():%Y-%m-%d %H:%M %Z}")
    print(
        f"# machine: {platform.machine()}, {os.cpu_count()} logical CPUs; Python {platform.python_version()}, "
        f"OpenCV {cv2.__version__}, numpy {np.__version__}"
    )
    print(
        f"# seed {args.seed}, {args.per_family} problems per family; correct = normalised error <= {CORRECT_BELOW:g} "
        "(max of position and rotation error from p_model over sqrt(trace) of their Cramer-Rao covariance)"
    )
    print(
        f"# times: median of {TIMED_CALLS} calls per problem (OpenCV: minus {empty_us:.2f} us, an empty cv2 call), "
        "median over the family; not checked"
    )
    all_failures: list[str] = []
    summary = {}
    for family in FAMILIES:
        index = [i for i, p in enumerate(problems) if p["family"] == family]
        ours = figures([ours_all[i] for i in index], roitrack=True)
        methods = list(cv_all[index[0]].keys())
        theirs = {m: figures([cv_all[i][m] for i in index], roitrack=False) for m in methods}
        print_family_table(family, ours, theirs)
        failures = check_family(family, ours, theirs)
        all_failures += failures
        summary[family] = {"roitrack": ours, **{f"cv2 {m}": f for m, f in theirs.items()}, "check": failures}
        wrong = [i for i in index if ours_all[i]["error_norm"] > CORRECT_BELOW]
        if wrong and (args.list_wrong or (args.check and failures)):
            print("  roitrack wrong on (suite index, family #k: normalised errors, parameters):")
            for i in wrong:
                o = ours_all[i]
                errs = ", ".join(f"{e:.3g}" for e in o.get("all_error_norms", [o["error_norm"]]))
                cv = ", ".join(f"{m} {cv_all[i][m]['error_norm']:.3g}" for m in methods)
                flag = "ambiguous" if o.get("ambiguous") else ("error: " + o["error"] if not o["ok"] else "unflagged")
                print(f"    [{i}] {family} #{problems[i]['k']}: roitrack {errs} ({flag}); cv2 {cv}")
                print(f"        {describe(problems[i], refs[i])}")

    print(f"\n# {len(problems)} problems in {time.monotonic() - start_s:.1f} s")
    if args.json_out:
        per_problem = []
        for i, (p, ref) in enumerate(zip(problems, refs)):
            per_problem.append(
                {
                    "index": i,
                    "family": p["family"],
                    "k": p["k"],
                    "parameters": describe(p, ref),
                    "roitrack": ours_all[i],
                    "opencv": cv_all[i],
                }
            )
        with open(args.json_out, "w") as f:
            report_json = {
                "seed": args.seed,
                "per_family": args.per_family,
                "versions": {"opencv": cv2.__version__, "numpy": np.__version__},
                "summary": summary,
                "problems": per_problem,
                "checks": all_failures,
            }
            json.dump(finite_or_none(report_json), f, indent=1, allow_nan=False)
    if args.check:
        if all_failures:
            print("# check: FAIL")
            for failure in all_failures:
                print(f"#   {failure}")
            return 1
        print("# check: PASS (on every family roitrack's correct rate, median error and unflagged wrong answers "
              "are as good as the best OpenCV method's)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
