"""The grid-decomposition service's error type."""

from __future__ import annotations


class DecompositionError(ValueError):
    """Input the decomposition cannot use: empty, unknown-only or malformed maps and map files."""
