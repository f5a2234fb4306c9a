"""The map domain: typed queries over the map store that the REST API, the CLI and the benchmarks share.

Bins as a WMS wants them (:mod:`atlas.bins`, matched to the WMS's own list by :mod:`atlas.reconcile`), features
and the live state answered from memory (:mod:`atlas.features`, :mod:`atlas.live`), grid look-ups
(:mod:`atlas.grids`), what is at a point and the place label table (:mod:`atlas.semantics`), the whole layout
(:mod:`atlas.layout`), topology, blocks and routes (:mod:`atlas.navigation`), pictures (:mod:`atlas.render`)
and exports (:mod:`atlas.exports`). Nothing here speaks HTTP: queries raise the errors of
:mod:`atlas.errors` (and of navigation, rendering and exports), which the API translates.
"""

from atlas.bins import BinAnswer, BinIndex, BinNotFoundError, BinStatus, bin_index, select_bins, stored_bin
from atlas.cache import RevisionCache
from atlas.errors import AtlasConfigError, AtlasError, ConflictError, InvalidQueryError, NotInMapError, TooLargeError
from atlas.layout import LayoutCollection, layout_collection, layout_picture
from atlas.live import LiveMap, LiveMaps
from atlas.reconcile import WmsMatching, reconcile, wms_matching
from atlas.semantics import label_table, semantics_at

__all__ = [
    "AtlasConfigError",
    "AtlasError",
    "BinAnswer",
    "BinIndex",
    "BinNotFoundError",
    "BinStatus",
    "ConflictError",
    "InvalidQueryError",
    "LayoutCollection",
    "LiveMap",
    "LiveMaps",
    "NotInMapError",
    "RevisionCache",
    "TooLargeError",
    "WmsMatching",
    "bin_index",
    "label_table",
    "layout_collection",
    "layout_picture",
    "reconcile",
    "select_bins",
    "semantics_at",
    "stored_bin",
    "wms_matching",
]
