"""The lumped tier in memory: simulate a ``[lumped]`` section and report, writing nothing (benches and tests
that want the arrays). ``piezodyn run`` runs the tier through the one run loop instead
(app/lumped/engine.py), with the same numbers."""

from __future__ import annotations

import time

from app.case.lumped import LumpedSection
from app.lumped.parameters import derive_parameters
from app.lumped.simulate import SimulationResult, initial_state_from_section, simulate
from app.lumped.stats import run_statistics


def solver_report(step_s: float, unit_s: float, counters: dict, wall_setup_s: float, wall_integrate_s: float,
                  wall_total_s: float, simulated_s: float) -> dict:
    """``results.solver`` of a lumped run: the lattice, the kernel's counters and wall times [s]."""
    simulated_ms = simulated_s * 1e3
    return {
        "sampling_step_s": step_s,
        "event_time_resolution_s": unit_s,
        **counters,
        "wall_setup_s": wall_setup_s,
        "wall_integrate_s": wall_integrate_s,
        "wall_total_s": wall_total_s,
        "integrate_wall_s_per_simulated_ms": wall_integrate_s / simulated_ms if simulated_ms > 0 else None,
    }


def compute(section: LumpedSection) -> tuple[dict, SimulationResult]:
    """Simulate ``section`` and return (results dict, SimulationResult). Writes nothing. The results hold the
    tier's generic keys (``statistics`` without the scene's, e.g. the drill's ``transducer``: those come from
    a written series, app/scenes/)."""
    wall0 = time.perf_counter()
    p = derive_parameters(section)
    result = simulate(p, section.duration_s, initial_state_from_section(p, section.initial),
                      section.output.output_interval_s, section.solver)
    stats = run_statistics(result)
    wall = time.perf_counter() - wall0
    results = {
        "tier": "lumped",
        "simulated_time_s": result.duration_s,
        "wall_s_per_simulated_ms": wall / (result.duration_s * 1e3),
        "cutbacks": 0,                      # exact propagation between events: no step to cut back
        "parameters": p.to_report(),
        "statistics": stats,
        "energy_ledger": result.energy_balance(),
        "solver": solver_report(result.step_s, result.lattice_unit_s, result.counters, result.wall_s["setup"],
                                result.wall_s["integrate"], wall, result.duration_s),
    }
    return results, result
