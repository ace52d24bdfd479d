"""Type stubs of the compiled module (crates/roitrack-python/src/lib.rs)."""

import os
from collections.abc import Sequence
from typing import Any, Optional, Union, final

import numpy as np
import numpy.typing as npt

__all__ = [
    "Camera",
    "Target",
    "Tracker",
    "Estimate",
    "track",
    "detect",
    "simulate",
    "evaluate",
    "RoitrackError",
    "_tracker_options",
]

_Path = Union[str, "os.PathLike[str]"]
_F64 = npt.NDArray[np.float64]

class RoitrackError(ValueError): ...

@final
class Camera:
    def __new__(
        cls,
        width: int,
        height: int,
        fx: float,
        fy: float,
        cx: float,
        cy: float,
        distortion: Optional[Sequence[float]] = None,
        model: str = "plumb_bob",
        skew: float = 0.0,
    ) -> "Camera": ...
    @staticmethod
    def from_yaml(path: _Path) -> "Camera": ...
    @staticmethod
    def from_file(
        path: _Path, image_size: Optional[tuple[int, int]] = None, camera_name: Optional[str] = None
    ) -> "Camera": ...
    def to_yaml(self, path: _Path) -> None: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def fx(self) -> float: ...
    @property
    def fy(self) -> float: ...
    @property
    def cx(self) -> float: ...
    @property
    def cy(self) -> float: ...
    @property
    def skew(self) -> float: ...
    @property
    def distortion(self) -> list[float]: ...
    @property
    def model(self) -> str: ...

@final
class Target:
    def __new__(
        cls,
        points_m: npt.ArrayLike,
        ids: Optional[Sequence[int]] = None,
        diameters_m: Optional[Sequence[float]] = None,
    ) -> "Target": ...
    @staticmethod
    def from_csv(path: _Path, units: Optional[str] = None) -> "Target": ...
    def to_csv(self, path: _Path) -> None: ...
    @property
    def points_m(self) -> _F64: ...
    @property
    def ids(self) -> npt.NDArray[np.uint32]: ...
    @property
    def diameters_m(self) -> _F64: ...
    def __len__(self) -> int: ...

@final
class Estimate:
    @property
    def t_s(self) -> float: ...
    @property
    def position_m(self) -> _F64: ...
    @property
    def quaternion_xyzw(self) -> _F64: ...
    @property
    def velocity_mps(self) -> _F64: ...
    @property
    def angular_velocity_radps(self) -> _F64: ...
    @property
    def covariance(self) -> _F64: ...
    @property
    def status(self) -> str: ...
    @property
    def residual_px(self) -> float: ...
    @property
    def conditioning(self) -> float: ...
    @property
    def measurements_used(self) -> int: ...
    @property
    def noise_px(self) -> float: ...

@final
class Tracker:
    def __new__(
        cls,
        camera: Camera,
        target: Target,
        estimator: str = "kalman",
        every: int = 10,
        gain: float = 1.0,
        iterations: int = 1,
        window: int = 0,
        noise_px: float = 0.1,
        adapt: Optional[str] = None,
        accel_psd: Optional[float] = None,
        angular_accel_psd: Optional[float] = None,
        motion_model: Optional[str] = None,
        jerk_psd: Optional[float] = None,
        angular_jerk_psd: Optional[float] = None,
        robust: str = "tukey",
        min_conditioning: Optional[float] = None,
    ) -> "Tracker": ...
    def push(self, t_s: float, point_id: int, u_px: float, v_px: float) -> Optional[Estimate]: ...
    def reset(self) -> None: ...
    @property
    def measurements(self) -> int: ...

def track(
    camera: Camera,
    target: Target,
    measurements: npt.ArrayLike,
    estimator: str = "kalman",
    every: int = 10,
    gain: float = 1.0,
    iterations: int = 1,
    window: int = 0,
    noise_px: float = 0.1,
    adapt: Optional[str] = None,
    accel_psd: Optional[float] = None,
    angular_accel_psd: Optional[float] = None,
    motion_model: Optional[str] = None,
    jerk_psd: Optional[float] = None,
    angular_jerk_psd: Optional[float] = None,
    robust: str = "tukey",
    min_conditioning: Optional[float] = None,
) -> dict[str, Any]: ...
def detect(
    camera: Camera,
    target: Target,
    image: npt.NDArray[Union[np.uint8, np.uint16]],
    polarity: str = "auto",
    distance_m: Optional[tuple[float, float]] = None,
) -> dict[str, Any]: ...
def simulate(
    scenario: str,
    seed: int = 1,
    camera: Optional[Camera] = None,
    target: Optional[Target] = None,
    noise_px: float = 0.1,
    rate_hz: float = 4000.0,
    order: str = "bitrev",
    drop: float = 0.0,
    outliers: float = 0.0,
) -> dict[str, Any]: ...
def evaluate(sim: dict[str, Any], res: dict[str, Any]) -> dict[str, Any]: ...
# Only in a wheel built with the feature `lab` (bench/python_bench.py); private, so stubtest does not miss it in the
# default wheel.
def _bench_track_library(runs: int = 5) -> float: ...
# The table of tracker options (name, shape, default as Python writes it, Rust type): for tests/test_options.py.
def _tracker_options() -> list[tuple[str, str, str, str]]: ...
