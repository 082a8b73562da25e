"""Initial samples of grains: loose random disk packings (packing.py) in a box of kinematic
walls (box.py), for compaction runs."""

from softgrains.sample.box import GRAIN_PREFIX, WALLS, BoxLayout, box_layout
from softgrains.sample.packing import DiskSample, generate_disks

__all__ = ["GRAIN_PREFIX", "WALLS", "BoxLayout", "DiskSample", "box_layout", "generate_disks"]
