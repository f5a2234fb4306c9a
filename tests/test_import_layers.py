"""The house's layers: who may import whom (docs/architecture.md draws the same picture).

* ``shared`` imports nothing of ours;
* a stage (``services/<stage>/``) imports ``shared`` and its own package only; so do the simulator and the
  replay tools;
* ``services/labelling_training`` (training the RGB-D classifier on photos and simulator renders) may import the
  object-labelling stage and the simulator besides;
* the map-domain package ``atlas`` imports ``shared`` only;
* ``api`` imports ``atlas`` and ``shared``, and no router imports another;
* nothing imports ``api`` but the composition root (``services/cli.py``, ``services/runtime.py``); benchmarks
  build the app with ``from api import create_app`` and query through ``atlas``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
OURS = ("shared", "services", "api", "atlas", "migrations")
STAGES = ("occupancy_mapping", "pillar_mapping", "grid_decomposition", "object_labelling", "semantic_fusion",
          "floor_plan", "load_scenes", "simulator", "replay")
COMPOSITION_ROOT = ("services.cli", "services.runtime")


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Our modules ``path`` imports (absolute imports; the code base uses no relative ones)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module is not None and node.level == 0:
            found.add(node.module)
    return {name for name in found if name.split(".")[0] in OURS}


def _allowed(importer: str) -> tuple[str, ...]:
    """Package prefixes ``importer`` may import."""
    top, _, rest = importer.partition(".")
    if top == "shared":
        return ("shared",)
    if top == "atlas":
        return ("shared", "atlas")
    if top == "api":
        return ("shared", "atlas", "api")
    if top == "migrations":
        return ("shared", "migrations")
    stage = rest.split(".")[0]
    if importer in COMPOSITION_ROOT:
        return OURS
    if stage == "labelling_training":
        return ("shared", "services.labelling_training", "services.object_labelling", "services.simulator")
    if stage in STAGES:
        return ("shared", f"services.{stage}")
    return ("shared",)


def _within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _modules() -> list[Path]:
    return sorted(p for top in OURS for p in (ROOT / top).rglob("*.py"))


def test_every_package_imports_only_the_layers_below_it() -> None:
    wrong = []
    for path in _modules():
        importer = _module_name(path)
        allowed = _allowed(importer)
        wrong += [f"{importer} imports {name}" for name in sorted(_imports(path))
                  if not any(_within(name, prefix) for prefix in allowed)]
    assert not wrong, "\n".join(wrong)


def test_no_router_imports_another() -> None:
    routers = {_module_name(p): p for p in (ROOT / "api" / "routers").glob("*.py") if p.stem != "__init__"}
    wrong = [f"{name} imports {other}" for name, path in routers.items() for other in sorted(_imports(path))
             if other in routers and other != name]
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("package", ["shared", "atlas", "services"])
def test_nothing_below_the_api_imports_it(package: str) -> None:
    wrong = [f"{_module_name(p)} imports {name}" for p in sorted((ROOT / package).rglob("*.py"))
             if _module_name(p) not in COMPOSITION_ROOT for name in _imports(p) if _within(name, "api")]
    assert not wrong, "\n".join(wrong)


def test_benchmarks_use_the_domain_package_not_the_api_internals() -> None:
    """Benchmarks may build the app (``from api import create_app``) but query through ``atlas``."""
    wrong = [f"{p.name} imports {name}" for p in sorted((ROOT / "bench").glob("*.py")) for name in _imports(p)
             if _within(name, "api") and name != "api"]
    assert not wrong, "\n".join(wrong)
