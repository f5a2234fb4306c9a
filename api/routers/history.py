"""What changed in the map between two revisions."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, HTTPException, Path, Query, status
from pydantic import BaseModel, Field

from api.deps import MapDep, StoreDep, find_revision
from api.models import COMMON_ERRORS, ErrorOut, Responses
from shared.store import MapInfo, MapStore

router = APIRouter(prefix="/v1/maps/{map_name}/revisions", tags=["maps"], responses=COMMON_ERRORS)

MAX_KEYS = 1000
"""Keys listed per kind and change type; counts are always complete."""

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map or revision."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad revision ids."},
}


class KindDiff(BaseModel):
    added: list[str] = Field(description="Keys live at `to` but not at `from`.")
    removed: list[str] = Field(description="Keys live at `from` but not at `to`.")
    moved: list[str] = Field(description="Keys whose geometry changed.")
    changed: list[str] = Field(description="Keys whose properties or confidence changed but not their geometry.")
    counts: dict[str, int] = Field(description="Complete sizes of the four lists (the lists stop at 1000 keys).")


class LayerDiff(BaseModel):
    name: str
    from_revision_id: int | None = Field(description="Revision that wrote the layer version live at `from`.")
    to_revision_id: int | None = Field(description="Revision that wrote the layer version live at `to`.")


class RevisionDiff(BaseModel):
    from_revision: int = Field(description="Revision id compared from.")
    to_revision: int = Field(description="Revision id compared to.")
    features: dict[str, KindDiff] = Field(description="Per feature kind that changed.")
    layers: list[LayerDiff] = Field(description="Layers whose version differs.")
    topology: dict[str, int] = Field(description="Region-graph nodes and edges added and removed.")

    model_config = {"json_schema_extra": {"examples": [{
        "from_revision": 120, "to_revision": 131,
        "features": {"bin": {"added": ["04-011"], "removed": [], "moved": ["04-010"], "changed": [],
                             "counts": {"added": 1, "removed": 0, "moved": 1, "changed": 0}}},
        "layers": [{"name": "occupancy", "from_revision_id": 118, "to_revision_id": 130}],
        "topology": {"nodes_added": 0, "nodes_removed": 0, "edges_added": 1, "edges_removed": 0}}]}}


def _snapshot(store: MapStore, map_info: MapInfo, revision: int) -> dict[tuple[str, str, str], tuple[Any, Any]]:
    return {(f.feature.kind, f.stage, f.feature.key): (f.feature.geometry, (f.feature.properties, f.feature.confidence))
            for f in store.features(map_info.id, revision=revision)}


def _kind_diffs(before: dict[tuple[str, str, str], tuple[Any, Any]],
                after: dict[tuple[str, str, str], tuple[Any, Any]]) -> dict[str, KindDiff]:
    changes: dict[str, dict[str, list[str]]] = {}

    def note(kind: str, what: str, key: str) -> None:
        changes.setdefault(kind, {"added": [], "removed": [], "moved": [], "changed": []})[what].append(key)

    for ident in after.keys() - before.keys():
        note(ident[0], "added", ident[2])
    for ident in before.keys() - after.keys():
        note(ident[0], "removed", ident[2])
    for ident in before.keys() & after.keys():
        if before[ident][0] != after[ident][0]:
            note(ident[0], "moved", ident[2])
        elif before[ident][1] != after[ident][1]:
            note(ident[0], "changed", ident[2])
    return {kind: KindDiff(**{what: sorted(keys)[:MAX_KEYS] for what, keys in lists.items()},
                           counts={what: len(keys) for what, keys in lists.items()})
            for kind, lists in sorted(changes.items())}


def _topology_diff(store: MapStore, map_info: MapInfo, a: int, b: int) -> dict[str, int]:
    nodes_a, edges_a = store.topology(map_info.id, revision=a)
    nodes_b, edges_b = store.topology(map_info.id, revision=b)
    na, nb = {n.key for n in nodes_a}, {n.key for n in nodes_b}
    ea = {(e.source, e.target, str(sorted(e.attributes.items()))) for e in edges_a}
    eb = {(e.source, e.target, str(sorted(e.attributes.items()))) for e in edges_b}
    return {"nodes_added": len(nb - na), "nodes_removed": len(na - nb), "edges_added": len(eb - ea),
            "edges_removed": len(ea - eb)}


@router.get("/{from_id}/diff", summary="Diff two revisions", responses=_ERRORS)
def diff_revisions(
    map_info: MapDep,
    store: StoreDep,
    from_id: Annotated[int, Path(ge=1, le=2**31 - 1, description="The earlier revision.", examples=[120])],
    to: Annotated[int | None, Query(ge=1, le=2**31 - 1, description="The later revision (default: the newest).",
                                    examples=[131])] = None,
) -> RevisionDiff:
    """Features added, removed, moved and changed per kind, layers updated and region-graph changes between
    revision ``from_id`` and ``to`` (the map as it was at each; ``to`` may also be the earlier one)."""
    latest = store.latest_revision(map_info.id)
    target = to if to is not None else (latest.id if latest is not None else None)
    for ident in (from_id, target):
        if ident is None or find_revision(store, map_info, ident) is None:
            raise HTTPException(status.HTTP_404_NOT_FOUND,
                                f"revision {ident} is not a revision of map {map_info.name!r}; list them at "
                                f"/v1/maps/{map_info.name}/revisions")
    assert target is not None
    layers = []
    for name in store.layer_names(map_info.id):
        a = store.layer_revision(map_info.id, name, revision=from_id)
        b = store.layer_revision(map_info.id, name, revision=target)
        if a != b:
            layers.append(LayerDiff(name=name, from_revision_id=a, to_revision_id=b))
    return RevisionDiff(
        from_revision=from_id,
        to_revision=target,
        features=_kind_diffs(_snapshot(store, map_info, from_id), _snapshot(store, map_info, target)),
        layers=layers,
        topology=_topology_diff(store, map_info, from_id, target),
    )
