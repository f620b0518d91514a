"""Errors that command lines raise before anything heavy is imported."""

from __future__ import annotations


class ConfigError(Exception):
    """Bad configuration: the message names every bad field and where it may come from."""


class StartupError(RuntimeError):
    """A service cannot start (a port in use, a device that does not answer, a bad file)."""
