"""The object-labelling service's error type."""

from __future__ import annotations


class ObjectLabellingError(ValueError):
    """Input the object labeller cannot use: malformed images, camera models, planes, weights or models."""
