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
- ``sweep_axis(key)``: how a sweep plots one of the scene's keys, as the user thinks of it: (label with unit,
  component of a vector value or None, sign), e.g. the drill's ``transient.loads.fe_force_N`` as
  "downforce [N]" = -F_z; None: the generic axis;
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

from app.scenes.registry import SCENES, Scene, SceneReport, register, scene_named

__all__ = ["SCENES", "Scene", "SceneReport", "register", "scene_named", "scene_of"]
_SHIPPED = ("app.scenes.percussion_drill", "app.scenes.wwusm_motor")


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


_load()
