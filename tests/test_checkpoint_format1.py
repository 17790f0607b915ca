"""Checkpoints written before the one run loop (format 1, app/loop/checkpoint.py): an FE-tier checkpoint is read
and continued, a modal-tier one is refused with one line.

The data (tests/data/format1-*) are runs of the program at commit 256f258 (the last before the loop): the FE and
modal drill on the tiny mesh to 0.1 ms, checkpointed at the end. ``format1-fe-drill-continued.npz`` holds the
rows that program wrote when it resumed its own checkpoint to 0.2 ms. The resumed FE run here must write the
same rows: the state, step size and controller come from the record; the only difference is the order of
floating-point operations of the later active-set Newton (issue 26), measured at 3e-13 of each column's largest
value over the 414 continued steps (impacts included), so 1e-10 of it."""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest
from conftest import CASES, ROOT, run_cli

DATA = ROOT / "tests" / "data"
TINY = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
        "output.fields=false", "output.plots=false", "transient.end_time_s=2e-4"]


def _sets(overrides):
    return [a for o in overrides for a in ("--set", o)]


def test_format1_fe_checkpoint_continues_as_the_program_that_wrote_it(tmp_path):
    out = tmp_path / "fe"
    shutil.copytree(DATA / "format1-fe-drill", out)
    proc = run_cli("run", CASES / "usdc-fe.toml", "--resume", out, "--quiet", *_sets(TINY))
    assert proc.returncode == 0, proc.stderr[-3000:]
    reference = np.load(DATA / "format1-fe-drill-continued.npz")
    with h5py.File(out / "transient.h5", "r") as f:
        t = f["time_s"][:]
        continued = t > 1e-4 * (1 + 1e-12)
        np.testing.assert_array_equal(t[continued], reference["time_s"])     # the same steps
        for name in ("tip_displacement_m", "ball_velocity_m_per_s", "tip_ball_force_N", "stem_rock_force_N"):
            expected = reference[name]
            assert np.abs(f[name][:][continued] - expected).max() <= 1e-10 * np.abs(expected).max(), name


@pytest.mark.parametrize("mpi", [0, 2])
def test_format1_modal_checkpoint_is_refused_with_one_line(tmp_path, mpi):
    out = tmp_path / "modal"
    shutil.copytree(DATA / "format1-modal-drill", out)
    proc = run_cli("run", CASES / "usdc-fe.toml", "--resume", out, "--quiet", *_sets([*TINY, 'tier="modal"']),
                   mpi=mpi)
    assert proc.returncode == 2
    lines = [line for line in proc.stderr.splitlines() if line.startswith("piezodyn: error:")]
    assert len(lines) == 1 and "checkpoint.json: format:" in lines[0] and "Traceback" not in proc.stderr, \
        proc.stderr[-2000:]


def test_resuming_with_another_case_says_so(tmp_path):
    """The drill's directory resumed with the motor case: one line naming the first differing key and saying the
    checkpoint is another case's (not a missing entry of the other tier's checkpoint)."""
    out = tmp_path / "fe"
    shutil.copytree(DATA / "format1-fe-drill", out)
    proc = run_cli("run", CASES / "wwusm-motor.toml", "--resume", out, "--quiet")
    assert proc.returncode == 2
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "a run of another case ('USDC percussion drill" in lines[0], proc.stderr[-2000:]
