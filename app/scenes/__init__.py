"""Scene reports: the statistics, end-of-run lines and plots that only make sense for one scene
(the percussion drill's transducer flights), kept out of the generic transient engine.

A case selects its report with the top-level key ``scene`` (``scene = "percussion-drill"``); the
lumped tier is the drill model and always uses the drill's report. A report module provides

- ``statistics(data, cfg) -> dict``: entries added to ``statistics`` of an FE/modal transient run,
  from its time series ``data`` (app/series.py names) and the case's ``[transient]`` section;
- ``table_rows(statistics) -> list[(label, value, unit)]``: lines of the end-of-run table;
- ``plots(statistics, out_dir, title) -> list[str]``: extra plots (file names written).

A new report is one module here and one entry in :data:`SCENES` (docs/adding-a-scene.md).
"""

from __future__ import annotations

from importlib import import_module

SCENES: dict[str, str] = {
    "percussion-drill": "app.scenes.percussion_drill",
}


def scene_report(name: str):
    """The report module of scene ``name`` (a key of :data:`SCENES`)."""
    return import_module(SCENES[name])
