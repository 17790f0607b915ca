"""What piezo users expect next to the admittance: harmonic.csv (f, |Y|, phase, |Z|), modes.csv, an
impedance plot with f_r/f_a, ``piezodyn cases`` and ``piezodyn plot DIR``; readable plot labels."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import CASES, run_cli

from app.plots import quantity_label

BAR = CASES / "validation" / "pzt4-bar-axisymmetric.toml"


@pytest.fixture(scope="module")
def bar_run(tmp_path_factory):
    """The IEEE 176 PZT-4 bar: modal, harmonic and equivalent circuit (a few seconds)."""
    from mpi4py import MPI

    from app.runner import run_case

    out = tmp_path_factory.mktemp("bar")
    summary = run_case(BAR, ["output.fields=false"], out, comm=MPI.COMM_SELF, quiet=True)
    return out, summary


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_harmonic_csv_has_admittance_and_impedance(bar_run):
    out, summary = bar_run
    harmonic = summary["results"]["harmonic"]
    rows = _rows(out / "harmonic.csv")
    assert list(rows[0]) == ["frequency_Hz", "admittance_magnitude_S", "admittance_phase_deg",
                             "impedance_magnitude_ohm", "impedance_phase_deg"]
    f = np.array([float(r["frequency_Hz"]) for r in rows])
    y = np.array([float(r["admittance_magnitude_S"]) for r in rows])
    z = np.array([float(r["impedance_magnitude_ohm"]) for r in rows])
    np.testing.assert_array_equal(f, harmonic["frequency_Hz"])
    np.testing.assert_allclose(y * z, 1.0, rtol=1e-14)  # Z = 1/Y
    z_phase = [float(r["impedance_phase_deg"]) for r in rows]
    np.testing.assert_allclose(z_phase, -np.array(harmonic["admittance_phase_deg"]))
    # |Z| is least at the series resonance and largest at the antiresonance (within one frequency step)
    step = np.max(np.diff(f))
    modal = summary["results"]["modal"]
    assert abs(f[np.argmin(z)] - modal["working_resonance_Hz"]) <= step
    assert abs(f[np.argmax(z)] - modal["working_antiresonance_Hz"]) <= step
    for name in ("harmonic.csv", "modes.csv", "admittance.png", "impedance.png"):
        assert name in summary["outputs"] and (out / name).stat().st_size > 0


def test_mode_table_marks_the_working_mode(bar_run):
    out, summary = bar_run
    modal = summary["results"]["modal"]
    rows = _rows(out / "modes.csv")
    assert len(rows) == len(modal["modes"])
    working = [r for r in rows if r["working"] == "1"]
    # one numbering everywhere: modes.csv, the summary and the mode-shape XDMF count from 1
    assert [int(r["mode"]) for r in rows] == [m["mode"] for m in modal["modes"]] == list(range(1, len(rows) + 1))
    assert len(working) == 1 and int(working[0]["mode"]) == modal["working_mode"] == modal["working_mode_index"] + 1
    assert float(working[0]["resonance_Hz"]) == modal["working_resonance_Hz"]
    assert float(working[0]["k_eff"]) == pytest.approx(modal["working_k_eff"], rel=1e-12)


def test_plot_dir_rewrites_the_outputs_from_summary(bar_run, tmp_path):
    out, _ = bar_run
    copy = tmp_path / "copy"
    copy.mkdir()
    shutil.copy(out / "summary.json", copy / "summary.json")
    proc = run_cli("plot", copy)
    assert proc.returncode == 0, proc.stderr
    for name in ("harmonic.csv", "modes.csv", "admittance.png", "impedance.png"):
        assert name in proc.stdout and (copy / name).stat().st_size > 0
    assert (copy / "harmonic.csv").read_text() == (out / "harmonic.csv").read_text()
    missing = run_cli("plot", tmp_path / "nowhere")
    assert missing.returncode == 2 and "Traceback" not in missing.stderr
    assert missing.stderr.count("\n") == 1 and "no such directory" in missing.stderr
    (copy / "summary.json").write_text("{not json")
    broken = run_cli("plot", copy)
    assert broken.returncode == 2 and "Traceback" not in broken.stderr


def test_cases_lists_every_shipped_case_with_its_title():
    proc = run_cli("cases")
    assert proc.returncode == 0, proc.stderr
    files = sorted(CASES.rglob("*.toml"))
    for path in files:
        assert str(path.relative_to(CASES.parent)) in proc.stdout
    assert "USDC drill transducer: modal + harmonic + equivalent circuit" in proc.stdout
    assert "PZT-4 33-bar, axisymmetric" in proc.stdout
    line = next(ln for ln in proc.stdout.splitlines() if "usdc-lumped.toml" in ln)
    assert "lumped model" in line  # a case without a title: its leading comment


@pytest.mark.parametrize("where", ["checkout", "elsewhere"])
def test_cases_prints_paths_that_open_from_where_it_runs(where, tmp_path):
    """Issue 28: the Docker image runs in /work while the cases are installed in /opt/piezodyn/cases, so
    a path relative to the install directory did not exist there. Each listed path must open from the working
    directory: relative below a checkout, absolute elsewhere (tests/test_docker.py checks the image's
    WORKDIR is such an elsewhere)."""
    cwd = CASES.parent if where == "checkout" else tmp_path
    proc = run_cli("cases", cwd=cwd)
    assert proc.returncode == 0, proc.stderr
    listed = [ln.split()[0] for ln in proc.stdout.splitlines() if ln.startswith("  ")]
    assert len(listed) == len(list(CASES.rglob("*.toml")))
    for name in listed:
        assert (cwd / name).is_file(), name
        assert Path(name).is_absolute() == (where == "elsewhere")


def test_plot_labels_have_readable_names_and_display_units():
    assert quantity_label("transient.statistics.transducer.max_rise_m") == ("transducer max rise [mm]", 1e3)
    assert quantity_label("lumped.downforce_N") == ("downforce [N]", 1.0)
    assert quantity_label("modal.working_resonance_Hz") == ("modal working resonance [kHz]", 1e-3)
    assert quantity_label("lumped.free_mass.mass_kg") == ("free mass mass [g]", 1e3)
    assert quantity_label("lumped.statistics.impact_rate_per_s.stem_rock") == ("impact rate stem rock [1/s]", 1.0)
    assert quantity_label("modal.working_k_eff")[0] == "modal working k_eff"


def test_transient_result_replots_its_time_series(tmp_path):
    out = tmp_path / "fe"
    proc = run_cli("run", CASES / "usdc-fe.toml", "--out", out, "--quiet",
                   "--set", "geometry.parameters.mesh_size_m=0.004",
                   "--set", "geometry.parameters.ceramic_mesh_size_m=0.0025",
                   "--set", "transient.end_time_s=2e-5", "--set", "transient.output_interval_s=1e-5",
                   "--set", "output.fields=false", "--set", "output.plots=false")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # --quiet: no progress either
    assert not (out / "transient_motion.png").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["results"]["transient"]["time_series"] == "transient.h5"
    replot = run_cli("plot", out)
    assert replot.returncode == 0, replot.stderr
    assert (out / "transient_motion.png").stat().st_size > 0 and (out / "transient_force.png").stat().st_size > 0
    # a result written before summaries recorded what to plot (results.transient.plot): from its case
    del summary["results"]["transient"]["plot"]
    (out / "summary.json").write_text(json.dumps(summary))
    for name in ("transient_motion.png", "transient_force.png"):
        (out / name).unlink()
    replot = run_cli("plot", out)
    assert replot.returncode == 0, replot.stderr
    assert (out / "transient_motion.png").stat().st_size > 0 and (out / "transient_force.png").stat().st_size > 0


def _saved_figure(monkeypatch):
    """Capture the figure a plot function saves: [(figure)]."""
    from matplotlib.figure import Figure

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *args, **kwargs: saved.append(fig))
    return saved


def _stator_like_sweep(phases_deg):
    """A synthetic two-electrode sweep (|Y| of a resonance) with the drive and the driven-alone curves as
    app/harmonic.py writes them."""
    f = np.linspace(35750.0, 36250.0, 21)
    y = 1j * 2 * np.pi * f * 2e-9 + 1e-3 / (1 + 2j * (f - 36000.0) / 144.0)
    out = {"frequency_Hz": f.tolist(), "admittance_magnitude_S": np.abs(2 * y).tolist(),
           "admittance_phase_deg": np.degrees(np.angle((1 + 1j) * y)).tolist(),
           "drive_phasors_V_deg": {"A": [200.0, phases_deg[0]], "B": [200.0, phases_deg[1]]}}
    for name in ("A", "B"):
        out[f"admittance_{name}_alone_magnitude_S"] = np.abs(y).tolist()
        out[f"admittance_{name}_alone_phase_deg"] = np.degrees(np.angle(y)).tolist()
    return out


def test_two_phase_admittance_plot_says_what_each_curve_is(monkeypatch, tmp_path):
    """Issue 28: under a two-phase drive the total current / V is no driving-point admittance (phase near 135
    deg for A + jB): the plot draws each electrode driven alone, labelled so, beside the total, labelled as
    what it is; the title says so; axes labelled; the legend below the panels (off the curves)."""
    from app.plots import admittance_plot

    saved = _saved_figure(monkeypatch)
    admittance_plot(tmp_path / "admittance.png", _stator_like_sweep((0.0, 90.0)), 36000.0, None, title="stator")
    (fig,) = saved
    top, bottom = fig.axes
    labels = [line.get_label() for line in top.lines]
    assert "Y_A = I/V, A driven alone" in labels and "Y_B = I/V, B driven alone" in labels
    total = [label for label in labels if label.startswith("FE:")]
    assert len(total) == 1 and "not a driving-point Y" in total[0] and "B 200 V at 90 deg" in total[0]
    assert "each driven electrode alone" in top.get_title() and top.get_title().startswith("stator")
    assert top.get_ylabel() == "|Y| [S]" and bottom.get_ylabel() == "phase(Y) [deg]"
    assert bottom.get_xlabel() == "frequency [kHz]"
    assert top.get_legend() is None and len(fig.legends) == 1       # below the panels, off the curves
    # in phase (one electrode or several together): the curve is their I/V, no alone curves asked
    saved.clear()
    single = {k: v for k, v in _stator_like_sweep((0.0, 0.0)).items() if "alone" not in k}
    admittance_plot(tmp_path / "admittance.png", single, 36000.0, None, title="stator")
    (fig,) = saved
    assert "I/V of electrode A, B" in fig.axes[0].get_title()
    assert [line.get_label() for line in fig.axes[0].lines if not line.get_label().startswith("f_")] == \
        ["FE: Y of A, B"]
