"""The scene registry and the protocol a scene implements (app/scenes/__init__.py says what each method does)."""

from __future__ import annotations

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

    def sweep_axis(self, key: str) -> tuple[str, int | None, float] | None: ...


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

    def sweep_axis(self, key: str) -> tuple[str, int | None, float] | None:
        """How a sweep plots swept key ``key`` of this scene: (axis label with unit, the component of a vector
        value or None, the sign), x = sign * value[component] in the label's unit; None: the generic axis."""
        return None


SCENES: dict[str, Scene] = {}


def register(scene: Scene) -> Scene:
    """Add ``scene`` to the registry under ``scene.name`` (a later registration of the same name replaces it)."""
    if not scene.name:
        raise ValueError("a scene needs a name")
    SCENES[scene.name] = scene
    return scene


def scene_named(name: str | None) -> Scene | None:
    return None if name is None else SCENES.get(name)
