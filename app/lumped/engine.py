"""The lumped tier's engine for the run loop (app/loop/loop.py): the drill's lumped model (eqs. 5-16)
propagated exactly by :class:`app.lumped.simulate.LumpedIntegrator`, one row per output interval under the
output convention of every tier (app/lumped/outputs.py), and its event table appended as events occur.

A "step" of this tier is one output interval (one time-series row): ``steps`` counts them,
``[lumped.output] checkpoint_interval_steps`` spaces the checkpoints in them. The model is serial and fast,
so rank 0 integrates and the other ranks receive the rows (the loop writes on rank 0 and tests on every
rank); a checkpoint holds the integrator's state arrays, so a resumed run writes the same bits."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from app.errors import CaseError, NumericalFailure
from app.loop.checkpoint import Found
from app.lumped.driver import solver_report
from app.lumped.outputs import EVENT_UNITS, EVENTS, columns, series_rows
from app.lumped.parameters import derive_parameters
from app.lumped.simulate import (
    LumpedIntegrator,
    energy_balance,
    initial_state_from_section,
    intervals_in,
    state_problem,
)
from app.lumped.stats import contact_summary, statistics
from app.series import read_time_series

#: the most rows one advance() integrates before handing them to the loop (a block of the series file)
BLOCK_ROWS = 20000


class LumpedEngine:
    """The lumped tier as an :class:`app.loop.loop.Engine`."""

    tier = "lumped"

    def __init__(self, case, comm, log, found: Found | None = None):
        self.wall_start = time.perf_counter()
        self.case, self.comm, self.log = case, comm, log
        self.section = section = case.lumped
        self.p = derive_parameters(section)
        self.interval_s = section.output.output_interval_s
        self.end_time_s = intervals_in(section.duration_s, self.interval_s) * self.interval_s
        self.checkpoint_interval_steps = section.output.checkpoint_interval_steps
        self.root = comm.rank == 0
        # rank 0 integrates (serial, well under a second per 200 ms); the others receive its rows
        self.integrator = None
        if self.root:
            initial = initial_state_from_section(self.p, section.initial)
            self.integrator = LumpedIntegrator(self.p, self.interval_s, initial, section.solver)
        self.intervals = 0
        self._first_row = False         # a fresh run's first advance writes the sample at t = 0 too
        self._events: list[np.ndarray] = []

    @classmethod
    def check(cls, case, comm, log) -> None:
        """``validate``: what the run derives from the section before it steps (the SI parameters, the
        sampling step), without stepping."""
        from app.lumped.model import shortest_period_s

        p = derive_parameters(case.lumped)
        period = shortest_period_s(p)
        if not (math.isfinite(period) and period > 0):
            raise CaseError(case.source, "lumped", f"the model's shortest period is {period} s: check the masses "
                                                   "and stiffnesses")

    # ---------------------------------------------------------------- start / restore
    def start(self) -> None:
        self._first_row = True
        self._started()

    def restore(self, found: Found) -> None:
        why = check_state(found.arrays, int(found.engine.get("intervals", -1)))
        if why:
            raise CaseError(str(found.pointer), "engine", f"not a lumped checkpoint of this version: {why}")
        self.intervals = int(found.engine["intervals"])
        if self.root:
            self.integrator.restore(found.arrays)
        self._started()

    def _started(self) -> None:
        s = self.section
        self.log(f"lumped: {self.end_time_s * 1e3:g} ms from t = {self.t * 1e3:g} ms, downforce {s.downforce_N:g} N, "
                 f"output every {self.interval_s * 1e6:g} us")

    @property
    def t(self) -> float:
        """The time of the last sample [s] (whole output intervals, as the run's end and the summary count it)."""
        return self.intervals * self.interval_s

    @property
    def steps(self) -> int:
        return self.intervals

    # ---------------------------------------------------------------- stepping
    def columns(self) -> dict[str, str]:
        return {name: unit for name, (unit, _) in columns().items()}

    def advance(self, t_end: float, max_steps: int, stop_at_s: float) -> dict[str, np.ndarray]:
        n = min(intervals_in(t_end, self.interval_s) - self.intervals, max_steps, BLOCK_ROWS)
        if math.isfinite(stop_at_s):        # the first sample at or after stop_at_s
            n = min(n, max(1, math.ceil(stop_at_s / self.interval_s * (1 - 1e-12)) - self.intervals))
        if n <= 0:
            return {}
        payload = None
        if self.root:
            try:
                payload = self._integrate(n)
            except NumericalFailure as exc:
                payload = exc
        if self.comm.size > 1:
            payload = self.comm.bcast(payload, root=0)
        if isinstance(payload, NumericalFailure):
            raise payload
        rows, events = payload
        self.intervals += n
        self._events.append(events)
        return rows

    def _integrate(self, n: int) -> tuple[dict, np.ndarray]:
        """Rank 0: ``n`` output intervals; their rows (with the sample at t = 0 first on a fresh run's first
        call) and events."""
        integrator = self.integrator
        t_previous = integrator.time_s()
        t, y, mode, events = integrator.advance(n)
        if self._first_row:
            t = np.concatenate([[t_previous], t])
            y = np.concatenate([integrator.initial_y[None, :], y])
            mode = np.concatenate([[integrator.initial_mode], mode])
            self._first_row = False
        return series_rows(t, y, mode, integrator.propagators.force_rows, t_previous), events

    def take_tables(self) -> dict[str, tuple[str, np.ndarray]]:
        # an empty block too: the table exists from the first block on, events or not
        from app.lumped import kernel as K

        events = np.concatenate(self._events) if self._events else np.zeros((0, K.N_EVCOL))
        self._events = []
        return {EVENTS: (EVENT_UNITS, events)}

    # ---------------------------------------------------------------- checkpoints, fields, results
    def snapshot(self) -> tuple[dict | None, dict]:
        arrays = self.integrator.state_arrays() if self.root else None
        return arrays, {"intervals": self.intervals}

    def checkpoint_files(self, out_dir: Path) -> dict[str, str]:
        return {}

    def field_export(self, out_dir: Path, resume_from_s: float | None):
        """``[lumped.output] bodies_interval_s``: the bodies drawn with shapes (app/lumped/bodies.py), else None."""
        interval = self.section.output.bodies_interval_s
        if interval is None:
            return None
        from app.lumped.bodies import body_meshes
        from app.transient.fields import BodySeriesExport

        return BodySeriesExport(Path(out_dir) / "transient_bodies.xdmf", lambda: body_meshes(self.section), interval,
                                self.comm, resume_from_s)

    def body_positions(self) -> np.ndarray:
        """The drawn bodies' packed coordinates at the current sample (rank 0; app/lumped/bodies.py)."""
        from app.lumped.bodies import body_coordinates

        return body_coordinates(self.section, self.integrator.y) if self.root else np.zeros(0)

    def results(self) -> dict:
        out = None
        if self.root:
            ig = self.integrator
            balance = energy_balance(self.p, ig.ledger_J, ig.initial_y, ig.y)
            out = {"cutbacks": 0,                      # exact propagation between events: no step to cut back
                   "parameters": self.p.to_report(),
                   "energy_ledger": balance,
                   "solver": solver_report(ig.step_s, ig.unit_s, ig.counters, ig.wall_setup_s, ig.wall_integrate_s,
                                           time.perf_counter() - self.wall_start, self.t)}
        if self.comm.size > 1:
            out = self.comm.bcast(out, root=0)
        solver = out["solver"]
        self.log(f"lumped: {solver['events']} contact events, {solver['zeno_holds']} Zeno holds, ledger closure "
                 f"{out['energy_ledger']['closure_relative']:.1e}")
        return out

    def statistics(self, h5_path: Path) -> tuple[dict, dict]:
        """Rank 0: the per-contact summary and the generic statistics of the whole run (a resumed one too:
        the series from the file, the ledger and impulses from the integrator's state)."""
        data = read_time_series(h5_path)
        events = data[EVENTS]
        ig = self.integrator
        return (contact_summary(data, events, ig.impulse_total_N_s, self.t),
                statistics(data, events, self.p, ig.ledger_J, ig.impulse_total_N_s, ig.initial_y, ig.y, self.t))

    def close(self) -> None:
        self.integrator = None


def check_state(arrays: dict, intervals: int) -> str | None:
    """Why checkpoint arrays cannot continue a lumped run (None: they can): the integrator's arrays with their
    shapes, and the interval count the record names."""
    why = state_problem(arrays)
    if why is None and (intervals < 0 or int(arrays["counts"][0]) != intervals):
        why = f"the record's interval count {intervals} does not match its state's {int(arrays['counts'][0])}"
    return why
