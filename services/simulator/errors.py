"""The simulator's error type."""

from __future__ import annotations


class SimulatorError(ValueError):
    """A layout, route, robot or sensor setting the simulator cannot use."""
