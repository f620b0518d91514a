"""Benchmarks: speed figures measured against a reference in the same run (docs/benchmarks.md)."""
