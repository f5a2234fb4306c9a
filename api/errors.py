"""The API's own error type."""

from __future__ import annotations


class ApiConfigError(ValueError):
    """An API option that makes no sense (a rate that is not positive, an origin that is not a URL, ...)."""
