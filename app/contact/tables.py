"""Per-site diagnostics as tables of the series file, the same in every tier (``output.contact_sites``).

Each engine integrates, per contact site and over the accepted steps, the pressure and the time the site is
closed, sticking, or slipping along +e1 / -e1 of its frame (app/contact/law.py's rule) into ``sums``; at every
output interval a row per quantity is appended (its mean over the interval), and once per run the sites'
geometry. Names: app/series.py ``sites_table``."""

from __future__ import annotations

import numpy as np

from app import series as S

QUANTITIES = ((0, "pressure", "Pa"), (1, "closed", "1"), (2, "stick", "1"), (3, "slip_positive", "1"),
              (4, "slip_negative", "1"))


class SiteTables:
    """``contacts``: (name, mask of its sites) of every sampled surface contact; ``interval_s``: the rows'
    spacing [s]."""

    def __init__(self, contacts: list[tuple[str, np.ndarray]], n_sites: int, interval_s: float):
        self.contacts = contacts
        self.sums = np.zeros((n_sites, 5))
        self.interval_s = float(interval_s)
        self.next_s = self.interval_s
        self.started_s = 0.0
        self.pending: dict[str, tuple[str, np.ndarray]] = {}

    def geometry(self, points: np.ndarray, weight: np.ndarray) -> None:
        """Once per run: each contact's sites, x y z [m] and area [m^2]."""
        for name, mine in self.contacts:
            self._append(S.sites_table(name, "geometry"), "m, m, m, m^2",
                         np.column_stack([points[mine], weight[mine]]))

    def due(self, t: float) -> bool:
        return t >= self.next_s * (1 - 1e-12)

    def row(self, t: float) -> None:
        """Close the interval at time t: the means since the last row."""
        duration = t - self.started_s
        if duration > 0:
            for name, mine in self.contacts:
                means = self.sums[mine] / duration
                self._append(S.sites_table(name, "time"), "s", np.array([[self.started_s, t]]))
                for col, key, unit in QUANTITIES:
                    self._append(S.sites_table(name, key), unit, means[:, col].reshape(1, -1))
        self.sums[:] = 0.0
        self.started_s = t
        while self.next_s <= t * (1 + 1e-12):
            self.next_s += self.interval_s

    def _append(self, name: str, unit: str, rows: np.ndarray) -> None:
        if name in self.pending:
            unit0, old = self.pending[name]
            self.pending[name] = (unit0, np.vstack([old, rows]))
        else:
            self.pending[name] = (unit, rows)

    def take(self) -> dict:
        out, self.pending = self.pending, {}
        return out

    def snapshot(self) -> tuple[dict, dict]:
        return {"site_sums": self.sums}, {"next_sites_s": self.next_s, "sites_started_s": self.started_s}

    def restore(self, arrays: dict, record: dict) -> None:
        self.sums[:] = arrays["site_sums"]
        self.next_s = float(record["next_sites_s"])
        self.started_s = float(record["sites_started_s"])
