"""Scenes: what only one scene knows, kept out of the engines, the runner and the sweep.

A case selects its scene with the top-level key ``scene`` (``scene = "percussion-drill"``); nothing generic
names a scene or guesses one from the case. A scene computes its results from the run's time series, so every
tier that runs the case reports them under the same keys. A scene is an object of the :class:`Scene` protocol
(subclass :class:`SceneReport`, whose methods default to "nothing"):

- ``check(case)``: the scene's own input rules (one CaseError naming the key), run by ``validate`` and ``run``;
- ``statistics(data, case, results)``: entries added to the transient (or lumped) results' ``statistics``,
  from the time series ``data`` (app/series.py names) and the tier's results;
- ``table_rows(results)``: lines (label, value, unit) of the end-of-run table, one unit per row;
- ``outputs(results, out_dir, title, plots)``: CSVs and (with ``plots``) plots it writes (file names), rank 0;
- ``sweep_columns``: result paths (below the analysis: ``statistics.motor.speed_rpm``) a sweep plots first;
- ``steady_floors(case)``: (speed [rad/s], torque [N m]) below which the steady-state stop counts a change as
  noise, when the case does not set them.

Registry: :func:`register` adds a scene under its ``name``; the shipped scenes register here, and
``PIEZODYN_SCENES=module[,module...]`` imports more modules (each registers its scenes when imported), so a
scene outside piezodyn's tree runs from the command line and under MPI as the shipped ones do
(docs/adding-a-scene.md).
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Protocol


class Scene(Protocol):
    name: str
    sweep_columns: tuple[str, ...]

    def check(self, case) -> None: ...

    def statistics(self, data: dict, case, results: dict) -> dict: ...

    def table_rows(self, results: dict) -> list[tuple[str, str, str]]: ...

    def outputs(self, results: dict, out_dir: Path, title: str, plots: bool = True) -> list[str]: ...

    def steady_floors(self, case) -> tuple[float, float]: ...


class SceneReport:
    """A scene that adds nothing: subclass it and override what the scene knows."""

    name = ""
    sweep_columns: tuple[str, ...] = ()

    def check(self, case) -> None:
        return None

    def statistics(self, data: dict, case, results: dict) -> dict:
        return {}

    def table_rows(self, results: dict) -> list[tuple[str, str, str]]:
        return []

    def outputs(self, results: dict, out_dir: Path, title: str, plots: bool = True) -> list[str]:
        return []

    def steady_floors(self, case) -> tuple[float, float]:
        return 0.0, 0.0


SCENES: dict[str, Scene] = {}
_SHIPPED = ("app.scenes.percussion_drill", "app.scenes.wwusm_motor")


def register(scene: Scene) -> Scene:
    """Add ``scene`` to the registry under ``scene.name`` (a later registration of the same name replaces it)."""
    if not scene.name:
        raise ValueError("a scene needs a name")
    SCENES[scene.name] = scene
    return scene


def _load() -> None:
    from app.errors import CaseError

    for module in _SHIPPED:
        importlib.import_module(module)
    for module in filter(None, (m.strip() for m in os.environ.get("PIEZODYN_SCENES", "").split(","))):
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise CaseError("PIEZODYN_SCENES", module, f"cannot be imported ({exc})") from None


def scene_of(case) -> Scene | None:
    """The scene a case names (None without ``scene``); KeyError for an unknown name (the runner refuses it
    with one line first)."""
    name = getattr(case, "scene", None)
    return None if name is None else SCENES[name]


def scene_named(name: str | None) -> Scene | None:
    return None if name is None else SCENES.get(name)


_load()
