"""The fault campaign (``python -m benchmarks.faults``; docs/reliability.md)."""

from benchmarks.faults.campaign import STEPS, Row, run, table

__all__ = ["STEPS", "Row", "run", "table"]
