"""Errors that command lines raise before anything heavy is imported."""

from __future__ import annotations


class ConfigError(Exception):
    """Bad configuration: the message names every bad field and where it may come from."""
