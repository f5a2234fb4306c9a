"""Bin answers in WMS form (:class:`api.models.BinOut`) from the map's typed ones, and the live ones encoded once
per version of a bin, for the bins route and the fast path alike; and :class:`MetricJSONResponse`, how every JSON
answer is encoded (numbers rounded as :mod:`atlas.precision` says)."""

from __future__ import annotations

import datetime as dt
from typing import Any

from fastapi.responses import JSONResponse

from api.models import (
    UNKNOWN_OCCUPANCY,
    AccessPose,
    BinOut,
    OccupancyOut,
    Opening,
    PlaceRef,
    SceneEdgeOut,
    SceneNodeOut,
)
from api.translate import http_error
from atlas.bins import BinAnswer, no_bin
from atlas.bins import PlaceRef as MapPlaceRef
from atlas.live import LiveMap
from atlas.precision import json_bytes
from shared.loads import BinOccupancy, SceneEdge, SceneNode
from shared.store import MapInfo


class MetricJSONResponse(JSONResponse):
    """JSON with metres to the millimetre and angles to 0.1 mrad (:func:`atlas.precision.json_bytes`): the app's
    default response class, so every route's JSON answer is rounded the same way."""

    def render(self, content: Any) -> bytes:
        return json_bytes(content)


def _place(ref: MapPlaceRef | None) -> PlaceRef | None:
    return None if ref is None else PlaceRef(key=ref.key, label=ref.label, distance_m=ref.distance_m)


def bin_out(answer: BinAnswer) -> BinOut:
    """A bin answer in WMS form; what the bin lacks comes out null."""
    record = answer.bin
    opening, pose = record.opening, record.access_pose
    return BinOut(
        id=answer.id,
        detected_id=record.id,
        wms_id=answer.wms_id,
        status=answer.status.value,
        aisle=record.aisle,
        bay=record.bay,
        level=record.level,
        centre=record.centre,
        footprint=None if record.footprint is None else list(record.footprint),
        opening=None if opening is None else Opening(left=opening.left, right=opening.right, width_m=opening.width_m),
        access_pose=None if pose is None else AccessPose(x_m=pose.x_m, y_m=pose.y_m, yaw_rad=pose.yaw_rad),
        row=record.row,
        back_row=record.back_row,
        corridor=_place(answer.corridor),
        region=_place(answer.region),
        storage_region=_place(answer.storage_region),
        nearest_junction=_place(answer.nearest_junction),
        confidence=record.confidence,
        stage=answer.stage,
        revision_id=answer.revision_id,
        occupancy=(UNKNOWN_OCCUPANCY if answer.occupancy is None
                   else occupancy_out(answer.occupancy, answer.occupancy_revision_id)),
    )


def stamp(ns: int | None) -> dt.datetime | None:
    """A stamp in nanoseconds since the epoch as a UTC time (None stays None)."""
    return None if ns is None else dt.datetime.fromtimestamp(ns / 1e9, tz=dt.UTC)


def occupancy_out(occupancy: BinOccupancy, revision_id: int | None) -> OccupancyOut:
    """A stored bin state in WMS form."""
    return OccupancyOut(state=occupancy.state.value, confidence=occupancy.confidence,
                        last_seen=stamp(occupancy.last_seen_ns), views=occupancy.views, objects=list(occupancy.objects),
                        stable=occupancy.stable, hidden=occupancy.hidden, bay=occupancy.bay, revision_id=revision_id)


def node_out(node: SceneNode) -> SceneNodeOut:
    return SceneNodeOut(id=node.id, kind=node.kind.value, centre=node.centre, size=node.size, yaw_rad=node.yaw_rad,
                        level=node.level, flags=sorted(flag.value for flag in node.flags), probability=node.probability)


def edge_out(edge: SceneEdge) -> SceneEdgeOut:
    return SceneEdgeOut(source=edge.source, target=edge.target, relation=edge.relation.value,
                        probability=edge.probability)


def live_bin(live: LiveMap, map_info: MapInfo, bin_id: str) -> bytes:
    """Bin ``bin_id`` of the live map as JSON (404 if there is none), made once per version of the bin and of
    what it reads besides."""
    row = live.bin_row(bin_id)
    if row is None:
        raise http_error(no_bin(map_info, bin_id, None))
    state = live.state_row(row)
    rows = (row.id, 0 if state is None else state.id)
    body = live.bin_json.get(rows)
    if body is None:
        body = live.bin_json[rows] = json_bytes(bin_out(live.bin_answer(row, state)).model_dump(mode="json"))
    return body
