"""``piezodyn sweep``: any case key, any tier (lumped, FE modal, FE transient), the same table on 1 or 2
ranks, one-line errors, help without markup, flags as for ``run``.

The ``mpi`` tests also run in the MPI pass (``mpirun -n 2 python3 -m pytest -m mpi``)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from conftest import CASES, run_cli

from app.errors import CaseError
from app.sweep import build_parser, main, parse_param, run_sweep, sweep_figures

LUMPED = CASES / "usdc-lumped.toml"
FAST = ["lumped.duration_s=0.004", "lumped.output.plots=false", "lumped.output.write_time_series=false"]
BAR = CASES / "validation" / "pzt4-bar-axisymmetric.toml"
BAR_MODAL = ["analyses=[\"modal\"]", "output.fields=false"]
DRILL = CASES / "usdc-fe.toml"
# the FE drill on a coarse mesh for 20 simulated microseconds (~80 steps): the plumbing, not the physics
DRILL_TINY = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
              "transient.end_time_s=2e-5", "transient.output_interval_s=1e-5", "output.fields=false",
              "output.plots=false"]


def _world():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def _table(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def test_lumped_sweep_writes_table_summaries_and_readable_plot(tmp_path):
    rows = run_sweep(LUMPED, [parse_param("lumped.downforce_N=0,9")], tmp_path, FAST, comm=None, progress=False)
    assert [r["lumped.downforce_N"] for r in rows] == [0, 9]
    table = _table(tmp_path / "sweep.csv")
    assert len(table) == 2 and table[1]["lumped.downforce_N"] == "9"
    assert "lumped.statistics.stem_rock_foundation.mean_power_W" in table[0]
    assert not [c for c in table[0] if "wall" in c]  # the table does not depend on the machine
    for i in range(2):
        summary = json.loads((tmp_path / f"point_{i:04d}" / "summary.json").read_text())
        assert summary["case"]["lumped"]["downforce_N"] == [0.0, 9.0][i]  # as `run --set` writes it
        assert summary["results"]["lumped"]["energy_ledger"]["closure_relative"] < 1e-10
        assert float(table[i]["lumped.energy_ledger.closure_relative"]) < 1e-10
    assert (tmp_path / "sweep_lumped_downforce_N.png").exists()


def test_param_values_may_be_lists_and_keys_are_checked_against_the_schema(tmp_path):
    assert parse_param("transient.loads.fe_force_N=[0,0],[0,-3.5]") == (
        "transient.loads.fe_force_N", [[0, 0], [0, -3.5]])
    assert parse_param("lumped.downforce_N=0,3") == ("lumped.downforce_N", [0, 3])
    with pytest.raises(CaseError) as info:
        run_sweep(LUMPED, [parse_param("lumped.free_mass.weight_kg=0.002,0.004")], tmp_path, FAST, progress=False)
    assert info.value.key == "lumped.free_mass.weight_kg"
    with pytest.raises(CaseError) as info:  # a key of the other tier: the FE schema has no lumped.x
        run_sweep(BAR, [parse_param("geometry.parameters.lenght_m=0.02,0.04")], tmp_path, BAR_MODAL, progress=False)
    assert "lenght_m" in info.value.key
    with pytest.raises(CaseError):
        parse_param("downforce_N")


def test_sweep_main_exits_2_on_bad_value_with_one_line(tmp_path, capsys):
    code = main([str(LUMPED), "--param", "lumped.stem.mass_kg=0.04,-1", "--out", str(tmp_path), "--quiet",
                 *[a for s in FAST for a in ("--set", s)]])
    assert code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if _world().rank == 0:  # only rank 0 prints the one-line message
        assert err.count("\n") == 1 and "lumped.stem.mass_kg" in err and err.startswith("piezodyn: error:")


def test_help_is_plain_text_with_the_flags_of_run():
    text = build_parser().format_help()
    assert "``" not in text and ":class:" not in text
    for flag in ("--param", "--set", "--out", "--quiet"):
        assert flag in text
    assert "--no-progress" not in text
    assert "fe_force_N=[0,0],[0,-3]" in text  # an FE example, not only lumped keys


def test_fe_modal_sweep_resonance_scales_as_one_over_length(tmp_path):
    """Length-extensional 33 bar (IEEE 176): f_r = (f_r/f_a)(k33) / (2 L sqrt(rho s33^D)), so doubling L halves
    f_r, up to the rod's lateral inertia (Rayleigh-Love, (nu^E pi r / L)^2 / 4: -7.2e-4 at 20 mm, a quarter
    of it at 40 mm): the ratio is 2 (1 - 5.4e-4). Tolerance 1e-4: the Rayleigh-Love term's own error for
    f_r (measured 1.6e-5 at 20 mm) and the mesh (4e-7 at 20 divisions)."""
    from ieee176 import rayleigh_love_factor

    from app.materials import LIBRARY
    from forms import voigt

    rows = run_sweep(BAR, [parse_param("geometry.parameters.length_m=0.02,0.04")], tmp_path, BAR_MODAL,
                     comm=None, progress=False)
    f_short, f_long = (r["modal.working_resonance_Hz"] for r in rows)
    s_e, _, _ = voigt.e_form_to_d_form(*LIBRARY["PZT-4"].tensors())
    poisson = -s_e[0, 2] / s_e[2, 2]
    expected = 2.0 * rayleigh_love_factor(poisson, 0.001, 0.02) / rayleigh_love_factor(poisson, 0.001, 0.04)
    assert f_short / f_long == pytest.approx(expected, rel=1e-4)
    table = _table(tmp_path / "sweep.csv")
    assert float(table[1]["modal.working_resonance_Hz"]) == f_long
    assert (tmp_path / "sweep_geometry_parameters_length_m.png").exists()


def test_fe_transient_downforce_sweep_equals_single_runs(tmp_path):
    from app.runner import run_case

    param = parse_param("transient.loads.fe_force_N=[0.0,0.0],[0.0,-9.0]")
    rows = run_sweep(DRILL, [param], tmp_path / "sweep", DRILL_TINY, comm=None, progress=False)
    assert [r["transient.loads.fe_force_N"] for r in rows] == [[0.0, 0.0], [0.0, -9.0]]
    single = run_case(DRILL, [*DRILL_TINY, "transient.loads.fe_force_N=[0.0, -9.0]"], tmp_path / "single",
                      quiet=True)
    assert single["case"]["transient"]["loads"]["fe_force_N"] == [0.0, -9.0]
    assert rows[1]["transient.steps"] == single["results"]["transient"]["steps"] > 0
    stats = single["results"]["transient"]["statistics"]["transducer"]
    assert rows[1]["transient.statistics.transducer.mean_displacement_m"] == stats["mean_displacement_m"]
    table = _table(tmp_path / "sweep" / "sweep.csv")
    assert table[1]["transient.loads.fe_force_N"] == "[0.0, -9.0]"
    assert (tmp_path / "sweep" / "sweep_transient_loads_fe_force_N.png").exists()
    # the plot reads "downforce [N]" increasing to the right (the drill scene's axis, kept in sweep.json)
    sweep = json.loads((tmp_path / "sweep" / "sweep.json").read_text())
    assert sweep["axes"] == {"transient.loads.fe_force_N": ["downforce [N]", -1, -1.0]}
    ((_, fig),) = list(sweep_figures([r for r in sweep["rows"]], sweep["parameters"], sweep["title"],
                                     sweep["headline"], sweep["axes"]))
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert visible and all(ax.get_xlabel() == "downforce [N]" for ax in visible)
    assert list(visible[0].lines[0].get_xdata()) == [0.0, 9.0]


def _drill_rows(with_intervals: bool) -> list[dict]:
    """Sweep rows as the drill's downforce sweep makes them: the vector key, one headline that is zero at
    every point, one with batch-means half-widths."""
    rate = "transient.statistics.impact_rate_per_s.stem_rock"
    zero = "transient.statistics.transducer.flight_rate_per_s"
    rows = []
    for i, force in enumerate([0.0, -3.0, -9.0]):
        row = {"point": i, "transient.loads.fe_force_N": [0.0, force], rate: 200.0 - 40 * force, zero: 0.0}
        if with_intervals:
            row["transient.statistics.interval_95.impact_rate_per_s.stem_rock"] = 30.0 + i
        rows.append(row)
    return rows


@pytest.mark.parametrize("with_intervals", [True, False])
def test_downforce_sweep_plot_reads_downforce_increasing_with_intervals_and_no_zero_panel(with_intervals):
    """Issue 28: the FE drill's downforce sweep is plotted against "downforce [N]" (the scene's axis: -F_z, not
    "loads FE force, component 1" from -9 to 0), x increasing to the right; a panel whose values are all zero
    is left out; a statistic with a 95 % batch-means interval gets error bars of that half-width; the title
    says what is plotted; the terminal table names the axis and the intervals."""
    from matplotlib.container import ErrorbarContainer

    from app.case.schema import load_case
    from app.sweep import scene_axes, table_lines

    key = "transient.loads.fe_force_N"
    axes = scene_axes(load_case(DRILL), [key])
    assert axes == {key: ["downforce [N]", -1, -1.0]}
    rows = _drill_rows(with_intervals)
    headline = ["transient.statistics.impact_rate_per_s.stem_rock", "transient.statistics.transducer.flight_rate_per_s"]
    ((name, fig),) = list(sweep_figures(rows, [key], "drill", headline, axes))
    assert name == "sweep_transient_loads_fe_force_N.png"
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 1                                   # the all-zero flight rate has no panel
    ax = visible[0]
    assert ax.get_xlabel() == "downforce [N]" and "impact rate" in ax.get_ylabel() and "[1/s]" in ax.get_ylabel()
    low, high = ax.get_xlim()
    assert low < high
    line = ax.lines[0]
    assert list(line.get_xdata()) == [0.0, 3.0, 9.0] and list(line.get_ydata()) == [200.0, 320.0, 560.0]
    bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    assert len(bars) == int(with_intervals)
    if with_intervals:
        segments = bars[0].lines[2][0].get_segments()
        assert [seg[1][1] - seg[0][1] for seg in segments] == pytest.approx([60.0, 62.0, 64.0])
    title = fig._suptitle.get_text()
    assert "drill" in title and "downforce [N]" in title and ("95 %" in title) == with_intervals
    table = table_lines(rows, [key], headline, axes)
    assert "downforce [N]" in table[0] and "flight rate" not in table[0]
    assert table[2].split()[:2] == ["0", "0"]                      # point 0 at 0 N, not "-0"
    assert ("± 32" in table[2 + 2]) == with_intervals


def test_cli_sweep_is_a_subcommand_with_quiet(tmp_path):
    proc = run_cli("sweep", LUMPED, "--param", "lumped.downforce_N=3", "--quiet", "--out", tmp_path,
                   *[a for s in FAST for a in ("--set", s)])
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == "" and proc.stderr == ""
    assert len(_table(tmp_path / "sweep.csv")) == 1


@pytest.mark.mpi
def test_lumped_sweep_table_is_identical_on_any_number_of_ranks(shared_tmp):
    comm = _world()
    params = [parse_param("lumped.downforce_N=3,9"), parse_param("lumped.free_mass.mass_kg=0.002,0.004")]
    run_sweep(LUMPED, params, shared_tmp / "parallel", FAST, comm=comm, progress=False)
    comm.barrier()
    if comm.rank == 0:
        run_sweep(LUMPED, params, shared_tmp / "serial", FAST, comm=None, progress=False)
        parallel = (shared_tmp / "parallel" / "sweep.csv").read_text()
        serial = (shared_tmp / "serial" / "sweep.csv").read_text()
        assert parallel == serial
        assert len(parallel.strip().splitlines()) == 5
    comm.barrier()


@pytest.mark.mpi
def test_fe_drill_downforce_sweep_over_ranks(shared_tmp):
    """The FE drill at 0 and 9 N: with 2 ranks each runs one point on COMM_SELF, rank 0 gathers; the
    point run elsewhere equals the same point run here."""
    from mpi4py import MPI

    from app.runner import run_case

    comm = _world()
    param = parse_param("transient.loads.fe_force_N=[0.0,0.0],[0.0,-9.0]")
    rows = run_sweep(DRILL, [param], shared_tmp / "sweep", DRILL_TINY, comm=comm, progress=False)
    if comm.rank == 0:
        assert [r["point"] for r in rows] == [0, 1]
        assert {r["_rank"] for r in rows} == set(range(min(comm.size, 2)))
        single = run_case(DRILL, [*DRILL_TINY, "transient.loads.fe_force_N=[0.0, -9.0]"], shared_tmp / "single",
                          comm=MPI.COMM_SELF, quiet=True)["results"]["transient"]
        assert rows[1]["transient.steps"] == single["steps"]
        assert rows[1]["transient.statistics.transducer.max_rise_m"] == pytest.approx(
            single["statistics"]["transducer"]["max_rise_m"], rel=1e-9)
        assert len(_table(shared_tmp / "sweep" / "sweep.csv")) == 2
    else:
        assert rows is None
    comm.barrier()


def test_drill_batch_intervals_are_the_spread_of_the_window_means():
    """The drill scene's 95 % batch-means intervals (app/scenes/percussion_drill batch_intervals): on a
    synthetic 0.2 s series whose stem-rock contact closes 5 + w times in window w of the 10 windows after the
    first tenth (3 rows each at 2 N), the impact rate's half-width is t_{0.975, 9} s / sqrt(10) of the
    per-window rates counted here (exact to round-off: same windows, the count is known), the mean force's
    likewise, and a statistic that does not change (no other contact closes) has a zero interval. A run
    whose windows would be shorter than 10 ms gets none."""
    import numpy as np
    from scipy import stats as sps

    from app import series as S
    from app.case.schema import load_case
    from app.scenes.percussion_drill import BATCHES, batch_intervals

    cfg = load_case(DRILL).transient
    dt, n = 1e-5, 20000
    t = dt * np.arange(1, n + 1)
    closed = np.zeros(n)
    edges = np.linspace(t[0] + 0.1 * (t[-1] - t[0]), t[-1], BATCHES + 1)
    rates, forces = [], []
    for w, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        rows = np.flatnonzero((t > lo) & (t <= hi))
        for k in range(5 + w):
            closed[rows[10 + 20 * k: 13 + 20 * k]] = 1.0
        duration = rows.size * dt
        rates.append((5 + w) / duration)
        forces.append(2.0 * 3 * dt * (5 + w) / duration)
    data = {S.TIME: t, S.STEP: np.full(n, dt)}
    for c in cfg.contacts:
        data[S.contact_closed(c.name)] = closed if c.name == "stem_rock" else np.zeros(n)
        data[S.contact_force(c.name)] = np.zeros((n, 2))
    data[S.contact_force("stem_rock")][:, 1] = 2.0 * closed
    for body in ("ball", "stem"):
        data[S.body_position(body)] = np.zeros((n, 2))
        data[S.body_velocity(body)] = np.zeros((n, 2))
    out = batch_intervals(data, cfg)
    t_crit = sps.t.ppf(0.975, BATCHES - 1)
    assert out["impact_rate_per_s"]["stem_rock"] == pytest.approx(
        t_crit * np.std(rates, ddof=1) / np.sqrt(BATCHES), rel=1e-12)
    assert out["stem_rock_foundation"]["mean_force_N"] == pytest.approx(
        t_crit * np.std(forces, ddof=1) / np.sqrt(BATCHES), rel=1e-9)
    assert out["impact_rate_per_s"]["tip_ball"] == 0.0
    short = {name: array[: n // 2] for name, array in data.items()}       # 0.1 s: windows of 9 ms
    assert batch_intervals(short, cfg) == {}


def test_lumped_batch_intervals_count_the_events_per_window():
    """The lumped tier's batch-means intervals (from its exact event table): stem-rock closings 5 + w in window
    w of a 0.2 s run, each followed by an opening carrying 1e-3 N s; the rate's and the mean force's half-widths
    are t_{0.975, 9} s / sqrt(10) of the per-window values counted here; no tip-ball event: zero."""
    import numpy as np
    from scipy import stats as sps

    from app.lumped import kernel as K
    from app.scenes.percussion_drill import BATCHES, lumped_batch_intervals

    duration = 0.2
    edges = np.linspace(0.1 * duration, duration, BATCHES + 1)
    rows, rates, forces = [], [], []
    for w, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        for k in range(5 + w):
            t = lo + (k + 0.5) * (hi - lo) / 20
            for closing, impulse in ((1.0, 0.0), (0.0, 1e-3)):
                row = np.zeros(8)
                row[[K.EV_TIME, K.EV_CONTACT, K.EV_CLOSING, K.EV_IMPULSE]] = t + 1e-6 * (1 - closing), 2, closing, \
                    impulse
                rows.append(row)
        rates.append((5 + w) / (hi - lo))
        forces.append((5 + w) * 1e-3 / (hi - lo))
    out = lumped_batch_intervals(np.array(rows), duration)
    half = sps.t.ppf(0.975, BATCHES - 1) / np.sqrt(BATCHES)
    assert out["impact_rate_per_s"]["stem_rock"] == pytest.approx(half * np.std(rates, ddof=1), rel=1e-12)
    assert out["stem_rock_foundation"]["mean_force_N"] == pytest.approx(half * np.std(forces, ddof=1), rel=1e-12)
    assert out["impact_rate_per_s"]["tip_ball"] == 0.0
    assert lumped_batch_intervals(np.array(rows), 0.1) == {}          # windows of 9 ms: too short
