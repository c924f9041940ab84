"""Sim-to-real gap diagnosis (placeholder docstring, expanded below)."""

from .diagnose import SCHEMA, diagnose, diagnose_per_flight, prepare

__all__ = ["SCHEMA", "diagnose", "diagnose_per_flight", "prepare"]
