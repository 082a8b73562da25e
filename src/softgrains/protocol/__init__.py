"""Loading programmes that drive the walls of a generated sample (ALGORITHM.md §8)."""

from softgrains.protocol.uniaxial import UniaxialCompaction

__all__ = ["UniaxialCompaction"]
