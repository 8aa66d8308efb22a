"""Scenes to explore and what a perfect exploration of each can observe."""

from areas.area import Area, AreaInfo, GroundTruth, StartPose
from areas.ground_truth import load_ground_truth
from areas.registry import UnknownAreaError, area_names, load_area

__all__ = [
    "Area",
    "AreaInfo",
    "GroundTruth",
    "StartPose",
    "UnknownAreaError",
    "area_names",
    "load_area",
    "load_ground_truth",
]
