"""Errors of navigation: the API turns each into an HTTP status with its message as ``detail``."""

from __future__ import annotations


class NavigationError(ValueError):
    """Something navigation cannot do as asked."""


class NavigationUnavailableError(NavigationError):
    """The map has nothing to navigate yet (no region decomposition at the revision asked for)."""


class NoRouteError(NavigationError):
    """No drivable route joins the two ends (blocked, disconnected, or an end off every drivable region)."""


class EndSyntaxError(NavigationError):
    """A route end that is not written in one of the accepted forms."""


class UnknownEndError(NavigationError):
    """A route end naming a bin or place the map does not have."""
