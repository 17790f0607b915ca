"""A scene is a case file plus a scene module, and nothing under app/ changes (issue 22): the strip under a
slider, its module and case under tests/ (tests/scenes/strip_slider.py), registered through the registry,
runs in the FE and the modal tier, each reporting its summary key (``statistics.strip``) and its table row,
and a sweep plots its column. Its force ratio follows the friction-drive law (the validation's tolerance,
0.05 of mu N, tests/test_strip_friction_drive.py) in both tiers."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

CASE = ROOT / "cases" / "validation" / "strip-friction-drive.toml"
SHORT = ["transient.end_time_s=1.5e-4", "geometry.parameters.lateral_divisions=50"]


def _register():
    sys.path.insert(0, str(Path(__file__).parent))
    import scenes.strip_slider  # noqa: F401  (registers the scene)


@pytest.mark.parametrize("tier", ["fe", "modal"])
def test_a_scene_outside_app_runs_in_both_tiers(tmp_path, tier):
    from app.runner import run_case

    _register()
    lines = []
    summary = run_case(CASE, [*SHORT, 'scene="strip-slider"', f'tier="{tier}"'], tmp_path / tier, quiet=True)
    strip = summary["results"]["transient"]["statistics"]["strip"]
    assert abs(strip["force_ratio"] - strip["law_force_ratio"]) <= 0.05
    # its table row, as the end-of-run table prints it
    from app.report import print_table, result_rows
    from app.scenes import SCENES

    print_table(result_rows(summary["results"], SCENES["strip-slider"]), lines.append)
    assert any(line.startswith("slider drive force / (mu N)") for line in lines)


def test_the_scene_from_the_command_line_and_its_sweep_column(tmp_path):
    env = dict(os.environ, PIEZODYN_SCENES="scenes.strip_slider",
               PYTHONPATH=os.pathsep.join([str(ROOT), str(Path(__file__).parent)]))
    out = tmp_path / "sweep"
    proc = subprocess.run([sys.executable, "-m", "app", "sweep", str(CASE), "--param",
                           "transient.bodies[0].velocity_m_per_s=[-0.30,0.0],[-0.36,0.0]", "--set",
                           'scene="strip-slider"', "--set", 'tier="modal"', *sum((["--set", s] for s in SHORT), []),
                           "--out", str(out), "--quiet"], capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr
    sweep = json.loads((out / "sweep.json").read_text())
    assert "transient.statistics.strip.force_ratio" in sweep["columns"]
    # the scene's column is the sweep's first plotted headline
    from app.sweep import plot_columns

    rows = [r for r in sweep["rows"] if "_failed" not in r]
    assert plot_columns(rows, ["transient.statistics.strip.force_ratio"])[0] == \
        "transient.statistics.strip.force_ratio"
    ratios = [r["transient.statistics.strip.force_ratio"] for r in rows]
    assert ratios[0] > ratios[1]         # the faster slider is driven less
