"""Grid layers <-> nav_msgs/OccupancyGrid messages."""

from __future__ import annotations

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Point as Point
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Quaternion as Quaternion
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__MapMetaData as MapMetaData
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__OccupancyGrid as OccupancyGrid

from shared.messages import header, time_msg
from shared.store import GridLayer, StoreError


def occupancy_grid_message(layer: GridLayer, *, stamp_ns: int, frame_id: str) -> OccupancyGrid:
    """A nav_msgs/OccupancyGrid of an int8 occupancy layer (-1 unknown, 0..100)."""
    if layer.data.dtype != np.int8:
        raise StoreError(f"layer {layer.name!r} is {layer.data.dtype}, an OccupancyGrid needs int8")
    height, width = layer.data.shape
    pose = Pose(position=Point(x=layer.origin_x_m, y=layer.origin_y_m, z=0.0),
                orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))
    info = MapMetaData(map_load_time=time_msg(stamp_ns), resolution=layer.resolution_m, width=width, height=height,
                       origin=pose)
    return OccupancyGrid(header=header(stamp_ns, frame_id), info=info, data=layer.data.ravel())


def layer_from_occupancy_grid(message: OccupancyGrid, *, name: str) -> GridLayer:
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
