"""Domain errors of the map queries as HTTP errors: the status each kind of error means, its message the
``detail``."""

from __future__ import annotations

from fastapi import HTTPException, status

from atlas.errors import AtlasError, ConflictError, InvalidQueryError, NotInMapError, TooLargeError
from atlas.navigation import EndSyntaxError, NavigationError, UnknownEndError


def http_error(err: AtlasError | NavigationError) -> HTTPException:
    """The HTTP error a domain error means: 404 for something the map lacks, 422 for a query written wrong,
    409 for a map not in a state to answer (no regions yet, no drivable route), 413 for too much."""
    if isinstance(err, EndSyntaxError | InvalidQueryError):
        return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err))
    if isinstance(err, UnknownEndError | NotInMapError):
        return HTTPException(status.HTTP_404_NOT_FOUND, str(err))
    if isinstance(err, TooLargeError):
        return HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, str(err))
    if isinstance(err, NavigationError | ConflictError):
        return HTTPException(status.HTTP_409_CONFLICT, str(err))
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err))
