"""Robots heard on the bus: where each is now and where it was over the last minute."""

from __future__ import annotations

import datetime as dt

from fastapi import APIRouter, Response
from pydantic import BaseModel, Field

from api.deps import MapDep, RevisionQuery, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, Responses, example_config, not_found
from atlas.robots import robots as stored_robots
from shared.robots import TrackPoint
from shared.vocabulary import REVISION_HEADER

router = APIRouter(prefix="/v1/maps/{map_name}/robots", tags=["robots"], responses=COMMON_ERRORS)

_ERRORS: Responses = {**not_found("No such map or revision."), **UNPROCESSABLE}


class PoseOut(BaseModel):
    x_m: float = Field(description="x of the lidar, metres, map frame.")
    y_m: float = Field(description="y of the lidar, metres, map frame.")
    yaw_rad: float = Field(description="Heading, radians from the map x axis.")
    stamp_ns: int = Field(description="Time of the scan the pose is from, ns since the Unix epoch (robot clock).")


class RobotOut(BaseModel):
    robot: str = Field(description="The robot's ROS namespace without slashes (empty: the root namespace).")
    pose: PoseOut = Field(description="Where the robot's lidar was at its newest scan the map took in.")
    seen_at: dt.datetime = Field(description="`pose.stamp_ns` as a time (UTC).")
    track: list[PoseOut] = Field(description="Its poses over the minute before, oldest first, ending at `pose`.")
    revision_id: int = Field(description="Revision that stored this pose.")


class RobotsOut(BaseModel):
    robots: list[RobotOut]

    model_config = example_config(robots=[{
        "robot": "robot1", "pose": {"x_m": 12.4, "y_m": 3.1, "yaw_rad": 1.57, "stamp_ns": 1767225600000000000},
        "seen_at": "2026-01-01T00:00:00Z", "revision_id": 1207,
        "track": [{"x_m": 12.4, "y_m": 1.1, "yaw_rad": 1.57, "stamp_ns": 1767225598000000000},
                  {"x_m": 12.4, "y_m": 3.1, "yaw_rad": 1.57, "stamp_ns": 1767225600000000000}]}])


def _pose(point: TrackPoint) -> PoseOut:
    return PoseOut(x_m=point.x_m, y_m=point.y_m, yaw_rad=point.yaw_rad, stamp_ns=point.stamp_ns)


@router.get("", summary="Robots and their tracks", responses=_ERRORS)
def list_robots(map_info: MapDep, store: StoreDep, revision: RevisionQuery, response: Response) -> RobotsOut:
    """Every robot the map was built from, as at ``?revision=`` (default: now): its latest pose in the map frame
    and its track over the last minute.

    The occupancy stage stores them with each occupancy revision (every few seconds while a robot's scans
    arrive), as `robot` features: a revision event whose `features` names `robot` says they moved. A robot that
    went quiet keeps its last pose; `seen_at` says when that was.
    """
    found = stored_robots(store, map_info, revision=revision)
    if found:
        response.headers[REVISION_HEADER] = str(max(item.revision_id for item in found))
    return RobotsOut(robots=[
        RobotOut(robot=item.robot.robot, pose=_pose(item.robot.pose),
                 seen_at=dt.datetime.fromtimestamp(item.robot.pose.stamp_ns / 1e9, tz=dt.UTC),
                 track=[_pose(p) for p in item.robot.track], revision_id=item.revision_id)
        for item in found])
