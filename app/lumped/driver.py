"""Entry point the runner calls for ``tier = "lumped"``: simulate, write files, return ``results``."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from app.case.lumped import LumpedSection
from app.errors import NumericalFailure
from app.lumped.outputs import plot_spec, write_time_series
from app.lumped.parameters import derive_parameters
from app.lumped.simulate import initial_state_from_section, simulate
from app.lumped.stats import run_statistics
from app.plots import time_series_outputs
from app.series import TIME_SERIES_FILE


def _rank(comm) -> int:
    return 0 if comm is None else comm.Get_rank()


def compute(section: LumpedSection) -> tuple[dict, object]:
    """Simulate ``section`` and return (results dict, SimulationResult). Writes nothing."""
    wall0 = time.perf_counter()
    p = derive_parameters(section)
    result = simulate(
        p,
        section.duration_s,
        initial_state_from_section(p, section.initial),
        section.output.output_interval_s,
        section.solver,
    )
    balance = result.energy_balance()
    if not all(abs(v) < float("inf") for v in balance.values()):
        raise NumericalFailure(
            "lumped model: the state became non-finite although the propagation is exact; "
            "check the parameters (tried: exact matrix-exponential steps, no step-size control to relax)"
        )
    stats = run_statistics(result)
    wall = time.perf_counter() - wall0
    simulated_ms = result.duration_s * 1e3
    results = {
        "tier": "lumped",
        "simulated_time_s": result.duration_s,
        "wall_s_per_simulated_ms": wall / simulated_ms,
        "cutbacks": 0,                      # exact propagation between events: no step to cut back
        "parameters": p.to_report(),
        "statistics": stats,
        "energy_ledger": balance,
        "solver": {
            "sampling_step_s": result.step_s,
            "event_time_resolution_s": result.lattice_unit_s,
            **result.counters,
            "wall_setup_s": result.wall_s["setup"],
            "wall_integrate_s": result.wall_s["integrate"],
            "wall_total_s": wall,
            "integrate_wall_s_per_simulated_ms": result.wall_s["integrate"] / simulated_ms,
        },
    }
    return results, result


def run(section: LumpedSection, out_dir: Path, comm=None, log: Callable[[str], None] = print,
        name: str = "lumped") -> dict:
    """Run the lumped model on rank 0 (it is serial and takes well under a second per 200 ms);
    other ranks receive the same results dict. Files go to ``out_dir`` (rank 0 only), named as every
    tier's (app/series.py); ``name`` (the case's) titles the plots."""
    out_dir = Path(out_dir)
    results = None
    if _rank(comm) == 0:
        log(f"lumped: {section.duration_s * 1e3:g} ms, downforce {section.downforce_N:g} N")
        results, result = compute(section)
        results["plot"] = plot_spec(section.downforce_N, name)
        out_dir.mkdir(parents=True, exist_ok=True)
        results["outputs"] = []
        if section.output.write_time_series:
            write_time_series(result, out_dir / TIME_SERIES_FILE)
            results["time_series"] = TIME_SERIES_FILE
            results["outputs"].append(TIME_SERIES_FILE)
            if section.output.plots:
                results["plots"] = time_series_outputs(out_dir, results)
                results["outputs"] += results["plots"]
        s = results["statistics"]
        log(
            f"lumped: {result.counters['events']} contact events, "
            f"rock power {s['stem_rock_foundation']['mean_power_W']:.3g} W, "
            f"ledger closure {results['energy_ledger']['closure_relative']:.1e}, "
            f"{results['wall_s_per_simulated_ms'] * 1e3:.3f} ms wall per simulated ms"
        )
    if comm is not None and comm.Get_size() > 1:
        results = comm.bcast(results, root=0)
    return results
