"""Navigation over the map: the region graph of the grid decomposition with portals, blocked regions and
connections, drivable routes, and the waypoint network the LIF and Open-RMF exports write."""

from atlas.navigation.blocks import (
    BLOCKABLE_KEY_PATTERN,
    OPERATOR_STAGE,
    REGION_KEY_PATTERN,
    Block,
    read_blocks,
    region_pair,
    write_blocks,
)
from atlas.navigation.ends import KEY_PATTERN, End, Located, locate_end, parse_end, place_pose
from atlas.navigation.errors import (
    EndSyntaxError,
    NavigationError,
    NavigationUnavailableError,
    NoRouteError,
    UnknownEndError,
)
from atlas.navigation.graph import ROUTE_CONNECTIONS, NavMap, Region, ResolvedBlock, build_navmap, load_navmap
from atlas.navigation.grid import FREE_BELOW, Frame
from atlas.navigation.portals import Portal, find_portals
from atlas.navigation.routes import Route, Waypoint, plan_route

__all__ = [
    "BLOCKABLE_KEY_PATTERN",
    "FREE_BELOW",
    "KEY_PATTERN",
    "OPERATOR_STAGE",
    "REGION_KEY_PATTERN",
    "ROUTE_CONNECTIONS",
    "Block",
    "End",
    "EndSyntaxError",
    "Frame",
    "Located",
    "NavMap",
    "NavigationError",
    "NavigationUnavailableError",
    "NoRouteError",
    "Portal",
    "Region",
    "ResolvedBlock",
    "Route",
    "UnknownEndError",
    "Waypoint",
    "build_navmap",
    "find_portals",
    "load_navmap",
    "locate_end",
    "parse_end",
    "place_pose",
    "plan_route",
    "read_blocks",
    "region_pair",
    "write_blocks",
]
