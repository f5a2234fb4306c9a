"""Named places people set: docks, gates and chargers, with the pose a vehicle approaches them at."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt
from fastapi import APIRouter, HTTPException, Path, Query, Response, status
from pydantic import BaseModel, Field

from api.deps import AnnouncerDep, MapDep, RevisionQuery, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, Responses, example_config, not_found
from atlas.navigation import KEY_PATTERN, OPERATOR_STAGE, place_pose
from atlas.navigation.blocks import OPERATOR_LOCK
from atlas.navigation.ends import MAX_COORDINATE_M, geometry_centre
from shared.store import Feature, MapStore, RevisionWrite, StoredFeature
from shared.vocabulary import PLACE_KINDS

router = APIRouter(prefix="/v1/maps/{map_name}/places", tags=["places"], responses=COMMON_ERRORS)

PlaceKind = Literal["dock", "gate", "charger"]
MAX_PLACE_SIDE_M = 500.0
"""Longest side of a place's bounds; a dock or charger is metres across, so more is a mistake."""
MAX_APPROACH_M = 50.0
"""Farthest an approach pose may lie from the middle of its place."""
MAX_RING_POINTS = 256
MIN_AREA_M2 = 1e-4
RESERVED_PROPERTIES = frozenset({"name", "approach_pose", "kind", "key", "stage", "revision_id", "confidence",
                                 "pose"})

_ERRORS: Responses = {**not_found("No such map, revision or place."), **UNPROCESSABLE}

Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M, allow_inf_nan=False)]
Position = tuple[Coordinate, Coordinate]
Scalar = (Annotated[str, Field(max_length=256)] | bool | Annotated[int, Field(ge=-(2**53), le=2**53)]
          | Annotated[float, Field(allow_inf_nan=False)] | None)


class PointIn(BaseModel):
    type: Literal["Point"]
    coordinates: Position = Field(description="(x, y) in map-frame metres.")


class PolygonIn(BaseModel):
    type: Literal["Polygon"]
    coordinates: Annotated[
        list[Annotated[list[Position], Field(min_length=4, max_length=MAX_RING_POINTS)]],
        Field(min_length=1, max_length=1, description="One closed ring (first point repeated last) of (x, y), "
                                                      "metres, map frame; no holes."),
    ]


class PlacePose(BaseModel):
    x_m: Coordinate = Field(description="x, metres, map frame.")
    y_m: Coordinate = Field(description="y, metres, map frame.")
    yaw_rad: Annotated[float, Field(ge=-2 * math.pi, le=2 * math.pi, allow_inf_nan=False,
                                    description="Heading on arrival, radians from the map frame's x axis.")]


class NamedPlaceIn(BaseModel):
    geometry: Annotated[PointIn | PolygonIn, Field(discriminator="type",
                                                   description="GeoJSON Point or Polygon in map-frame metres.")]
    name: str | None = Field(default=None, max_length=128, description="For people, e.g. `Dock 1 (north)`.")
    approach_pose: PlacePose | None = Field(
        default=None, description="Where a vehicle stops to use the place; routes to it end here.")
    properties: Annotated[dict[Annotated[str, Field(min_length=1, max_length=64)], Scalar],
                          Field(max_length=32, description="Anything else, flat (strings, numbers, booleans).")
                          ] = Field(default_factory=dict)

    model_config = {"json_schema_extra": {"examples": [{
        "geometry": {"type": "Polygon", "coordinates": [[[4, 0], [7, 0], [7, 1], [4, 1], [4, 0]]]},
        "name": "Dock 1", "approach_pose": {"x_m": 5.5, "y_m": 2.0, "yaw_rad": -1.5708},
        "properties": {"door_height_m": 4.2}}]}}


_PLACE_EXAMPLE: dict[str, Any] = {
    "kind": "dock", "key": "G1", "name": "Dock 1",
    "geometry": {"type": "Polygon", "coordinates": [[[4, 0], [7, 0], [7, 1], [4, 1], [4, 0]]]},
    "approach_pose": {"x_m": 5.5, "y_m": 2.0, "yaw_rad": -1.5708}, "target": [5.5, 2.0],
    "properties": {"door_height_m": 4.2}, "stage": "operator", "revision_id": 51}


class NamedPlaceOut(BaseModel):
    kind: str = Field(description="dock, gate or charger.")
    key: str
    name: str | None
    geometry: dict[str, Any] = Field(description="GeoJSON geometry in map-frame metres.")
    approach_pose: PlacePose | None
    target: tuple[float, float] = Field(description="Where routes to the place end (x, y), metres, map frame: the "
                                                    "approach pose, else the middle of the geometry.")
    properties: dict[str, Any]
    stage: str = Field(description="Who wrote it: `operator` for places set through this API.")
    revision_id: int = Field(description="Revision that wrote this version of the place.")

    model_config = example_config(**_PLACE_EXAMPLE)


class NamedPlaceList(BaseModel):
    places: list[NamedPlaceOut]
    revision: int | None = Field(description="The revision read at, or null for the live map.")

    model_config = example_config(places=[_PLACE_EXAMPLE], revision=None)


class NamedPlaceDeleted(BaseModel):
    kind: str
    key: str
    revision_id: int = Field(description="The operator revision that removed it.")

    model_config = example_config(kind="dock", key="G1", revision_id=52)


KindPath = Annotated[PlaceKind, Path(description="dock, gate or charger.", examples=["dock"])]
KeyPath = Annotated[str, Path(pattern=KEY_PATTERN, description="The place's key, e.g. `G1`.", examples=["G1"])]


def _out(stored: StoredFeature) -> NamedPlaceOut:
    feature = stored.feature
    props = dict(feature.properties)
    pose = props.pop("approach_pose", None)
    name = props.pop("name", None)
    x, y, _ = place_pose(feature)
    approach = None
    if (isinstance(pose, list) and len(pose) == 3
            and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in pose)
            and max(abs(pose[0]), abs(pose[1])) <= MAX_COORDINATE_M):
        yaw = math.atan2(math.sin(pose[2]), math.cos(pose[2]))
        approach = PlacePose(x_m=pose[0], y_m=pose[1], yaw_rad=yaw)
    return NamedPlaceOut(kind=feature.kind, key=feature.key, name=name if isinstance(name, str) else None,
                         geometry=dict(feature.geometry), approach_pose=approach, target=(x, y), properties=props,
                         stage=stored.stage, revision_id=stored.revision_id)


def _unprocessable(detail: str) -> HTTPException:
    return HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, detail)


def _self_intersects(ring: npt.NDArray[np.float64]) -> bool:
    """Whether two non-neighbouring edges of a closed ring cross (vectorised over every pair)."""
    p, q = ring[:-1], ring[1:]
    n = len(p)

    def side(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], c: npt.NDArray[np.float64]
             ) -> npt.NDArray[np.float64]:
        return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                       - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))

    pi, qi, pj, qj = p[:, None], q[:, None], p[None, :], q[None, :]
    crosses = ((side(pi, qi, pj) * side(pi, qi, qj) < 0) & (side(pj, qj, pi) * side(pj, qj, qi) < 0))
    i, j = np.triu_indices(n, k=2)
    neighbours = (i == 0) & (j == n - 1)
    return bool(crosses[i[~neighbours], j[~neighbours]].any())


def _check_geometry(body: NamedPlaceIn) -> dict[str, Any]:
    if isinstance(body.geometry, PointIn):
        return {"type": "Point", "coordinates": list(body.geometry.coordinates)}
    ring = np.asarray(body.geometry.coordinates[0], dtype=float)
    if not np.array_equal(ring[0], ring[-1]):
        raise _unprocessable("the polygon's ring must be closed: repeat its first point as the last")
    if _self_intersects(ring):
        raise _unprocessable("the polygon's ring crosses itself")
    x, y = ring[:, 0], ring[:, 1]
    area = abs(float((x[:-1] * y[1:] - x[1:] * y[:-1]).sum())) / 2.0
    if area < MIN_AREA_M2:
        raise _unprocessable(f"the polygon has no area ({area:.2g} m²); coordinates are map metres")
    if max(np.ptp(x), np.ptp(y)) > MAX_PLACE_SIDE_M:
        raise _unprocessable(f"the polygon is more than {MAX_PLACE_SIDE_M:g} m across; a place is a few metres "
                             "across and coordinates are map metres")
    return {"type": "Polygon", "coordinates": [ring.tolist()]}


def _place_feature(kind: str, key: str, body: NamedPlaceIn) -> Feature:
    geometry = _check_geometry(body)
    reserved = sorted(RESERVED_PROPERTIES & body.properties.keys())
    if reserved:
        raise _unprocessable(f"properties {reserved} are reserved; give name and approach_pose as fields of "
                             "their own")
    props: dict[str, Any] = dict(body.properties)
    if body.name is not None:
        props["name"] = body.name
    if body.approach_pose is not None:
        pose = body.approach_pose
        centre = geometry_centre(geometry)
        far = math.dist(centre, (pose.x_m, pose.y_m))
        if far > MAX_APPROACH_M:
            raise _unprocessable(f"the approach pose is {far:.1f} m from the place; it must be within "
                                 f"{MAX_APPROACH_M:g} m")
        yaw = math.atan2(math.sin(pose.yaw_rad), math.cos(pose.yaw_rad))
        props["approach_pose"] = [pose.x_m, pose.y_m, yaw]
    return Feature(kind, key, geometry, props)


def _operator_places(store: MapStore, map_id: int, kind: str) -> list[Feature]:
    return [s.feature for s in store.features(map_id, kinds=[kind]) if s.stage == OPERATOR_STAGE]


@router.get("", summary="List named places", responses=_ERRORS)
def list_places(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    kind: Annotated[PlaceKind | None, Query(description="Only places of this kind.", examples=["dock"])] = None,
) -> NamedPlaceList:
    """Docks, gates and chargers of the map (as of ``?revision=``): the ones set here (stage ``operator``) and
    any a stage wrote, sorted by kind and key."""
    found = store.features(map_info.id, kinds=[kind] if kind else list(PLACE_KINDS), revision=revision)
    places = sorted((_out(s) for s in found), key=lambda p: (p.kind, p.key, p.stage))
    return NamedPlaceList(places=places, revision=revision)


@router.get("/{kind}/{key}", summary="One named place", responses=_ERRORS)
def get_place(map_info: MapDep, store: StoreDep, revision: RevisionQuery, kind: KindPath, key: KeyPath
              ) -> NamedPlaceOut:
    """A dock, gate or charger by key (as of ``?revision=``; the newest if several stages have it)."""
    found = store.feature(map_info.id, kind, key, revision=revision)
    if found is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"map {map_info.name!r} has no {kind} {key!r}")
    return _out(found)


@router.put("/{kind}/{key}", summary="Set a named place", responses={
    **_ERRORS, status.HTTP_201_CREATED: {"model": NamedPlaceOut, "description": "Created (it did not exist)."}})
def put_place(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
              response: Response, kind: KindPath, key: KeyPath,
              body: NamedPlaceIn) -> NamedPlaceOut:
    """Create or replace a dock, gate or charger, stored as an ``operator`` revision; 201 when new, 200 when
    replaced. Routes reach it as ``<kind>:<key>``. Needs a write key."""
    feature = _place_feature(kind, key, body)
    with OPERATOR_LOCK:
        existing = _operator_places(store, map_info.id, kind)
        current = [f for f in existing if f.key != key]
        existed = len(current) < len(existing)
        revision = store.write_revision(map_info.id, RevisionWrite(
            OPERATOR_STAGE, features={kind: [*current, feature]}, summary={"operator": f"set {kind} {key}"}))
    announcer.announce(map_info, revision)
    response.status_code = status.HTTP_200_OK if existed else status.HTTP_201_CREATED
    return _out(StoredFeature(0, revision.id, OPERATOR_STAGE, feature))


@router.delete("/{kind}/{key}", summary="Remove a named place", responses=_ERRORS)
def delete_place(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                 kind: KindPath, key: KeyPath
                 ) -> NamedPlaceDeleted:
    """Remove a place set through this API (stage ``operator``); 404 when there is none. Needs a write key."""
    with OPERATOR_LOCK:
        current = _operator_places(store, map_info.id, kind)
        if all(f.key != key for f in current):
            other = store.feature(map_info.id, kind, key)
            why = (f"; {kind} {key!r} was written by stage {other.stage!r}, and only places set through this API "
                   "can be removed" if other is not None else "")
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"no {kind} {key!r} was set through this API{why}")
        revision = store.write_revision(map_info.id, RevisionWrite(
            OPERATOR_STAGE, features={kind: [f for f in current if f.key != key]},
            summary={"operator": f"removed {kind} {key}"}))
    announcer.announce(map_info, revision)
    return NamedPlaceDeleted(kind=kind, key=key, revision_id=revision.id)
