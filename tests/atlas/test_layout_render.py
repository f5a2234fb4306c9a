"""atlas.render.scene and atlas.render.svg: what a layout picture shows, where, and that it looks right."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any

import cv2
import numpy as np
import pytest

from atlas.render.layers import RenderError
from atlas.render.png import render_png
from atlas.render.scene import (
    KIND_STYLES,
    MAX_SIDE_PX,
    NothingToDrawError,
    geometry_shapes,
    layout_scene,
    view_for,
)
from atlas.render.svg import render_svg
from services.grid_decomposition.overview import LABEL_COLOURS
from services.simulator import ground_truth_features, ground_truth_grids, load_world
from shared.store import FEATURE_KINDS, Feature, GridLayer
from shared.vocabulary import PlaceLabel

LABEL_META = {"encoding": "place_labels", "classes": [label.name.lower() for label in PlaceLabel],
              "colours": [list(LABEL_COLOURS[label]) for label in PlaceLabel]}


def _box(min_x: float, min_y: float, max_x: float, max_y: float) -> dict[str, Any]:
    ring = [[min_x, min_y], [max_x, min_y], [max_x, max_y], [min_x, max_y], [min_x, min_y]]
    return {"type": "Polygon", "coordinates": [ring]}


def test_every_feature_kind_has_a_style() -> None:
    assert set(KIND_STYLES) == FEATURE_KINDS


def test_view_keeps_the_aspect_ratio() -> None:
    view = view_for((0.0, 0.0, 100.0, 10.0), width_px=1000)

    assert (view.width_px, view.height_px) == (1000, 100)
    assert view.px_per_m == pytest.approx(10.0)
    np.testing.assert_allclose(view.to_px(np.array([[0.0, 10.0], [100.0, 0.0]])), [[0, 0], [1000, 100]])


def test_view_of_a_tall_area_is_capped_in_height_and_a_tiny_one_widened() -> None:
    tall = view_for((0.0, 0.0, 10.0, 1000.0), width_px=1000)
    tiny = view_for((5.0, 5.0, 5.0, 5.0), width_px=100)

    assert tall.height_px == MAX_SIDE_PX and tall.width_px < 1000
    assert tiny.max_x_m - tiny.min_x_m == pytest.approx(1.0) and tiny.min_x_m == pytest.approx(4.5)
    with pytest.raises(RenderError, match=r"outside 64\.\.4096"):
        view_for((0.0, 0.0, 1.0, 1.0), width_px=5000)


@pytest.mark.parametrize(
    ("geometry", "points", "lines", "polygons"),
    [
        ({"type": "Point", "coordinates": [1, 2]}, 1, 0, 0),
        ({"type": "Point", "coordinates": [1, 2, 3]}, 1, 0, 0),
        ({"type": "MultiPoint", "coordinates": [[1, 2], [3, 4]]}, 1, 0, 0),
        ({"type": "LineString", "coordinates": [[1, 2], [3, 4]]}, 0, 1, 0),
        ({"type": "MultiLineString", "coordinates": [[[1, 2], [3, 4]], [[0, 0], [1, 1]]]}, 0, 2, 0),
        (_box(0, 0, 1, 1), 0, 0, 1),
        ({"type": "MultiPolygon", "coordinates": [_box(0, 0, 1, 1)["coordinates"], []]}, 0, 0, 1),
    ],
)
def test_geometry_shapes_reads_every_geojson_geometry(geometry: dict[str, Any], points: int, lines: int,
                                                      polygons: int) -> None:
    shapes = geometry_shapes(geometry)

    assert shapes is not None
    assert (len(shapes.points), len(shapes.lines), len(shapes.polygons)) == (points, lines, polygons)
    assert all(a.shape[1] == 2 for a in [*shapes.points, *shapes.lines])


@pytest.mark.parametrize("geometry", [
    {"type": "Polygon", "coordinates": [1, 2]},
    {"type": "LineString", "coordinates": [[1, 2], [3]]},
    {"type": "Circle", "coordinates": [1, 2]},
    {"type": "MultiPolygon", "coordinates": []},
])
def test_geometry_shapes_refuses_what_it_cannot_draw(geometry: dict[str, Any]) -> None:
    assert geometry_shapes(geometry) is None


def test_features_sharing_a_footprint_are_drawn_once_and_counted_each() -> None:
    levels = [Feature("bin", f"01-001-0{level}", _box(0, 0, 1, 1), {"level": level}) for level in (1, 2, 3)]
    other = Feature("bin", "01-002-01", _box(1, 0, 2, 1))

    scene = layout_scene([*levels, other], occupancy=None, place_labels=None, bbox=None, width_px=100, title="t")

    assert [item.keys for item in scene.features] == [("01-001-01", "01-001-02", "01-001-03"), ("01-002-01",)]
    assert [entry.text for entry in scene.kinds] == ["bin (4)"]


def test_kinds_are_drawn_places_first_and_listed_in_that_order() -> None:
    features = [Feature("dock", "D1", {"type": "Point", "coordinates": [0, 0]}),
                Feature("bin", "B1", _box(0, 0, 1, 1)), Feature("corridor", "c1", _box(-2, -2, 3, 3))]

    scene = layout_scene(features, occupancy=None, place_labels=None, bbox=None, width_px=100, title="t")

    assert [item.kind for item in scene.features] == ["corridor", "bin", "dock"]
    assert [entry.text for entry in scene.kinds] == ["corridor (1)", "bin (1)", "dock (1)"]


def test_undrawable_geometries_are_left_out_of_picture_and_legend() -> None:
    features = [Feature("dock", "D1", {"type": "Point", "coordinates": [0, 0]}),
                Feature("bin", "bad", {"type": "Polygon", "coordinates": [1, 2]})]

    scene = layout_scene(features, occupancy=None, place_labels=None, bbox=None, width_px=100, title="t")

    assert [entry.text for entry in scene.kinds] == ["dock (1)"]


def test_nothing_to_draw_without_a_bbox_is_an_error() -> None:
    with pytest.raises(NothingToDrawError, match="no layer and no feature"):
        layout_scene([], occupancy=None, place_labels=None, bbox=None, width_px=100, title="t")


def test_background_lines_up_with_the_map_frame() -> None:
    occupancy = np.zeros((20, 20), np.int8)
    occupancy[5, 12] = 100  # the cell centred on x = 1.25, y = 0.55
    layer = GridLayer("occupancy", occupancy, 0.1, 0.0, 0.0)

    scene = layout_scene([], occupancy=layer, place_labels=None, bbox=(0.0, 0.0, 2.0, 2.0), width_px=200, title="t")

    x, y = scene.view.to_px(np.array([[1.25, 0.55]]))[0].astype(int)
    assert scene.base[y, x].tolist() == [0, 0, 0]
    assert scene.base[y, x + 10].tolist() == [255, 255, 255]
    assert scene.base[y - 10, x].tolist() == [255, 255, 255]


def test_shrinking_a_large_grid_keeps_one_cell_walls_visible() -> None:
    occupancy = np.zeros((1000, 1000), np.int8)
    occupancy[500, :] = 100  # a 5 cm wall across a 50 m map
    layer = GridLayer("occupancy", occupancy, 0.05, 0.0, 0.0)

    scene = layout_scene([], occupancy=layer, place_labels=None, bbox=None, width_px=100, title="t")

    row = round(scene.view.to_px(np.array([[25.0, 25.025]]))[0, 1])
    assert scene.base[row - 1: row + 2, 10:90].min(axis=0).max() < 60


def test_place_labels_tint_free_space_and_are_listed() -> None:
    labels = np.zeros((10, 20), np.uint8)
    labels[:, :10] = PlaceLabel.CORRIDOR
    labels[:, 10:] = PlaceLabel.STORAGE
    layer = GridLayer("place_labels", labels, 0.5, 0.0, 0.0, LABEL_META)

    scene = layout_scene([], occupancy=None, place_labels=layer, bbox=None, width_px=200, title="t")

    assert [entry.text for entry in scene.places] == ["corridor", "storage"]
    left = scene.base[scene.view.height_px // 2, 50].astype(int)
    green = np.array(LABEL_COLOURS[PlaceLabel.CORRIDOR])
    assert np.abs(left - (255 * 0.55 + green * 0.45)).max() <= 1


def test_a_label_layer_without_class_names_is_drawn_without_tint() -> None:
    layer = GridLayer("place_labels", np.ones((4, 4), np.uint8), 0.5, 0.0, 0.0, {"encoding": "place_labels"})

    scene = layout_scene([], occupancy=None, place_labels=layer, bbox=None, width_px=100, title="t")

    assert scene.places == [] and scene.base.min() == 255


@pytest.fixture(scope="module")
def demo_scene_inputs() -> tuple[list[Feature], GridLayer, GridLayer]:
    """The demo warehouse's ground truth: every feature kind but lines, occupancy and place labels."""
    world = load_world("demo", seed=0)
    grids = ground_truth_grids(world)
    geometry = (grids.resolution_m, grids.origin_x_m, grids.origin_y_m)
    features = []
    for item in ground_truth_features(world)["features"]:
        properties = dict(item["properties"])
        kind = properties.pop("kind")
        features.append(Feature(kind, str(properties["id"]), item["geometry"], properties))
    return (features, GridLayer("occupancy", grids.occupancy, *geometry),
            GridLayer("place_labels", grids.labels, *geometry, LABEL_META))


def test_demo_warehouse_picture_has_every_kind_in_its_legend_in_png_and_svg(
        demo_scene_inputs: tuple[list[Feature], GridLayer, GridLayer]) -> None:
    features, occupancy, labels = demo_scene_inputs

    scene = layout_scene(features, occupancy=occupancy, place_labels=labels, bbox=None, width_px=800, title="demo")
    png = cv2.imdecode(np.frombuffer(render_png(scene), np.uint8), cv2.IMREAD_COLOR)
    svg = ET.fromstring(render_svg(scene))

    kinds = {feature.kind for feature in features}
    listed = {entry.text.split(" (")[0] for entry in scene.kinds}
    assert listed == kinds
    texts = {t.text for t in svg.iter("{http://www.w3.org/2000/svg}text")}
    assert {entry.text for entry in (*scene.kinds, *scene.places)} <= texts
    assert {"corridor", "junction", "storage"} <= {entry.text for entry in scene.places}
    assert png is not None and png.shape[1] > 800 and png.shape[0] >= scene.view.height_px
