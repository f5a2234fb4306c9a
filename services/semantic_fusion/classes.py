"""The semantic classes of the map (:class:`shared.vocabulary.SemanticClass`), their order in the grid and colours.

``SemanticClass`` values are the uint8 codes of the label layer. ``NONE`` (0) marks cells with no
evidence (free or never seen) and is not part of the per-cell distribution; every other class is,
in value order, so distribution column ``k`` is class ``k + 1``.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from services.semantic_fusion.errors import SemanticFusionError
from shared.vocabulary import SemanticClass

DISTRIBUTION_CLASSES: Final = tuple(c for c in SemanticClass if c is not SemanticClass.NONE)
"""Classes of the per-cell distribution, column ``k`` being ``DISTRIBUTION_CLASSES[k]``."""

N_CLASSES: Final = len(DISTRIBUTION_CLASSES)

DYNAMIC_CLASSES: Final = frozenset({SemanticClass.FORKLIFT, SemanticClass.HUMAN})
"""Classes whose evidence decays over time instead of accumulating."""

CLASS_COLOURS: Final[dict[SemanticClass, tuple[int, int, int]]] = {
    SemanticClass.NONE: (255, 255, 255),
    SemanticClass.UNKNOWN: (150, 150, 150),
    SemanticClass.WALL: (40, 40, 40),
    SemanticClass.RACK: (31, 119, 180),
    SemanticClass.PALLET: (214, 140, 40),
    SemanticClass.GATE: (44, 160, 44),
    SemanticClass.FORKLIFT: (214, 39, 40),
    SemanticClass.HUMAN: (148, 103, 189),
}

_ALIASES: Final = {"upright": SemanticClass.RACK, "rack_upright": SemanticClass.RACK, "door": SemanticClass.GATE,
                   "person": SemanticClass.HUMAN, "background": SemanticClass.UNKNOWN}


def column_of(semantic_class: SemanticClass) -> int:
    """Distribution column of ``semantic_class``; raises for ``NONE``, which has none."""
    if semantic_class is SemanticClass.NONE:
        raise SemanticFusionError("class NONE is not part of the per-cell distribution")
    return int(semantic_class) - 1


def dynamic_columns() -> npt.NDArray[np.intp]:
    """Distribution columns of the dynamic classes, sorted."""
    return np.array(sorted(column_of(c) for c in DYNAMIC_CLASSES), dtype=np.intp)


def class_columns(class_names: list[str] | tuple[str, ...]) -> npt.NDArray[np.intp]:
    """Distribution column of each name in an AnnotatedScan's ``class_names``.

    Names match :class:`SemanticClass` members case-insensitively (plus a few aliases such as
    ``person`` and ``upright``); any other name, e.g. a class the labeller knows and the map does
    not, maps to ``UNKNOWN``. Raises :class:`SemanticFusionError` for ``none`` (the map's code
    for "no evidence" cannot be an observation) or an empty name.

    Examples
    --------
    >>> class_columns(["wall", "Person", "crate"]).tolist()
    [1, 6, 0]
    """
    out = np.empty(len(class_names), dtype=np.intp)
    for i, raw in enumerate(class_names):
        name = raw.strip().lower()
        if not name or name == "none":
            raise SemanticFusionError(f"class_names[{i}] = {raw!r} cannot label an observation")
        member = SemanticClass.__members__.get(name.upper(), _ALIASES.get(name, SemanticClass.UNKNOWN))
        out[i] = column_of(member)
    return out
