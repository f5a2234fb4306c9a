"""What stands in the racks: bin occupancy and bay scene graphs, and how they are stored as map features.

The load-scene stage (``services/load_scenes``) infers, per rack bay, a scene graph (objects, which supports
which, which estimate is false, which object is hidden) and per bin an occupancy (empty, occupied, unknown). The
types live here, beside the :class:`~shared.bins.Bin` record, so the store, ``atlas`` and the API read them without
importing the stage; the stage re-exports them from ``services.load_scenes.model``.

Each bin's occupancy is a ``bin_state`` feature keyed by the bin's id (a point at the bin's centre), each bay's
scene a ``load_scene`` feature keyed by the bay (a point in the middle of its bins); both are versioned by revision
like every feature. :func:`occupancy_feature` / :func:`occupancy_from_feature` and :func:`scene_feature` /
:func:`scene_from_feature` turn records into features and back; :func:`write_scene_revision` writes what changed
as one revision.

Examples
--------
>>> record = BinOccupancy("03-014-02", Occupancy.OCCUPIED, 0.97, 1_700_000_000_000_000_000, ("p1", "l1"), views=3)
>>> occupancy_from_feature(occupancy_feature(record, at=(41.2, 17.6))) == record
True
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, NamedTuple

from shared.bins import Bin
from shared.store import Feature, MapStore, Revision, RevisionWrite, StoreError
from shared.vocabulary import FeatureKind

XY = tuple[float, float]
"""(x, y) in map-frame metres."""
XYZ = tuple[float, float, float]
"""(x, y, z) in map-frame metres."""

LOADS_STAGE: Final = "load_scenes"
"""The stage that writes ``bin_state`` and ``load_scene`` features."""
CHANGED_LISTED: Final = 1000
"""Most bin ids a revision's summary lists under ``occupancy_changed`` (the count is always there)."""


class ObjectKind(enum.StrEnum):
    """What a box in a rack bay is."""

    PALLET = "pallet"
    LOAD = "load"
    """Cartons, boxes or goods standing on a pallet."""
    BEAM = "beam"
    """A rack beam pair of one level (the support a pallet rests on); level 0 has the floor instead."""


class Occupancy(enum.StrEnum):
    """A bin's state as the robots saw it."""

    EMPTY = "empty"
    OCCUPIED = "occupied"
    UNKNOWN = "unknown"
    """Not seen well enough (never in view, or the evidence does not decide)."""


class Relation(enum.StrEnum):
    """Edges of a bay's scene graph (seed 003 table 4.3, adapted to racks)."""

    SUPPORTS = "supports"
    """The source stably holds the target up (beam -> pallet, pallet -> load, load -> load)."""
    UNSTABLE_CONTACT = "unstable_contact"
    """The two touch but neither stably holds the other (a leaning or overhanging load)."""


class Flag(enum.StrEnum):
    """Node flags of a scene graph."""

    FALSE_ESTIMATE = "false_estimate"
    """A detected box the evidence and context reject (a ghost)."""
    HIDDEN_BELOW = "hidden_below"
    """A box nobody detected, added because something else would hover (or a second-deep pallet seen behind
    a gap)."""


@dataclass(frozen=True, slots=True)
class SceneNode:
    """One object of a bay's scene graph (a box estimate, possibly corrected, or an added hidden object)."""

    id: str
    kind: ObjectKind
    centre: XYZ
    size: XYZ
    yaw_rad: float
    level: int | None
    flags: frozenset[Flag] = frozenset()
    probability: float = 1.0
    """Posterior probability that the object is there as described."""


@dataclass(frozen=True, slots=True)
class SceneEdge:
    source: str
    target: str
    relation: Relation
    probability: float = 1.0


@dataclass(frozen=True, slots=True)
class SceneGraph:
    """What stands in one bay and what holds what."""

    bay: str
    nodes: tuple[SceneNode, ...]
    edges: tuple[SceneEdge, ...]
    stamp_ns: int
    iterations: int = 0
    """MCMC iterations the inference ran."""


@dataclass(frozen=True, slots=True)
class BinOccupancy:
    """One bin's state: empty, occupied by which objects, or unknown; how sure, and when last seen."""

    bin_id: str
    state: Occupancy
    confidence: float
    """Probability of ``state`` in [0, 1]."""
    last_seen_ns: int | None
    objects: tuple[str, ...] = ()
    """Ids of the scene nodes in the bin (pallet first)."""
    views: int = 0
    """How many separate views of the bin the state rests on."""
    stable: bool | None = None
    """False when a load in the bin has an unstable contact; None when empty or unknown."""
    hidden: bool = False
    """True when an object in the bin was inferred, not seen (e.g. a second-deep pallet)."""
    bay: str | None = None
    detail: dict[str, object] = field(default_factory=dict)


class LoadRecordError(ValueError):
    """An occupancy or scene record that cannot be stored (non-finite numbers, probabilities outside [0, 1],
    edges to unknown nodes), or a feature that is not one."""


# -- records <-> features ------------------------------------------------------------------------------------------
def occupancy_feature(record: BinOccupancy, *, at: XY) -> Feature:
    """The ``bin_state`` feature of ``record``: a point at ``at`` (the bin's centre, metres) keyed by the bin id.

    Raises
    ------
    LoadRecordError
        An empty id, a confidence outside [0, 1], negative views, or a detail that is not finite JSON.
    """
    where = f"bin {record.bin_id!r}"
    if not record.bin_id or len(record.bin_id) > 128:
        raise LoadRecordError(f"{where}: a bin id must be 1 to 128 characters")
    _probability(record.confidence, f"{where}: confidence")
    if record.views < 0:
        raise LoadRecordError(f"{where}: views must be >= 0, not {record.views}")
    properties = {
        "kind": FeatureKind.BIN_STATE.value,
        "bin_id": record.bin_id,
        "state": Occupancy(record.state).value,
        "last_seen_ns": record.last_seen_ns,
        "objects": [str(item) for item in record.objects],
        "views": int(record.views),
        "stable": record.stable,
        "hidden": bool(record.hidden),
        "bay": record.bay,
        "detail": _finite_json(record.detail, f"{where}: detail"),
    }
    return _feature(FeatureKind.BIN_STATE, record.bin_id, at, properties, float(record.confidence), where)


def occupancy_from_feature(feature: Feature) -> BinOccupancy:
    """The occupancy a stored ``bin_state`` feature holds; a state it does not know reads as ``unknown``.

    Raises
    ------
    LoadRecordError
        The feature is not of kind ``bin_state``.
    """
    if feature.kind != FeatureKind.BIN_STATE:
        raise LoadRecordError(f"feature {feature.kind}/{feature.key} is not a bin state")
    p = feature.properties
    state = p.get("state")
    confidence = feature.confidence
    detail = p.get("detail")
    objects = p.get("objects")
    return BinOccupancy(
        bin_id=_str(p.get("bin_id")) or feature.key,
        state=Occupancy(state) if state in tuple(Occupancy) else Occupancy.UNKNOWN,
        confidence=float(confidence) if confidence is not None else 0.0,
        last_seen_ns=_int(p.get("last_seen_ns")),
        objects=tuple(str(item) for item in objects) if isinstance(objects, list) else (),
        views=_int(p.get("views")) or 0,
        stable=stable if isinstance(stable := p.get("stable"), bool) else None,
        hidden=p.get("hidden") is True,
        bay=_str(p.get("bay")),
        detail=dict(detail) if isinstance(detail, Mapping) else {},
    )


def scene_feature(graph: SceneGraph, *, at: XY) -> Feature:
    """The ``load_scene`` feature of ``graph``: a point at ``at`` (the middle of the bay, metres) keyed by the bay.

    Raises
    ------
    LoadRecordError
        An empty bay key, repeated node ids, non-finite numbers, probabilities outside [0, 1] or an edge naming a
        node the graph lacks.
    """
    where = f"scene of bay {graph.bay!r}"
    if not graph.bay or len(graph.bay) > 128:
        raise LoadRecordError(f"{where}: a bay key must be 1 to 128 characters")
    ids = [node.id for node in graph.nodes]
    if len(set(ids)) != len(ids):
        raise LoadRecordError(f"{where}: node ids must be unique")
    nodes = []
    for node in graph.nodes:
        at_node = f"{where}, node {node.id!r}"
        numbers = (*node.centre, *node.size, node.yaw_rad)
        if len(node.centre) != 3 or len(node.size) != 3 or not all(math.isfinite(v) for v in numbers):
            raise LoadRecordError(f"{at_node}: centre, size and yaw must be finite (x, y, z) and radians")
        if min(node.size) <= 0:
            raise LoadRecordError(f"{at_node}: size must be positive, not {node.size}")
        nodes.append({"id": node.id, "kind": ObjectKind(node.kind).value, "centre": [float(v) for v in node.centre],
                      "size": [float(v) for v in node.size], "yaw_rad": float(node.yaw_rad), "level": node.level,
                      "flags": sorted(Flag(flag).value for flag in node.flags),
                      "probability": _probability(node.probability, f"{at_node}: probability")})
    known = set(ids)
    edges = []
    for edge in graph.edges:
        if edge.source not in known or edge.target not in known:
            raise LoadRecordError(f"{where}: edge {edge.source!r} -> {edge.target!r} names a node it lacks")
        edges.append({"source": edge.source, "target": edge.target, "relation": Relation(edge.relation).value,
                      "probability": _probability(edge.probability, f"{where}: edge probability")})
    properties = {"kind": FeatureKind.LOAD_SCENE.value, "bay": graph.bay, "stamp_ns": int(graph.stamp_ns),
                  "iterations": int(graph.iterations), "nodes": nodes, "edges": edges}
    return _feature(FeatureKind.LOAD_SCENE, graph.bay, at, properties, None, where)


def scene_from_feature(feature: Feature) -> SceneGraph:
    """The scene graph a stored ``load_scene`` feature holds; nodes and edges it cannot read are left out.

    Raises
    ------
    LoadRecordError
        The feature is not of kind ``load_scene``.
    """
    if feature.kind != FeatureKind.LOAD_SCENE:
        raise LoadRecordError(f"feature {feature.kind}/{feature.key} is not a load scene")
    p = feature.properties
    nodes = tuple(node for item in _list(p.get("nodes")) if (node := _node(item)) is not None)
    edges = tuple(edge for item in _list(p.get("edges")) if (edge := _edge(item)) is not None)
    return SceneGraph(bay=_str(p.get("bay")) or feature.key, nodes=nodes, edges=edges,
                      stamp_ns=_int(p.get("stamp_ns")) or 0, iterations=_int(p.get("iterations")) or 0)


def _feature(kind: FeatureKind, key: str, at: XY, properties: dict[str, Any], confidence: float | None,
             where: str) -> Feature:
    try:
        return Feature(kind.value, key, {"type": "Point", "coordinates": [float(at[0]), float(at[1])]}, properties,
                       confidence)
    except StoreError as err:
        raise LoadRecordError(f"{where}: {err}") from err


def _probability(value: float, what: str) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and 0.0 <= value <= 1.0):
        raise LoadRecordError(f"{what} must be a probability in [0, 1], not {value!r}")
    return float(value)


def _finite_json(value: Mapping[str, object], what: str) -> dict[str, Any]:
    try:
        return dict(json.loads(json.dumps(dict(value), allow_nan=False)))
    except (TypeError, ValueError) as err:
        raise LoadRecordError(f"{what} must be JSON with finite numbers: {err}") from err


def _node(item: Any) -> SceneNode | None:
    if not isinstance(item, Mapping):
        return None
    centre, size, kind = _xyz(item.get("centre")), _xyz(item.get("size")), item.get("kind")
    node_id, yaw = _str(item.get("id")), _float(item.get("yaw_rad"))
    if centre is None or size is None or node_id is None or yaw is None or kind not in tuple(ObjectKind):
        return None
    flags = frozenset(Flag(flag) for flag in _list(item.get("flags")) if flag in tuple(Flag))
    probability = _float(item.get("probability"))
    return SceneNode(node_id, ObjectKind(kind), centre, size, yaw, _int(item.get("level")), flags,
                     1.0 if probability is None else probability)


def _edge(item: Any) -> SceneEdge | None:
    if not isinstance(item, Mapping):
        return None
    source, target, relation = _str(item.get("source")), _str(item.get("target")), item.get("relation")
    if source is None or target is None or relation not in tuple(Relation):
        return None
    probability = _float(item.get("probability"))
    return SceneEdge(source, target, Relation(relation), 1.0 if probability is None else probability)


def _int(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _float(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def _str(value: Any) -> str | None:
    return value if isinstance(value, str) else None


def _list(value: Any) -> list[Any]:
    return value if isinstance(value, list) else []


def _xyz(value: Any) -> XYZ | None:
    if isinstance(value, list) and len(value) == 3 and all(_float(v) is not None for v in value):
        return float(value[0]), float(value[1]), float(value[2])
    return None


# -- the writer ----------------------------------------------------------------------------------------------------
class Skipped(NamedTuple):
    """A record the writer left out, and why."""

    kind: str
    """``bin_state`` or ``load_scene``."""
    key: str
    """The bin id or bay key."""
    reason: str


@dataclass(frozen=True, slots=True)
class SceneWrite:
    """What :func:`write_scene_revision` did."""

    revision: Revision | None
    """The revision written; None when nothing changed (or ``commit`` stored nothing)."""
    bins_written: tuple[str, ...]
    """Bins whose stored state record is new or different (any field: state, confidence, last seen, ...)."""
    bins_changed: tuple[str, ...]
    """Of them, bins whose state (empty, occupied, unknown) changed: the occupancy changes the revision announces."""
    scenes_written: tuple[str, ...]
    """Bays whose stored scene is new or different."""
    skipped: tuple[Skipped, ...]
    """Records left out (bad values, a bin the map lacks, a bay with no position), each with its reason."""


class SceneWriter:
    """Stores a stage's bin states and bay scenes revision by revision, writing only what changed.

    It reads the stage's stored states and scenes and the map's bin centres once (the first write), then keeps what
    it stored in memory and brings the centres up to date from the feature rows the revisions since changed; so a
    write reads from the store only what changed, and writes only the records that changed (a partial revision
    write: the stage's other records stay). A worker holds one for its life; :func:`write_scene_revision` is one
    write with a fresh writer.

    Parameters
    ----------
    store, map_id
        The map store and the map to write to.
    stage : str
        The stage named as the writer; only its own earlier records are merged with (default ``load_scenes``).
    """

    def __init__(self, store: MapStore, map_id: int, *, stage: str = LOADS_STAGE) -> None:
        self.store = store
        self.map_id = map_id
        self.stage = stage
        self._stored: dict[FeatureKind, dict[str, Feature]] | None = None
        self._centres: dict[str, XY] = {}
        self._centres_at: int | None = None  # the revision the bin centres are as of

    def write(self, scenes: Sequence[SceneGraph], occupancies: Sequence[BinOccupancy], *,
              commit: Callable[[RevisionWrite], Revision | None] | None = None, input_start_ns: int | None = None,
              input_end_ns: int | None = None) -> SceneWrite:
        """Store the bin states and bay scenes that changed as ONE revision; the others stay as they are.

        ``occupancies`` and ``scenes`` need only hold what the stage looked at anew: every bin state and scene the
        stage stored before and does not give again stays live (unchanged, the row it was), and one given exactly as
        stored is not written again. A bin state is placed at its bin's centre (the map's ``bin`` feature of that
        id), a scene at the middle of its bay's bins (or of its objects); the states of bins the map no longer has
        (the pillar stage removed them) are retired (``bin_states_retired`` in the summary). Records that cannot be
        stored are left out with a reason (``skipped``) and the rest is written; nothing stored is lost. When nothing
        changed, no revision is written.

        Parameters
        ----------
        scenes : sequence of SceneGraph
            Scene graphs of the bays looked at, one per bay (a later one of a bay wins).
        occupancies : sequence of BinOccupancy
            States of the bins looked at (a later one of a bin wins).
        commit : callable, optional
            Stores a :class:`RevisionWrite` and returns the revision, or None when the store is down; a worker
            passes ``StageContext.commit`` (which counts and announces). Default: ``store.write_revision``.
        input_start_ns, input_end_ns : int, optional
            Stamps of the oldest and newest input the revision rests on.

        Returns
        -------
        SceneWrite
            The revision (or None) and what was written, changed and skipped.

        Raises
        ------
        StoreUnavailableError
            The store could not be read (nothing was written; the writer is as before).
        """
        if self._stored is None:
            self._stored = {kind: _own(self.store, self.map_id, kind, self.stage)
                            for kind in (FeatureKind.BIN_STATE, FeatureKind.LOAD_SCENE)}
        stored_states, stored_scenes = self._stored[FeatureKind.BIN_STATE], self._stored[FeatureKind.LOAD_SCENE]
        skipped: list[Skipped] = []
        centres = self._bin_centres()
        new_states: dict[str, Feature] = {}
        for record in occupancies:
            where = centres.get(record.bin_id)
            if where is None:
                skipped.append(Skipped(FeatureKind.BIN_STATE, record.bin_id, "the map has no bin of this id"))
                continue
            try:
                new_states[record.bin_id] = occupancy_feature(record, at=where)
            except LoadRecordError as err:
                skipped.append(Skipped(FeatureKind.BIN_STATE, record.bin_id, str(err)))
        bay_bins: dict[str, list[XY]] = {}
        for item in {**stored_states, **new_states}.values():
            bay = item.properties.get("bay")
            if isinstance(bay, str):
                bay_bins.setdefault(bay, []).append(_point(item))
        new_scenes: dict[str, Feature] = {}
        for graph in scenes:
            where_xy = _middle(bay_bins.get(graph.bay) or [(node.centre[0], node.centre[1]) for node in graph.nodes])
            if where_xy is None:
                skipped.append(Skipped(FeatureKind.LOAD_SCENE, graph.bay, "no position: the bay has no known bin "
                                                                          "and the scene no object"))
                continue
            try:
                new_scenes[graph.bay] = scene_feature(graph, at=where_xy)
            except LoadRecordError as err:
                skipped.append(Skipped(FeatureKind.LOAD_SCENE, graph.bay, str(err)))

        bins_written = sorted(key for key, item in new_states.items() if not _same(item, stored_states.get(key)))
        scenes_written = sorted(key for key, item in new_scenes.items() if not _same(item, stored_scenes.get(key)))
        bins_changed = [key for key in bins_written
                        if new_states[key].properties["state"] != _state(stored_states.get(key))]
        retired = sorted(key for key in stored_states if key not in centres)  # bins the map no longer has
        if not bins_written and not scenes_written and not retired:
            return SceneWrite(None, (), (), (), tuple(skipped))
        features = {kind.value: [new[key] for key in written] for kind, new, written in
                    ((FeatureKind.BIN_STATE, new_states, bins_written),
                     (FeatureKind.LOAD_SCENE, new_scenes, scenes_written)) if written}
        partial = frozenset(features)
        if retired:  # the states of the bins kept, all of them: the kind's other states are retired
            features[FeatureKind.BIN_STATE.value] = [new_states.get(key, item) for key, item in stored_states.items()
                                                     if key in centres] + [new_states[key] for key in bins_written
                                                                          if key not in stored_states]
            partial -= {FeatureKind.BIN_STATE.value}
        summary = {"bin_states_written": len(bins_written), "scenes_written": len(scenes_written),
                   "occupancy_changed": bins_changed[:CHANGED_LISTED], "occupancy_changed_count": len(bins_changed),
                   "bin_states_retired": len(retired), "skipped": len(skipped)}
        write = RevisionWrite(self.stage, features=features, input_start_ns=input_start_ns,
                              input_end_ns=input_end_ns, summary=summary, partial=partial)
        revision = self.store.write_revision(self.map_id, write) if commit is None else commit(write)
        if revision is None:  # not stored: the next write compares with what the store holds
            return SceneWrite(None, (), (), (), tuple(skipped))
        stored_states.update((key, new_states[key]) for key in bins_written)
        for key in retired:
            del stored_states[key]
        stored_scenes.update((key, new_scenes[key]) for key in scenes_written)
        return SceneWrite(revision, tuple(bins_written), tuple(bins_changed), tuple(scenes_written), tuple(skipped))

    def _bin_centres(self) -> dict[str, XY]:
        """Centres (metres) of the map's bins by id, as of its newest revision: read whole the first time, then
        brought up to date with the feature rows the revisions since changed."""
        latest = self.store.latest_revision(self.map_id)
        upto = 0 if latest is None else latest.id
        if self._centres_at is None:
            self._centres = {item.feature.key: Bin.from_feature(item.feature).centre
                             for item in self.store.features(self.map_id, kinds=[FeatureKind.BIN], revision=upto)}
        elif upto > self._centres_at:
            for row in self.store.feature_rows_changed(self.map_id, after=self._centres_at, upto=upto):
                if row.kind != FeatureKind.BIN:
                    continue
                if row.retired_revision_id is not None and row.retired_revision_id <= upto:
                    self._centres.pop(row.key, None)  # rows come in id order: a key's newer row comes after
                else:
                    feature = Feature(row.kind, row.key, json.loads(row.geometry_json),
                                      json.loads(row.properties_json), row.confidence)
                    self._centres[row.key] = Bin.from_feature(feature).centre
        self._centres_at = upto
        return self._centres


def write_scene_revision(
    store: MapStore,
    map_id: int,
    scenes: Sequence[SceneGraph],
    occupancies: Sequence[BinOccupancy],
    *,
    stage: str = LOADS_STAGE,
    commit: Callable[[RevisionWrite], Revision | None] | None = None,
    input_start_ns: int | None = None,
    input_end_ns: int | None = None,
) -> SceneWrite:
    """Store the bin states and bay scenes that changed as ONE revision (:meth:`SceneWriter.write` with a fresh
    writer, which reads the stage's stored records first; a worker keeps a :class:`SceneWriter` instead).

    Examples
    --------
    A worker, once per batch of views::

        written = writer.write(scenes, occupancies, commit=context.commit, input_start_ns=t0, input_end_ns=t1)
        for item in written.skipped:
            context.count("records_skipped")
    """
    return SceneWriter(store, map_id, stage=stage).write(scenes, occupancies, commit=commit,
                                                         input_start_ns=input_start_ns, input_end_ns=input_end_ns)


def _own(store: MapStore, map_id: int, kind: FeatureKind, stage: str) -> dict[str, Feature]:
    """The live features of ``kind`` ``stage`` wrote, by key."""
    return {item.feature.key: item.feature for item in store.features(map_id, kinds=[kind]) if item.stage == stage}


def _same(item: Feature, stored: Feature | None) -> bool:
    return (stored is not None and dict(stored.geometry) == dict(item.geometry)
            and dict(stored.properties) == dict(item.properties) and stored.confidence == item.confidence)


def _state(stored: Feature | None) -> str:
    """The state a stored bin state says (``unknown`` without one)."""
    return Occupancy.UNKNOWN.value if stored is None else occupancy_from_feature(stored).state.value


def _point(item: Feature) -> XY:
    x, y = item.geometry["coordinates"]
    return float(x), float(y)


def _middle(points: Sequence[XY]) -> XY | None:
    if not points:
        return None
    return (sum(x for x, _ in points) / len(points), sum(y for _, y in points) / len(points))


__all__ = [
    "CHANGED_LISTED",
    "LOADS_STAGE",
    "XY",
    "XYZ",
    "BinOccupancy",
    "Flag",
    "LoadRecordError",
    "ObjectKind",
    "Occupancy",
    "Relation",
    "SceneEdge",
    "SceneGraph",
    "SceneNode",
    "SceneWrite",
    "SceneWriter",
    "Skipped",
    "occupancy_feature",
    "occupancy_from_feature",
    "scene_feature",
    "scene_from_feature",
    "write_scene_revision",
]
