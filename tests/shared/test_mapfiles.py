"""map_server YAML + PGM maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from shared.mapfiles import MapFileError, read_map_yaml, write_map_yaml

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"


def test_write_then_read_round_trips_trinary_map(tmp_path: Path) -> None:
    occ = np.full((4, 6), -1, np.int8)
    occ[0, :] = 0
    occ[1, 2] = 100
    occ[3, 5] = 90
    occ[2, 2] = 50  # uncertain: written as unknown
    image = write_map_yaml(tmp_path / "site.yaml", occ, resolution_m=0.05, origin_x_m=-1.0, origin_y_m=2.5)
    pixels = np.asarray(Image.open(image))
    assert pixels[-1, 0] == 254 and pixels[-2, 2] == 0 and pixels[0, 5] == 0  # row 0 of the image = top
    read = read_map_yaml(tmp_path / "site.yaml")
    assert (read.resolution_m, read.origin_x_m, read.origin_y_m) == (0.05, -1.0, 2.5)
    expected = occ.copy()
    expected[expected == 90] = 100
    expected[2, 2] = -1
    np.testing.assert_array_equal(read.occupancy, expected)


def test_read_honours_negate_and_thresholds(tmp_path: Path) -> None:
    Image.fromarray(np.array([[0, 100, 255]], np.uint8)).save(tmp_path / "m.png")
    (tmp_path / "m.yaml").write_text(
        "image: m.png\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n"
        "occupied_thresh: 0.9\nfree_thresh: 0.1\n"
    )
    np.testing.assert_array_equal(read_map_yaml(tmp_path / "m.yaml").occupancy, [[0, -1, 100]])
    (tmp_path / "m.yaml").write_text(
        "image: m.png\nresolution: 0.1\norigin: [0, 0, 0]\nmode: scale\n"
        "occupied_thresh: 0.9\nfree_thresh: 0.1\n"
    )
    np.testing.assert_array_equal(read_map_yaml(tmp_path / "m.yaml").occupancy, [[100, 63, 0]])


@pytest.mark.parametrize(
    ("yaml_text", "image_bytes", "match"),
    [
        (None, None, "does not exist"),
        ("image: [unclosed\n", None, "not readable YAML"),
        ("- just a list\n", None, "not a YAML mapping"),
        ("image: m.pgm\nresolution: 0.05\n", None, r"lacks \['origin'\]"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nmode: fancy\n", None, "unknown mode"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", None, "map image .* does not exist"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"not an image", "not a readable image"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0.5]\n", None, "origin yaw"),
    ],
)
def test_read_rejects_bad_map_files(
    tmp_path: Path, yaml_text: str | None, image_bytes: bytes | None, match: str
) -> None:
    if yaml_text is not None:
        (tmp_path / "m.yaml").write_text(yaml_text)
    if image_bytes is not None:
        (tmp_path / "m.pgm").write_bytes(image_bytes)
    with pytest.raises(MapFileError, match=match):
        read_map_yaml(tmp_path / "m.yaml")


def test_write_creates_the_folder_it_is_told_to_write_into(tmp_path: Path) -> None:
    """``aisle map-build BAG --out new_dir/map.yaml`` must not fail because ``new_dir`` does not exist yet."""
    occupancy = np.zeros((4, 6), dtype=np.int8)
    image = write_map_yaml(tmp_path / "new" / "dir" / "map.yaml", occupancy, resolution_m=0.05, origin_x_m=0.0,
                           origin_y_m=0.0)
    assert image.exists() and read_map_yaml(tmp_path / "new" / "dir" / "map.yaml").occupancy.shape == (4, 6)


def test_write_rejects_empty_map(tmp_path: Path) -> None:
    with pytest.raises(MapFileError, match="non-empty"):
        write_map_yaml(
            tmp_path / "x.yaml", np.zeros((0, 3), np.int8), resolution_m=0.05, origin_x_m=0, origin_y_m=0
        )


@pytest.mark.skipif(
    not (DATA / "bags" / "mac_first_floor").is_dir(), reason="shared data folder ../shared/data absent"
)
def test_reads_the_mac_floor_map() -> None:
    read = read_map_yaml(DATA / "bags" / "mac_first_floor" / "mac_1st_floor_final.yaml")
    assert read.occupancy.shape == (1706, 903)
    assert read.resolution_m == pytest.approx(0.03)
    assert 10_000 < np.count_nonzero(read.occupancy == 100) < 30_000


def test_a_bare_image_with_a_light_unknown_grey_reads_its_speckle_by_the_nearer_mode(tmp_path: Path) -> None:
    from shared.mapfiles import read_map_file

    grey = np.full((40, 60), 230, np.uint8)  # unknown drawn light grey, as some maps do
    grey[5:35, 5:30] = 255  # a room seen free
    grey[10:12, 10:20] = 236  # speckle nearer the unknown grey than white
    grey[20:22, 10:20] = 248  # speckle nearer white
    grey[5, 5:30] = 0  # a wall
    Image.fromarray(grey).save(tmp_path / "map.png")
    plain = read_map_file(tmp_path / "map.png", resolution_m=0.05).occupancy[::-1]
    modes = read_map_file(tmp_path / "map.png", resolution_m=0.05, free_from_modes=True).occupancy[::-1]
    assert plain[0, 0] == 0  # map_server's thresholds call 230 free
    assert modes[0, 0] == -1 and modes[10, 15] == -1
    assert modes[7, 7] == 0 and modes[20, 15] == 0
    assert modes[5, 10] == 100


def test_a_black_and_white_image_reads_as_map_server_reads_it(tmp_path: Path) -> None:
    from shared.mapfiles import read_map_file, unknown_greys

    grey = np.full((30, 30), 255, np.uint8)
    grey[::7] = 0
    grey[3, 3] = 220  # one light-grey pixel: no mode of its own
    Image.fromarray(grey).save(tmp_path / "map.png")
    plain = read_map_file(tmp_path / "map.png", resolution_m=0.05)
    modes = read_map_file(tmp_path / "map.png", resolution_m=0.05, free_from_modes=True)
    assert np.array_equal(plain.occupancy, modes.occupancy)
    assert not unknown_greys(grey).any()


def test_walls_drawn_light_grey_read_occupied_and_furniture_in_that_grey_stays_free(tmp_path: Path) -> None:
    from shared.mapfiles import read_map_file

    grey = np.full((120, 160), 180, np.uint8)  # unknown
    grey[10:110, 10:150] = 211  # the building's walls, filled light grey (map_server reads 211 as free)
    grey[13:107, 13:147] = 255
    grey[13:107, 79:82] = 211  # a wall between two rooms, 4.7 m long
    grey[40:70, 100:112] = 211  # a desk in the same grey, 1.5 m x 0.6 m
    grey[20:100, 30] = 0  # a black wall ...
    grey[20:100, 31] = 214  # ... with an antialiased edge in the light grey: one pixel wide
    Image.fromarray(grey).save(tmp_path / "map.png")
    plain = read_map_file(tmp_path / "map.png", resolution_m=0.05).occupancy[::-1]
    modes = read_map_file(tmp_path / "map.png", resolution_m=0.05, free_from_modes=True).occupancy[::-1]
    assert plain[50, 80] == plain[11, 50] == 0  # map_server's thresholds call the walls free
    assert modes[50, 80] == modes[11, 50] == 100
    assert modes[55, 105] == 0  # the desk
    assert modes[50, 31] == 0  # the black wall's edge
    assert modes[50, 60] == 0 and modes[0, 0] == -1
