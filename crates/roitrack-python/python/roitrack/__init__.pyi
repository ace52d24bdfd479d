from roitrack._roitrack import Camera as Camera
from roitrack._roitrack import Estimate as Estimate
from roitrack._roitrack import RoitrackError as RoitrackError
from roitrack._roitrack import Target as Target
from roitrack._roitrack import Tracker as Tracker
from roitrack._roitrack import detect as detect
from roitrack._roitrack import evaluate as evaluate
from roitrack._roitrack import simulate as simulate
from roitrack._roitrack import track as track

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
