"""Start-up of the decomposition in a fresh process: what importing it loads, and a first call from two threads."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def _fresh(code: str) -> str:
    """Standard output of ``code`` run by a fresh interpreter from the repository root."""
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_importing_the_decomposition_loads_no_store_and_no_clustering_signal_or_optimisation_library() -> None:
    out = _fresh(
        "import sys\n"
        "import services.grid_decomposition\n"
        "print(sorted(m for m in ('sqlalchemy', 'sklearn', 'scipy.signal', 'scipy.stats', 'scipy.optimize')\n"
        "             if m in sys.modules))\n"
    )
    assert out.strip() == "[]"


def test_importing_the_decomposition_loads_no_image_filters_and_no_map_file_reader() -> None:
    # scipy.ndimage (and scikit-image, which loads it) come with the step libraries on decompose's second thread
    out = _fresh(
        "import sys\n"
        "import services.grid_decomposition\n"
        "print(sorted(m for m in ('scipy.ndimage', 'skimage', 'PIL', 'yaml') if m in sys.modules))\n"
    )
    assert out.strip() == "[]"


def test_the_store_records_and_map_file_functions_are_still_names_of_the_package() -> None:
    out = _fresh(
        "from services.grid_decomposition import PLACE_LABELS, decomposition_features, read_map_file\n"
        "print(PLACE_LABELS, decomposition_features.__name__, read_map_file.__name__)\n"
    )
    assert out.split() == ["place_labels", "decomposition_features", "read_map_file"]


def test_a_first_decomposition_on_two_threads_at_once_gives_the_same_result_as_in_turn() -> None:
    # both threads import the lazily loaded libraries at the same moment (a deadlock risk)
    out = _fresh(
        "from concurrent.futures import ThreadPoolExecutor\n"
        "import numpy as np\n"
        "from services.grid_decomposition import decompose\n"
        "occ = np.full((100, 180), -1, dtype=np.int8)\n"
        "occ[5:95, 5:175] = 100\n"
        "occ[8:92, 8:172] = 0\n"
        "occ[8:92, 88:91] = 100\n"
        "occ[40:58, 88:91] = 0\n"
        "with ThreadPoolExecutor(2) as pool:\n"
        "    jobs = [pool.submit(decompose, occ, resolution_m=0.05) for _ in range(2)]\n"
        "    both = [job.result(timeout=240) for job in jobs]\n"
        "alone = decompose(occ, resolution_m=0.05)\n"
        "print(all(np.array_equal(d.segments, alone.segments) and np.array_equal(d.labels, alone.labels)\n"
        "          and d.regions == alone.regions for d in both), len(alone.regions))\n"
    )
    assert out.split() == ["True", "2"]
