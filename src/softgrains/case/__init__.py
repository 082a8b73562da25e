"""Case files: the pydantic schema (docs/case-schema.md), loading with overrides, summaries."""

from softgrains.case.load import case_to_toml, load_case, summarize
from softgrains.case.schema import Case, estimate_points

__all__ = ["Case", "case_to_toml", "estimate_points", "load_case", "summarize"]
