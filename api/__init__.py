"""The WMS-facing REST API over the layered map."""

from api.app import create_app

__all__ = ["create_app"]
