"""Grid layers <-> nav_msgs/OccupancyGrid messages."""

from __future__ import annotations

from typing import Any

import numpy as np

from shared import messages
from shared.store import GridLayer, StoreError


def _stamp(stamp_ns: int) -> Any:
    return messages.message_class("builtin_interfaces/msg/Time")(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)


def occupancy_grid_message(layer: GridLayer, *, stamp_ns: int, frame_id: str) -> Any:
    """A nav_msgs/OccupancyGrid of an int8 occupancy layer (-1 unknown, 0..100)."""
    if layer.data.dtype != np.int8:
        raise StoreError(f"layer {layer.name!r} is {layer.data.dtype}, an OccupancyGrid needs int8")
    cls = messages.message_class
    height, width = layer.data.shape
    pose = cls("geometry_msgs/msg/Pose")(
        position=cls("geometry_msgs/msg/Point")(x=layer.origin_x_m, y=layer.origin_y_m, z=0.0),
        orientation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0),
    )
    info = cls("nav_msgs/msg/MapMetaData")(map_load_time=_stamp(stamp_ns), resolution=layer.resolution_m,
                                           width=width, height=height, origin=pose)
    header = cls("std_msgs/msg/Header")(stamp=_stamp(stamp_ns), frame_id=frame_id)
    return cls(messages.OCCUPANCY_GRID)(header=header, info=info, data=layer.data.ravel())


def layer_from_occupancy_grid(message: Any, *, name: str) -> GridLayer:
    """The int8 layer in a nav_msgs/OccupancyGrid; raises :class:`StoreError` if sizes disagree.

    The map origin's rotation is not applied: Aisle grids are axis-aligned with their frame.
    """
    width, height = int(message.info.width), int(message.info.height)
    data = np.asarray(message.data, dtype=np.int8)
    if width * height == 0 or data.size != width * height:
        raise StoreError(f"OccupancyGrid says {width} x {height} cells but carries {data.size} values")
    origin = message.info.origin.position
    return GridLayer(name, data.reshape(height, width).copy(), float(message.info.resolution), float(origin.x),
                     float(origin.y), {"frame_id": message.header.frame_id})
