"""Per-site diagnostics as tables of the series file, the same in every tier (``output.contact_sites``).

Each engine integrates, per contact site and over the accepted steps, with the one rule of
app/contact/law.py ``accumulate_site``, into ``sums`` (n_sites x 14): the pressure and the time the site is
closed, sticking, or slipping along +e1 / -e1 of its frame; while slipping, the slip speed's parts |s.e1|,
|s.e2| and |s| and the friction power per area along e1 and e2; and the first harmonics at the drive frequency
of the pressure and of the site's normal displacement towards the obstacle. At every output interval a row
per quantity is appended (its mean over the interval; a harmonic's cosine and sine coefficients, p(t) ~
p_c cos(omega t) + p_s sin(omega t)), and once per run the sites' geometry.

*The wave frame*: each site's wave phase at time t is xi = phi - omega t, phi the phase of its normal
displacement's harmonic over the previous interval (so 0 when the crest passes the site, positive while the
crest has yet to come: ahead of the crest in the direction a travelling wave moves); ``bins`` accumulate per
*group* of sites (a ring of a ring-sampled contact, :func:`site_groups`) and per bin of xi (``WAVE_BINS`` per
wavelength, bin 0 centred on the crest) the area, normal force and area closed, sticking and slipping, so that
their row (``wave_frame``) gives the pressure and the contact states against the wave's phase: the mean taken in
the wave's frame, which at fixed angles is flat because the wave moves. Exact in a steady state (the wave's
phase at a site the same in consecutive intervals: choose ``output_interval_s`` a whole number of drive periods);
the first interval has no phase yet and adds no bins. Names: app/series.py ``sites_table``."""

from __future__ import annotations

import math

import numpy as np

from app import series as S

#: (column of ``sums``, table name, unit, factor from the interval's mean to the row's value)
QUANTITIES = ((0, "pressure", "Pa", 1.0), (1, "closed", "1", 1.0), (2, "stick", "1", 1.0),
              (3, "slip_positive", "1", 1.0), (4, "slip_negative", "1", 1.0),
              (5, "slip_speed_e1", "m/s", 1.0), (6, "slip_speed_e2", "m/s", 1.0), (7, "slip_speed", "m/s", 1.0),
              (8, "friction_power_e1", "W/m^2", 1.0), (9, "friction_power_e2", "W/m^2", 1.0),
              (10, "pressure_cos", "Pa", 2.0), (11, "pressure_sin", "Pa", 2.0),
              (12, "normal_displacement_cos", "m", 2.0), (13, "normal_displacement_sin", "m", 2.0))
N_SUMS = 14
#: bins of the wave phase per wavelength (10 degrees each, bin 0 centred on the crest)
WAVE_BINS = 36
#: columns of a ``wave_frame`` row (means over the interval of the area-weighted bin sums)
BIN_COLUMNS = (("area", "m^2"), ("normal_force", "N"), ("closed_area", "m^2"), ("stick_area", "m^2"),
               ("slip_positive_area", "m^2"), ("slip_negative_area", "m^2"), ("slip_speed_e1_area", "m^3/s"),
               ("slip_speed_e2_area", "m^3/s"))


def site_groups(case, contact_index: np.ndarray) -> np.ndarray:
    """Group of each site for the wave-frame bins (``contact_index``: the case's contact index of each site, in
    site order): one group per ring of a contact sampled in rings (``sample_rings``, ring-major sites, app/contact/
    sites.py ``ring_sites``), one group per other contact; numbered contact by contact."""
    contacts = case.transient.contacts
    groups = np.zeros(contact_index.size, np.int64)
    first = 0
    for c in np.unique(contact_index):
        mine = np.nonzero(contact_index == c)[0]
        section = contacts[int(c)]
        if section.kind == "surface" and section.sampling == "ring" and section.sample_rings > 1:
            local = np.arange(mine.size) // section.sample_points
        else:
            local = np.zeros(mine.size, np.int64)
        groups[mine] = first + local
        first += int(local.max()) + 1 if mine.size else 0
    return groups


class SiteTables:
    """``contacts``: (name, mask of its sites) of every sampled surface contact; ``interval_s``: the rows'
    spacing [s]; ``groups``: each site's group of the wave-frame bins (:func:`site_groups`; default one group
    per contact)."""

    def __init__(self, contacts: list[tuple[str, np.ndarray]], n_sites: int, interval_s: float,
                 groups: np.ndarray | None = None):
        self.contacts = contacts
        self.sums = np.zeros((n_sites, N_SUMS))
        if groups is None:
            groups = np.zeros(n_sites, np.int64)
            for k, (_, mine) in enumerate(contacts):
                groups[mine] = k
        self.groups = np.ascontiguousarray(groups, dtype=np.int64)
        n_groups = int(self.groups.max()) + 1 if n_sites else 1
        self.bins = np.zeros((n_groups, WAVE_BINS, len(BIN_COLUMNS)))
        self.phase = np.full(n_sites, np.nan)      # each site's wave phase reference [rad], NaN: none yet
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
        """Close the interval at time t: the means since the last row; the sites' wave phases from its
        displacement harmonics."""
        duration = t - self.started_s
        if duration > 0:
            units = ", ".join(unit for _, unit in BIN_COLUMNS)
            for name, mine in self.contacts:
                means = self.sums[mine] / duration
                self._append(S.sites_table(name, "time"), "s", np.array([[self.started_s, t]]))
                for col, key, unit, factor in QUANTITIES:
                    self._append(S.sites_table(name, key), unit, factor * means[:, col].reshape(1, -1))
                groups = np.unique(self.groups[mine])
                self._append(S.sites_table(name, "wave_frame"), units, self.bins[groups][None] / duration)
            amplitude = np.hypot(self.sums[:, 12], self.sums[:, 13])
            known = amplitude > 0.0
            self.phase[known] = np.arctan2(self.sums[known, 13], self.sums[known, 12])
        self.sums[:] = 0.0
        self.bins[:] = 0.0
        self.started_s = t
        while self.next_s <= t * (1 + 1e-12):
            self.next_s += self.interval_s

    def _append(self, name: str, unit: str, rows: np.ndarray) -> None:
        if name in self.pending:
            unit0, old = self.pending[name]
            self.pending[name] = (unit0, np.concatenate([old, rows]))
        else:
            self.pending[name] = (unit, rows)

    def take(self) -> dict:
        out, self.pending = self.pending, {}
        return out

    def snapshot(self) -> tuple[dict, dict]:
        return ({"site_sums": self.sums, "site_bins": self.bins, "site_phase": self.phase},
                {"next_sites_s": self.next_s, "sites_started_s": self.started_s})

    def restore(self, arrays: dict, record: dict) -> None:
        """A checkpoint's accumulators; one of a version before the slip parts, harmonics and wave frame (5
        columns, no bins) continues with those of its open interval from zero and no wave phases yet."""
        sums = np.asarray(arrays["site_sums"])
        self.sums[:] = 0.0
        self.sums[:, :sums.shape[1]] = sums
        if "site_bins" in arrays:
            self.bins[:] = arrays["site_bins"]
            self.phase[:] = arrays["site_phase"]
        self.next_s = float(record["next_sites_s"])
        self.started_s = float(record["sites_started_s"])


# ------------------------------------------------------------------ reading the tables
def contact_centre_rad(weight: np.ndarray, pressure_cos: np.ndarray, pressure_sin: np.ndarray,
                       displacement_cos: np.ndarray, displacement_sin: np.ndarray) -> float:
    """The pressure-weighted mean wave phase of a contact [rad] (0: the crest; positive: ahead of it in the
    direction the wave travels), the circular mean arg sum_i w_i int p_i exp(i xi_i) dt with xi_i = phi_i - omega t:
    from the sites' first harmonics (arrays over sites, or rows x sites) it is
    arg sum w_i exp(i phi_i) conj(P_i), P = p_cos + i p_sin, exp(i phi) = U / |U| of the displacement's harmonic.
    NaN where no site carries pressure or moves."""
    U = np.asarray(displacement_cos) + 1j * np.asarray(displacement_sin)
    P = np.asarray(pressure_cos) + 1j * np.asarray(pressure_sin)
    unit = np.divide(U, np.abs(U), out=np.zeros_like(U), where=np.abs(U) > 0)
    total = np.sum(weight * unit * np.conj(P))
    return float(np.angle(total)) if abs(total) > 0 else math.nan


def wave_phase_bins_deg() -> np.ndarray:
    """The bins' centres [deg of wave phase], bin 0 on the crest: 0, 10, ..., 350 for ``WAVE_BINS`` = 36."""
    return 360.0 * np.arange(WAVE_BINS) / WAVE_BINS


def wave_frame_centre_rad(bins: np.ndarray) -> float:
    """The pressure-weighted circular mean wave phase [rad] of binned sums (..., WAVE_BINS, columns): the normal
    force per bin times exp(i xi_bin), each bin at its centre (within half a bin of the harmonics' value)."""
    force = np.asarray(bins)[..., 1].reshape(-1, WAVE_BINS).sum(axis=0)
    total = np.sum(force * np.exp(1j * np.radians(wave_phase_bins_deg())))
    return float(np.angle(total)) if abs(total) > 0 else math.nan
