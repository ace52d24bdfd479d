"""roitrack: high-rate 3-D pose and velocity tracking of a rigid target from timestamped blob centroids.

The Python face of the roitrack Rust library: numpy arrays in and out, the command line's results and error messages.

>>> import roitrack
>>> sim = roitrack.simulate("orthoglide", seed=1)
>>> res = roitrack.track(sim["camera"], sim["target"], sim["measurements"], estimator="kalman", every=10)
>>> metrics = roitrack.evaluate(sim, res)
>>> metrics["position_rmse_mm"] < 0.5
True
"""

from roitrack._roitrack import (
    Camera,
    Estimate,
    RoitrackError,
    Target,
    Tracker,
    detect,
    evaluate,
    simulate,
    track,
)

__all__ = [
    "Camera",
    "Estimate",
    "RoitrackError",
    "Target",
    "Tracker",
    "detect",
    "evaluate",
    "simulate",
    "track",
]
