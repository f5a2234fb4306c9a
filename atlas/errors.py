"""Errors of the map queries; the API turns each into an HTTP status with its message as ``detail``.

Navigation (:mod:`atlas.navigation.errors`), exports (:mod:`atlas.exports.base`) and rendering
(:mod:`atlas.render.layers`) have error types of their own.
"""

from __future__ import annotations


class AtlasError(ValueError):
    """A map query that cannot be answered as asked."""


class AtlasConfigError(AtlasError):
    """An option of the map queries that makes no sense (a staleness that is not a number of seconds, ...)."""


class NotInMapError(AtlasError):
    """Something asked for that the map does not have (a bin, a region, a block, a WMS list)."""


class InvalidQueryError(AtlasError):
    """A query the map cannot answer as written (a label that is not one, a region that is not drivable)."""


class ConflictError(AtlasError):
    """A change the map is not in a state to take (a region without cells, a map not decomposed yet)."""


class TooLargeError(AtlasError):
    """More features than one answer may hold."""
