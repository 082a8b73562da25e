"""Initial samples of grains: loose random disk packings for compaction runs (packing.py)."""

from softgrains.sample.packing import DiskSample, generate_disks

__all__ = ["DiskSample", "generate_disks"]
