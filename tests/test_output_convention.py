"""One output convention for every tier (app/series.py): the lumped and FE tiers write the same
quantity under the same file, dataset name, ``units`` attribute and summary key, their plots show the
same curves under the same names, and ``piezodyn plot DIR`` redraws either tier's plots."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from conftest import ROOT, run_case_quiet, run_cli

from app import series as S
from app.plots import MOTION_AXIS, time_series_curves

FE_TINY = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
           "transient.end_time_s=1e-4", "transient.output_interval_s=5e-5", "output.fields=false"]
CONTACTS = ("tip_ball", "ball_stem", "stem_rock")
# Vertical force of each drill contact on the body the convention reports it on, for a compressed
# contact: the tip pushes the ball (its rigid body) down, the ball and the stem (upper bodies of the
# links) are pushed up.
PUSH_SIGN = {"tip_ball": -1.0, "ball_stem": 1.0, "stem_rock": 1.0}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The drill in both tiers: a 0.1 ms FE run (coarse mesh) and a 20 ms lumped run."""
    fe_dir, lumped_dir = tmp_path_factory.mktemp("fe"), tmp_path_factory.mktemp("lumped")
    fe = run_case_quiet("usdc-fe.toml", fe_dir, *FE_TINY)["results"]["transient"]
    lumped = run_case_quiet("usdc-lumped.toml", lumped_dir, "lumped.duration_s=0.02")["results"]["lumped"]
    return {"fe": (fe_dir, fe), "lumped": (lumped_dir, lumped)}


def test_tiers_write_the_same_names_units_and_summary_keys(runs):
    series = {tier: S.read_time_series(d / results["time_series"]) for tier, (d, results) in runs.items()}
    shared = {S.TIME, S.STEP, S.point_displacement("tip")}
    for body in ("ball", "stem"):
        shared |= set(S.body_columns(body))
    for contact in CONTACTS:
        shared |= set(S.contact_columns(contact))
    import h5py

    units = {}
    for tier, (directory, results) in runs.items():
        assert results["time_series"] == S.TIME_SERIES_FILE
        assert shared <= set(series[tier]), shared - set(series[tier])
        with h5py.File(directory / S.TIME_SERIES_FILE) as f:
            units[tier] = {name: f[name].attrs[S.UNITS] for name in shared}
            assert all(S.UNITS in f[name].attrs for name in f)        # one spelling, every dataset
    assert units["fe"] == units["lumped"]
    fe, lumped = runs["fe"][1], runs["lumped"][1]
    for key in ("statistics", "simulated_time_s", "wall_s_per_simulated_ms", "cutbacks", "scene", "plot"):
        assert key in fe and key in lumped, key
    assert fe["scene"] == lumped["scene"] == "percussion-drill"
    a, b = fe["statistics"], lumped["statistics"]
    assert set(a["impact_rate_per_s"]) == set(b["impact_rate_per_s"]) == set(CONTACTS)
    assert set(a["stem_rock_foundation"]) <= set(b["stem_rock_foundation"])
    assert set(a["transducer"]) <= set(b["transducer"])
    assert a["bodies"].keys() == b["bodies"].keys() == {"ball", "stem"}
    assert all(a["bodies"][k].keys() == b["bodies"][k].keys() for k in a["bodies"])
    # bench/bench_tiers.py reads both tiers with one function, without mapping names
    spec = importlib.util.spec_from_file_location("bench_tiers", ROOT / "bench" / "bench_tiers.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.row(fe).keys() == bench.row(lumped).keys()


def test_contact_forces_push_the_bodies_apart_in_both_tiers(runs):
    """Against physics, not a stored file: a contact only pushes, so the vertical force on the body
    the convention names has the sign of a push in every row, is zero while the contact is open
    (the lumped tier's exact layer forces), and some impact happened in each tier's window."""
    for tier, (directory, _) in runs.items():
        data = S.read_time_series(directory / S.TIME_SERIES_FILE)
        for contact in CONTACTS:
            vertical = data[S.contact_force(contact)][:, -1] * PUSH_SIGN[contact]
            assert vertical.min() >= 0.0, (tier, contact)
            if tier == "lumped":
                assert np.all(vertical[data[S.contact_closed(contact)] == 0] == 0.0)
        assert max(np.abs(data[S.contact_force(c)]).max() for c in CONTACTS) > 1.0, tier


def test_plots_show_the_same_curves_in_every_tier(runs):
    """FE and lumped plots: the same curve names (drive point, bodies from their start, contacts),
    the same units (mm, N) and the same files."""
    labels = {}
    for tier, (directory, results) in runs.items():
        spec = results["plot"]
        curves = time_series_curves(S.read_time_series(directory / S.TIME_SERIES_FILE), spec["point"],
                                    spec["bodies"], spec["contacts"])
        labels[tier] = {kind: [label for label, _ in c] for kind, c in curves.items()}
        for name in (S.MOTION_PLOT, S.FORCE_PLOT):
            assert (directory / name).stat().st_size > 0 and name in results["plots"]
    assert labels["fe"] == labels["lumped"]
    assert labels["fe"]["motion"] == ["transducer tip", "ball (from its start)", "stem (from its start)"]
    assert labels["fe"]["force"] == list(CONTACTS)
    assert MOTION_AXIS.endswith("[mm]")


def test_plot_dir_redraws_the_lumped_plots(tmp_path):
    out = tmp_path / "lumped"
    run_case_quiet("usdc-lumped-9N.toml", out, "lumped.duration_s=0.05", "lumped.output.plots=false")
    assert not list(out.glob("*.png"))
    proc = run_cli("plot", out)
    assert proc.returncode == 0, proc.stderr
    for name in (S.MOTION_PLOT, S.FORCE_PLOT):
        assert name in proc.stdout and (out / name).stat().st_size > 0
