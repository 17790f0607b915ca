"""Steady-state stop of a transient run (``[transient.steady_state]``): a rotor turns steadily once
the mean of its angular velocity over one drive period (its "cycle mean") stops changing.

:class:`SteadyStateWatch` integrates, per drive period [k T, (k + 1) T) (T = 1 / f_drive, k
counted from t = 0; the period of the run's first step, entered late, is left out), the watched
body's first angular velocity [rad/s] and the torque of its surface contacts about that axis [N m]
with the trapezoidal rule over the accepted steps (a step
that crosses a period boundary is split there by linear interpolation), so the means do not depend
on whether the steps fit the period. The watched quantity is the speed for a free rotation and the
contact (friction) torque for a prescribed or held one. After period n closes the run is steady
when n >= min_cycles and the last window_cycles + 1 cycle means (window_cycles periods apart at
the ends) lie within relative_tolerance of each other:

    0 < max |mean|  and  max - min <= relative_tolerance * max |mean|

(a window of zero means is not steady: a held rotor thrown off the stator by the wave's crests carries
no torque during its flight, then lands again).

The range over the window rather than the change between its ends, so a cycle mean oscillating
about a level (a beat between modes) is not mistaken for steady. Everything the test needs (the
open period's partial integrals and every closed period's means) is in :meth:`snapshot`, which the
stepper puts into the checkpoint: a resumed run decides exactly as the uninterrupted one.

Three rules (``rule``), on the closed cycle means (and, "orbit", the structure's state at the period ends), so a
resumed run decides as an uninterrupted one:

* ``"window"`` (:func:`window_is_steady`): the window test above. A plateau that drifts slowly (0.1 % per 60
  periods, docs/motor-studies.md "Plateaus") passes it, so the curve benches used to add a 500-period minimum.
* ``"trend"`` (:func:`trend_is_steady`): the window test, and the slow dynamics fitted over the latter half of the
  run, an exponential approach with a drift, ``m(k) = m_inf + B exp(-(k - k_last) / tau) + s (k - k_last)``
  (tau on a geometric grid from half a period to a quarter of the fitted span, the three linear coefficients by least
  squares for each tau, the best fit kept). The run is steady when the change still to come, ``|m_inf - w| +
  |s| H`` (w the steady window's mean; the drift continued over three times the run's age, H = 3 n), is within
  the tolerance. The decays fitted are those the span resolves (tau up to a quarter of it); a slower change is
  fitted as the drift, which keeps decay and drift apart. A plateau drifting at rate s holds the run while
  ``3 n s`` exceeds the tolerance, and since n grows a drift that goes on never passes: measured on synthetic
  series shaped like the motor's (tests/test_steady_rules.py), the documented plateau (0.1 % per 60 periods)
  and plateaus down to 0.05 % per 60 periods hold it, also under 0.1 % cycle-to-cycle noise. A second rise in
  the fitted span bends the fit the same way. At a turning point (a decay meeting a slower rise) the drift is
  nil for a moment, so the test must also have held when the run was 1/1.1 of its age (a recorded chained motor
  point fell to 25.09 rpm and climbed to 26.9 rpm: without this the rule stopped on the minimum). Fitting costs
  about a millisecond per period and runs only once the window test has passed.
* ``"orbit"`` (:func:`orbit_rule_is_steady`, the modal tier): the structure's state too. At each period end the
  engine's ``period_state`` is taken and the period's relative return ``|x(bT) - x((b-1)T)| / |x(bT)|`` recorded
  (:meth:`SteadyStateWatch._period_state`). A run whose returns grow over the window (by more than ORBIT_GROWTH) is
  leaving a periodic orbit: not steady, however flat its speed (the pinned motor's no-load plateau: the returns
  grow 1.5x per 20 periods through it, tests/data/motor-pinned-rest-plateau-means-returns.txt). Otherwise the trend
  rule decides on the cycle means since the run last was leaving one.
  docs/transient.md, "Steady-state stop", has the choices and the measurements.
"""

from __future__ import annotations

import math

import numpy as np


def window_is_steady(means, window_cycles: int, relative_tolerance: float, min_cycles: int,
                     floor: float = 0.0) -> bool:
    """The steady-state test on a list of cycle means (both tiers use it): at least ``min_cycles`` and
    ``window_cycles`` + 1 means, not all zero, and the last window_cycles + 1 within ``relative_tolerance`` of the
    larger of their largest magnitude and ``floor`` (a scale below which a change counts as noise, e.g. a
    few % of the wave's speed for a rotor near standstill)."""
    if len(means) < max(min_cycles, window_cycles + 1):
        return False
    window = np.asarray(means[-(window_cycles + 1):], dtype=float)
    scale = float(np.max(np.abs(window)))
    # all zero is no steady state: a rotor thrown off the stator carries no torque while it flies
    return bool(scale > 0 and np.ptp(window) <= relative_tolerance * max(scale, floor))


#: the steady-state rules of ``[transient.steady_state]`` (``rule``)
RULES = ("window", "trend", "orbit")
#: a step within this fraction of a period before a period's end closes the period (the run loop stops the engine
#: there, and the orbit rule takes the state there): a clock summed step by step lands a round-off short of it
PERIOD_END_TOLERANCE = 1e-9
#: the orbit rule: the largest growth of the relative return over the window (log-linear fit) that counts as holding
#: an orbit (a saturated, non-periodic state's returns scatter a few % about their level)
ORBIT_GROWTH = 1.1
#: the orbit rule: returns below this are round-off (the fit takes them at this value)
ORBIT_FLOOR = 1e-12
#: the trend rule: share of the closed periods (the latest) its fit spans
TREND_FIT_FRACTION = 0.5
#: the trend rule: a drift is extrapolated over this many times the run's age (closed periods)
TREND_HORIZON = 3.0
#: the trend rule: the decays fitted are those the span resolves, time constants up to the span / this (a slower
#: change is fitted as the drift, and extrapolated as one)
TREND_RESOLVED = 4.0
#: the trend rule: time constants tried, geometric from half a period to span / TREND_RESOLVED
TREND_TAUS = 48
#: the trend rule: the test must hold now and when the run was 1 / (1 + this) of its age (a turning point, where a
#: decay meets a slower rise, passes it for a moment)
TREND_PERSISTENCE = 0.1


def trend_fit(means, age_periods: int, window_cycles: int) -> dict:
    """The trend rule's fit of cycle means ``means`` (the fitted span, oldest first) of a run ``age_periods``
    closed periods old: ``m(k) = m_inf + B exp(-(k - k_last) / tau) + s (k - k_last)``, least squares in
    (m_inf, B, s) for every tau of a geometric grid from half a period to span / TREND_RESOLVED (a decay the
    span resolves; a slower one is fitted as the drift s, which keeps the two apart), the best fit kept.

    Returns ``asymptote`` = m_inf (where the decay goes, the drift aside), ``last`` (the fitted last mean),
    ``decay`` = |B|, ``drift_per_period`` = s, ``horizon_periods`` = TREND_HORIZON * age, ``window_mean`` (of
    the last ``window_cycles`` means: the steady window a scene reports), ``remaining`` = |m_inf -
    window_mean| + |s| * horizon (what the reported mean still lacks: the decay's rest seen from the window,
    and the drift continued over the horizon), ``tau_periods`` and ``rms`` (the residual's)."""
    y = np.asarray(means, dtype=float)
    span = y.size
    horizon = TREND_HORIZON * max(age_periods, span)
    x = np.arange(-(span - 1), 1, dtype=float)          # periods relative to the last mean
    best = None
    for tau in np.geomspace(0.5, max(span / TREND_RESOLVED, 0.5), TREND_TAUS):
        A = np.column_stack([np.ones(span), np.exp(-(x + (span - 1)) / tau), x])  # decay: 1 at the oldest mean
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        residual = float(np.sum((A @ coef - y) ** 2))
        if best is None or residual < best[0] * (1 - 1e-12):
            best = (residual, tau, coef)
    residual, tau, (level, c, drift) = best
    decay = float(c * math.exp(-(span - 1) / tau))      # B: the decaying term at the last mean
    last = float(level) + decay
    window_mean = float(np.mean(y[-window_cycles:]))
    return {"asymptote": float(level), "last": last, "decay": abs(decay), "drift_per_period": float(drift),
            "horizon_periods": horizon, "window_mean": window_mean,
            "remaining": abs(float(level) - window_mean) + abs(float(drift)) * horizon,
            "tau_periods": float(tau), "rms": math.sqrt(residual / span)}


def trend_span(n: int, window_cycles: int) -> int:
    """The trend rule's fitted span after n closed periods: the latest TREND_FIT_FRACTION of them, at least
    window_cycles + 1."""
    return max(window_cycles + 1, int(math.ceil(TREND_FIT_FRACTION * n)))


def trend_is_steady(means, window_cycles: int, relative_tolerance: float, min_cycles: int,
                    floor: float = 0.0) -> bool:
    """The trend rule on a list of cycle means: :func:`window_is_steady`, and :func:`trend_fit` of the latest
    ``TREND_FIT_FRACTION`` of the means (at least ``window_cycles`` + 1 of them) leaves a change still to come
    (``remaining``: the decay's rest from the steady window's mean, and the drift over three times the run's age) within
    ``relative_tolerance`` of the larger of the span's largest magnitude and ``floor``."""
    if not window_is_steady(means, window_cycles, relative_tolerance, min_cycles, floor):
        return False
    span = trend_span(len(means), window_cycles)
    recent = np.asarray(means[-span:], dtype=float)
    scale = max(float(np.max(np.abs(recent))), floor)
    return trend_fit(recent, len(means), window_cycles)["remaining"] <= relative_tolerance * scale


def trend_rule_is_steady(means, window_cycles: int, relative_tolerance: float, min_cycles: int,
                         floor: float = 0.0) -> bool:
    """The trend rule after a period closes, n = len(means): :func:`trend_is_steady` holds now and held when the run
    was n / (1 + TREND_PERSISTENCE) periods old (a turning point, where a decay meets a slower rise, passes the
    test for a moment only). A function of the means (nothing else to checkpoint)."""
    if not trend_is_steady(means, window_cycles, relative_tolerance, min_cycles, floor):
        return False
    earlier = int(math.floor(len(means) / (1 + TREND_PERSISTENCE)))
    return trend_is_steady(means[:earlier], window_cycles, relative_tolerance, min_cycles, floor)


def return_growth(returns, window_cycles: int) -> np.ndarray:
    """Per closed period k (index k - 1), the growth factor of the relative returns over the window ending there:
    exp(slope x window_cycles), the slope of a least-squares line through log(return) of periods k - window_cycles
    .. k (returns below ORBIT_FLOOR taken at it). NaN where the window is not complete or holds an unknown return."""
    r = np.array([np.nan if x is None else x for x in returns], dtype=float)
    growth = np.full(r.size, np.nan)
    width = window_cycles + 1
    if r.size < width:
        return growth
    x = np.arange(width, dtype=float) - 0.5 * (width - 1)
    slopes = np.correlate(np.log(np.maximum(r, ORBIT_FLOOR)), x, mode="valid") / float(x @ x)
    growth[width - 1:] = np.exp(slopes * window_cycles)
    return growth


def orbit_rule_is_steady(means, returns, window_cycles: int, relative_tolerance: float, min_cycles: int,
                         floor: float = 0.0) -> bool:
    """The orbit rule after period n = len(means) closes, ``returns``: the structure's relative return per closed
    period (None where unknown). The run is leaving a periodic orbit in a period whose window's returns grow by more
    than ORBIT_GROWTH (:func:`return_growth`; an unknown return counts as leaving); steady when it is not leaving
    one now and :func:`trend_rule_is_steady` holds on the cycle means since it last was (the slow dynamics of the
    state it has settled into, its age counted from there)."""
    since = orbit_held_since(returns, window_cycles)
    if since is None:
        return False
    return trend_rule_is_steady(means[since:], window_cycles, relative_tolerance, min_cycles, floor)


def orbit_held_since(returns, window_cycles: int) -> int | None:
    """The index (among the closed periods) of the first period after the last one in which the run was leaving a
    periodic orbit (0: it never was; see :func:`orbit_rule_is_steady`), None if it is leaving one now (or its last
    return is unknown)."""
    return _held_since(return_growth(returns, window_cycles), window_cycles)


def _held_since(growth: np.ndarray, window_cycles: int) -> int | None:
    """:func:`orbit_held_since` from the returns' growth per period (:func:`return_growth`)."""
    holding = growth <= ORBIT_GROWTH
    if not holding.size or not holding[-1]:
        return None
    leaving = ~holding
    leaving[:window_cycles] = False         # no complete window yet: no evidence either way
    return int(np.flatnonzero(leaving)[-1]) + 1 if leaving.any() else 0


def rule_is_steady(rule: str, means, returns, window_cycles: int, relative_tolerance: float, min_cycles: int,
                   floor: float = 0.0) -> bool:
    """The test of ``rule`` (one of RULES) after period n = len(means) closes; ``returns``: the relative returns
    (rule "orbit"; the other rules do not read them)."""
    if rule == "orbit":
        if returns is None:
            raise ValueError("the orbit rule needs the relative returns (returns=...)")
        return orbit_rule_is_steady(means, returns, window_cycles, relative_tolerance, min_cycles, floor)
    test = {"window": window_is_steady, "trend": trend_rule_is_steady}[rule]
    return test(means, window_cycles, relative_tolerance, min_cycles, floor)


def stop_period(rule: str, means, window_cycles: int, relative_tolerance: float, min_cycles: int,
                floor: float = 0.0, returns=None) -> int | None:
    """The number of closed periods after which a run whose cycle means are ``means`` (and, rule "orbit", relative
    returns ``returns``) stops under ``rule``, as :class:`SteadyStateWatch` decides; None: not within them."""
    for n in range(1, len(means) + 1):
        if rule_is_steady(rule, means[:n], None if returns is None else returns[:n], window_cycles,
                          relative_tolerance, min_cycles, floor):
            return n
    return None


class SteadyStateWatch:
    """Cycle means of a rotor's speed and contact torque, and the steady-state test."""

    def __init__(self, body: str, speed_column: str, torque_columns: list[str], free: bool, frequency_Hz: float,
                 window_cycles: int, relative_tolerance: float, min_cycles: int, floor: float = 0.0,
                 rule: str = "window"):
        """``speed_column``: the time-series column of the body's angular velocities (its first axis is watched);
        ``torque_columns``: the torque columns of the contacts acting on the body (their first axis, summed);
        ``free``: watch the speed (else the torque); ``floor``: the scale below which a change of the watched
        quantity counts as noise (rad/s or N m, see :func:`window_is_steady`); ``rule``: one of RULES."""
        if rule not in RULES:
            raise ValueError(f"unknown steady-state rule {rule!r} (rules: {', '.join(RULES)})")
        self.rule = rule
        self.body, self.speed_column, self.torque_columns, self.free = body, speed_column, torque_columns, free
        self.period_s = 1.0 / frequency_Hz
        self.window_cycles, self.relative_tolerance, self.min_cycles = window_cycles, relative_tolerance, min_cycles
        self.floor = float(floor)
        self.cycle = 0                     # index of the open period
        self.integral = np.zeros(2)        # (speed, torque) integrated over the open period so far
        self.last = None                   # (t, speed, torque) of the last sample
        self.means: list[list[float]] = []  # closed periods: [speed mean, torque mean]
        self.steady = False
        self.skip_cycle = -1               # the period the count started in (entered late)
        self.returns: list[float | None] = []   # per closed period: its relative return (see _period_state)
        self.orbit_last = None             # (period end index, the engine's state there as a list)

    def update_block(self, block: dict, state=None) -> bool:
        """Add the accepted steps of a time-series block (rows of ``time_s``, the speed and torque columns);
        True once the run is steady (the rows after the period that made it steady are not looked at).
        ``state``: a callable giving the engine's state after the block's last step (the engine's
        ``period_state``), asked only when that step ends a period."""
        from app import series as S

        t = block[S.TIME]
        speed = np.asarray(block[self.speed_column]).reshape(t.size, -1)[:, 0]
        torque = np.zeros(t.size)
        for name in self.torque_columns:
            torque = torque + np.asarray(block[name]).reshape(t.size, -1)[:, 0]
        for k in range(t.size):
            if self.update(float(t[k]), float(speed[k]), float(torque[k]), state if k == t.size - 1 else None):
                break
        return self.steady

    @property
    def watched(self) -> str:
        return "speed" if self.free else "torque"

    def update(self, t_s: float, speed: float, torque: float, state=None) -> bool:
        """Add an accepted step (its time [s], the watched body's speed [rad/s] and contact torque [N m];
        ``state``: None, or a callable giving the engine's state after this step, see :meth:`update_block`);
        True once the run is steady."""
        t1 = float(t_s)
        y1 = np.array([speed, torque])
        if self.last is None:
            # The first record starts the count (the contact torque of the initial state is not
            # evaluated): the period it falls in is entered late, so its mean is left out.
            self.cycle = int(math.floor(t1 / self.period_s + 1e-9))
            self.skip_cycle = self.cycle
            self.last = (t1, float(y1[0]), float(y1[1]))
            self._period_state(t1, round(t1 / self.period_s), state)
            return self.steady
        t0, y0 = self.last[0], np.array(self.last[1:])
        while True:
            boundary = (self.cycle + 1) * self.period_s
            if t1 < boundary - PERIOD_END_TOLERANCE * self.period_s:
                self.integral += 0.5 * (t1 - t0) * (y0 + y1)
                break
            # close the period at its boundary: interpolate the sample there
            w = (boundary - t0) / (t1 - t0) if t1 > t0 else 1.0
            yb = y0 + min(max(w, 0.0), 1.0) * (y1 - y0)
            self.integral += 0.5 * (boundary - t0) * (y0 + yb)
            returned = self._period_state(t1, self.cycle + 1, state)
            if self.cycle != self.skip_cycle:
                self.means.append((self.integral / self.period_s).tolist())
                self.returns.append(returned)
            self.integral = np.zeros(2)
            self.cycle += 1
            t0, y0 = boundary, yb
            self._test()
        self.last = (t1, float(y1[0]), float(y1[1]))
        return self.steady

    def _period_state(self, t_s: float, boundary: int, state) -> float | None:
        """Take the engine's state at period end ``boundary`` (index: its time is boundary x T) if ``state`` is given
        and ``t_s`` is that time (to PERIOD_END_TOLERANCE of a period, either side); returns the relative return
        ||x(b T) - x((b - 1) T)|| / ||x(b T)|| of the period ending there, None when either state is not known (a
        step that ends past the period's end: the summary counts them, ``orbit.unknown_returns``)."""
        if state is None or abs(t_s - boundary * self.period_s) > PERIOD_END_TOLERANCE * self.period_s:
            return None
        x = np.asarray(state(), dtype=float)
        returned = None
        if self.orbit_last is not None and self.orbit_last[0] == boundary - 1:
            size = float(np.linalg.norm(x))
            if size > 0:
                returned = float(np.linalg.norm(x - np.asarray(self.orbit_last[1])) / size)
        self.orbit_last = (boundary, x.tolist())
        return returned

    def _test(self) -> None:
        if not self.steady:
            column = 0 if self.free else 1
            self.steady = rule_is_steady(self.rule, [m[column] for m in self.means], self.returns,
                                         self.window_cycles, self.relative_tolerance, self.min_cycles, self.floor)

    # ------------------------------------------------------------ checkpoints and results
    def snapshot(self) -> dict:
        return {"cycle": self.cycle, "integral": self.integral.tolist(), "last": list(self.last) if self.last else None,
                "means": [list(m) for m in self.means], "steady": self.steady, "skip_cycle": self.skip_cycle,
                "returns": list(self.returns),
                "orbit_last": [self.orbit_last[0], self.orbit_last[1]] if self.orbit_last is not None else None}

    def restore(self, snap: dict) -> None:
        self.cycle = int(snap["cycle"])
        self.integral = np.asarray(snap["integral"], dtype=float)
        self.last = tuple(snap["last"]) if snap["last"] is not None else None
        self.means = [list(map(float, m)) for m in snap["means"]]
        self.steady = bool(snap["steady"])
        self.skip_cycle = int(snap["skip_cycle"])
        # a checkpoint of a version before the return residuals: none known
        self.returns = [None if r is None else float(r) for r in snap.get("returns", [None] * len(self.means))]
        last = snap.get("orbit_last")
        self.orbit_last = (int(last[0]), [float(v) for v in last[1]]) if last is not None else None

    def results(self) -> dict:
        """The summary.json block: steady or not, closed periods, the last cycle means."""
        last = self.means[-1] if self.means else [None, None]
        column = 0 if self.free else 1
        means = [m[column] for m in self.means]
        out = {"body": self.body, "watched": self.watched, "rule": self.rule, "steady": self.steady,
               "cycles": len(self.means), "window_cycles": self.window_cycles,
               "relative_tolerance": self.relative_tolerance, "min_cycles": self.min_cycles, "floor": self.floor,
               "cycle_mean_speed_rad_per_s": last[0], "cycle_mean_torque_N_m": last[1], "cycle_means": means}
        if any(r is not None for r in self.returns):
            out["period_returns"] = list(self.returns)
        fitted = means
        if self.rule == "orbit":
            # since the state last was leaving a periodic orbit (all of it when it is leaving one at the end)
            growth = return_growth(self.returns, self.window_cycles)
            since = _held_since(growth, self.window_cycles)
            out["orbit"] = {"held_since_period": since,
                            "return_growth": float(growth[-1]) if growth.size and np.isfinite(growth[-1]) else None,
                            "unknown_returns": sum(r is None for r in self.returns)}
            fitted = means[since or 0:]
        if self.rule in ("trend", "orbit") and len(fitted) > self.window_cycles:
            # the last fit (of the periods the stop, or the end, saw): what the rule extrapolated
            span = trend_span(len(fitted), self.window_cycles)
            out["trend"] = {"fit_periods": span, **trend_fit(fitted[-span:], len(fitted), self.window_cycles)}
        return out
