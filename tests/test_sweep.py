"""``piezodyn sweep``: a grid of lumped runs, unknown parameters rejected, the same table on 1 or 2 ranks.

The ``mpi`` test also runs in the MPI pass (``mpirun -n 2 python3 -m pytest -m mpi``)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from app.errors import CaseError
from app.sweep import main, parse_param, run_sweep

CASE = Path(__file__).resolve().parents[1] / "cases" / "usdc-lumped.toml"
FAST = ["lumped.duration_s=0.004", "lumped.output.plots=false", "lumped.output.write_time_series=false"]


def _world():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def test_sweep_over_two_points_writes_table_and_summaries(tmp_path):
    rows = run_sweep(CASE, [parse_param("lumped.downforce_N=0,9")], tmp_path, FAST, comm=None, progress=False)
    assert [r["lumped.downforce_N"] for r in rows] == [0, 9]
    with open(tmp_path / "sweep.csv") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 2 and table[1]["lumped.downforce_N"] == "9"
    for i in range(2):
        summary = json.loads((tmp_path / f"point_{i:04d}" / "summary.json").read_text())
        assert summary["resolved_case"]["lumped"]["downforce_N"] == [0.0, 9.0][i]
        assert summary["results"]["energy_ledger"]["closure_relative"] < 1e-10
    assert (tmp_path / "sweep_downforce_N.png").exists()


def test_unknown_sweep_parameter_is_a_case_error(tmp_path):
    with pytest.raises(CaseError) as info:
        run_sweep(
            CASE, [parse_param("lumped.free_mass.weight_kg=0.002,0.004")], tmp_path, FAST, progress=False
        )
    assert info.value.key == "lumped.free_mass.weight_kg"
    with pytest.raises(CaseError):
        parse_param("downforce_N=0,3")


def test_sweep_main_exits_2_on_bad_value(tmp_path, capsys):
    code = main(
        [
            str(CASE),
            "--param",
            "lumped.stem.mass_kg=0.04,-1",
            "--out",
            str(tmp_path),
            "--no-progress",
            *[a for s in FAST for a in ("--set", s)],
        ]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if _world().rank == 0:  # only rank 0 prints the one-line message
        assert "lumped.stem.mass_kg" in err


@pytest.mark.mpi
def test_sweep_table_is_identical_on_any_number_of_ranks(tmp_path):
    comm = _world()
    shared = Path(comm.bcast(str(tmp_path), root=0))  # every rank writes into rank 0's directory
    params = [parse_param("lumped.downforce_N=3,9"), parse_param("lumped.free_mass.mass_kg=0.002,0.004")]
    run_sweep(CASE, params, shared / "parallel", FAST, comm=comm, progress=False)
    comm.barrier()
    if comm.rank == 0:
        run_sweep(CASE, params, shared / "serial", FAST, comm=None, progress=False)
        parallel = (shared / "parallel" / "sweep.csv").read_text()
        serial = (shared / "serial" / "sweep.csv").read_text()
        assert parallel == serial
        assert len(parallel.strip().splitlines()) == 5
    comm.barrier()
