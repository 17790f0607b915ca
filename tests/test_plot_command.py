"""``piezodyn plot DIR`` (app/report.py): it redraws every result kind and reprints the end-of-run table, and a
damaged or foreign directory is one line naming the file, exit 2, no traceback, serially and on 2 ranks.

Result kinds: a transient run (the modal drill, fast; the FE and modal tiers share the code path), a lumped run,
a frequency-domain run (a PZT bar: modal and harmonic), a sweep. Damage: the series overwritten with random
bytes, truncated at several offsets, summary.json not UTF-8, truncated or missing, a summary naming an unknown
scene, an empty directory, a file given as the directory, a sweep.json damaged."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES, PINNED_MOTOR, run_cli

DRILL = ['tier="modal"', "geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
         "transient.end_time_s=1e-4", "transient.output_interval_s=1e-4", "output.fields=false"]


# as tests/test_cases.py runs the motor (its reduced model in the tests' shared cache)
MOTOR = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.tip_mesh_size_m=0.002",
         "reduction.interface_nodes=16", "transient.contacts[0].sample_points=64", "transient.end_time_s=2.8e-4"]


def _sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    root = tmp_path_factory.mktemp("plot")
    runs = {"drill": (CASES / "usdc-fe.toml", DRILL),
            "lumped": (CASES / "usdc-lumped.toml", ["lumped.duration_s=0.01"]),
            "bar": (CASES / "validation" / "pzt4-bar-axisymmetric.toml", ["geometry.parameters.axial_divisions=8"])}
    for name, (case, sets) in runs.items():
        proc = run_cli("run", case, "--out", root / name, "--quiet", *_sets(sets))
        assert proc.returncode == 0, proc.stderr
    proc = run_cli("sweep", CASES / "usdc-lumped.toml", "--param", "lumped.downforce_N=0,9", "--set",
                   "lumped.duration_s=0.01", "--out", root / "sweep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    return root


@pytest.fixture(scope="module")
def motor_result(tmp_path_factory):
    """The motor scene (modal tier) on the tests' coarse stator for ten periods, as tests/test_cases.py runs it."""
    out = tmp_path_factory.mktemp("plot_motor")
    proc = run_cli("run", PINNED_MOTOR, "--out", out, "--quiet", *_sets(MOTOR))
    assert proc.returncode == 0, proc.stderr
    return out


def _figures_drawn(directory, monkeypatch) -> dict:
    """{file name: what each saved figure shows} of ``piezodyn plot DIRECTORY`` run in this process: the titles
    (figure and axes), each drawn axes' labels and its legend's placement."""
    from matplotlib.figure import Figure

    from app.report import replot
    from app.scenes import SCENES
    from app.sweep import replot_sweep

    seen = {}
    original = Figure.savefig

    def record(fig, fname, *args, **kwargs):
        drawn = [ax for ax in fig.axes if ax.get_visible() and ax.has_data()]
        title = " ".join([fig._suptitle.get_text() if fig._suptitle else "", *(ax.get_title() for ax in drawn)])
        legends = [ax.get_legend() for ax in drawn if ax.get_legend() is not None]
        outside = [legend for legend in fig.legends if legend._loc == 8]       # below the panels (lower center)
        seen[Path(fname).name] = {"title": title.strip(), "x": [ax.get_xlabel() for ax in drawn],
                                  "y": [ax.get_ylabel() for ax in drawn], "legend_locs": [lg._loc for lg in legends],
                                  "outside_legends": len(outside), "figure_legends": len(fig.legends),
                                  "patches": sum(len(ax.patches) for ax in drawn)}
        return original(fig, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    if (directory / "sweep.json").is_file():
        replot_sweep(directory, lambda line: None)
    else:
        replot(directory, lambda line: None, SCENES)
    return seen


@pytest.mark.parametrize("kind", ["drill", "lumped", "bar", "sweep", "motor"])
def test_every_plot_is_titled_and_labelled(results, motor_result, kind, monkeypatch):
    """Issue 28: every plot of every result kind says what it shows: a title, every drawn panel's y label and
    the x label of at least the bottom panel (stacked panels share x), and legends placed where they cover
    the fewest points (loc 'best' = 0) or below the panels, not in a fixed corner a curve's peak may occupy.
    The motor: the ring plot is titled by what it shows (not the case's old "speed-torque"), the speed plot
    marks the steady window (a shaded span) and names the rotor speed."""
    directory = motor_result if kind == "motor" else results / kind
    seen = _figures_drawn(directory, monkeypatch)
    assert seen, "no plot drawn"
    for name, figure in seen.items():
        assert figure["title"], name
        assert all(figure["y"]), (name, figure["y"])
        assert any(figure["x"]), (name, figure["x"])
        assert all(loc == 0 for loc in figure["legend_locs"]), (name, figure["legend_locs"])
        assert figure["figure_legends"] == figure["outside_legends"], name
    if kind == "motor":
        from app.scenes.wwusm_motor.outputs import RING_PLOT, SPEED_PLOT

        assert "contact pressure round the ring" in seen[RING_PLOT]["title"]
        assert "speed-torque" not in seen[RING_PLOT]["title"]
        assert "rotor speed" in seen[SPEED_PLOT]["title"] and seen[SPEED_PLOT]["patches"] >= 1
        assert seen[SPEED_PLOT]["x"] == ["time [ms]"] and seen[SPEED_PLOT]["y"] == ["rotor speed [rpm]"]


@pytest.mark.parametrize("kind, expect", [("drill", ["transient_motion.png", "transient_force.png"]),
                                          ("lumped", ["transient_motion.png"]),
                                          ("bar", ["admittance.png", "impedance.png"]),
                                          ("sweep", ["sweep_lumped_downforce_N.png"])])
def test_plot_redraws_every_kind_and_reprints_its_table(results, kind, expect):
    for name in expect:
        (results / kind / name).unlink(missing_ok=True)
    proc = run_cli("plot", results / kind)
    assert proc.returncode == 0, proc.stderr
    for name in expect:
        assert (results / kind / name).is_file(), name
    lines = proc.stdout.splitlines()
    if kind == "sweep":
        assert lines[0].split()[0] == "point" and "downforce" in lines[0]
    else:
        assert any(line.startswith("-----") for line in lines)      # the end-of-run table, framed


def _one_line(proc, *needles):
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip() and not line.startswith(("-----", "Primary",
             "mpirun", "  Process", "  Exit", "the job", "a non-zero", "Per user", "job to be", "detected that"))]
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]


def _damaged(results, tmp_path):
    """(directory, what the message names) of each damage."""
    cases = []
    base = results / "drill"
    good = (base / "transient.h5").read_bytes()
    rng = np.random.default_rng(0)
    for name, data in (("random", rng.bytes(len(good))), ("cut_half", good[:len(good) // 2]),
                       ("cut_header", good[:100]), ("cut_end", good[:-64])):
        d = tmp_path / name
        shutil.copytree(base, d)
        (d / "transient.h5").write_bytes(data)
        cases.append((d, "transient.h5"))
    for name, data in (("summary_latin1", "é".encode("latin-1") * 10), ("summary_cut", b'{"results": {"tr')):
        d = tmp_path / name
        shutil.copytree(base, d)
        (d / "summary.json").write_bytes(data)
        cases.append((d, "summary.json"))
    d = tmp_path / "summary_missing"
    shutil.copytree(base, d)
    (d / "summary.json").unlink()
    cases.append((d, "summary.json"))
    d = tmp_path / "scene_unknown"
    shutil.copytree(base, d)
    summary = json.loads((d / "summary.json").read_text())
    summary["case"]["scene"] = "no-such-scene"
    (d / "summary.json").write_text(json.dumps(summary))
    cases.append((d, "scene"))
    d = tmp_path / "empty"
    d.mkdir()
    cases.append((d, "summary.json"))
    cases.append((base / "summary.json", "not a result directory"))
    d = tmp_path / "sweep_cut"
    shutil.copytree(results / "sweep", d)
    (d / "sweep.json").write_bytes((results / "sweep" / "sweep.json").read_bytes()[:50])
    cases.append((d, "sweep.json"))
    return cases


#: on 2 ranks, one damage of each file and each way the refusal travels (an unreadable HDF5 file, a cut JSON, a
#: foreign scene, no result at all, a cut sweep): the checks are the serial ones, what 2 ranks add is that every
#: rank stops with the one line (no hang)
ON_TWO_RANKS = {"random", "summary_cut", "scene_unknown", "empty", "sweep_cut"}


@pytest.mark.parametrize("mpi", [0, 2])
def test_plot_on_a_damaged_or_foreign_directory_is_one_line(results, tmp_path, mpi):
    for directory, needle in _damaged(results, tmp_path):
        if mpi and directory.name not in ON_TWO_RANKS:
            continue
        _one_line(run_cli("plot", directory, mpi=mpi), needle)
