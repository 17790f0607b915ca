"""The steady-state rules of ``[transient.steady_state]`` (app/loop/steady.py) on cycle-mean series.

References: the documented behaviour of the motor (docs/motor-studies.md, "Plateaus and the steady-state test":
from rest the no-load point holds a plateau at 45.7 rpm from period 174 for about 270 periods, drifting 0.1 %
per 60 periods, then climbs to 50.5 rpm within 100 periods and stays), two cycle-mean series recorded on the
tests' coarse stator (tests/data/motor-coarse-*-cycle-means.txt, their commands in their headers: an approach
from rest, and a chained point that falls to a minimum and climbs again), and exponential approaches whose final
value is known in closed form. The rules see only the cycle means, so a series stands for
a run; the watch (which integrates the means from the steps) is checked on its own below, including a snapshot
and restore in the middle of a run.

Tolerances: the issue's 0.5 % on the value a stopped point reports (the mean of the last ``window_cycles``
periods, as app/scenes/wwusm_motor reports it) against the series' final value.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from app.loop.steady import ORBIT_GROWTH, SteadyStateWatch, return_growth, stop_period

WINDOW, TOLERANCE, MIN_CYCLES = 20, 0.005, 40        # the shipped case's keys (cases/wwusm-motor.toml)
OLD_MINIMUM = 500                                      # the curve benches' former min_cycles (BENCHMARKS.md)
RECORDED = Path(__file__).parent / "data" / "motor-coarse-rest-cycle-means.txt"
TURNING = Path(__file__).parent / "data" / "motor-coarse-chained-turning-cycle-means.txt"
PLATEAU = Path(__file__).parent / "data" / "motor-pinned-rest-plateau-means-returns.txt"
PLATEAU_FLOOR = 0.3523500430316455   # that run's speed floor [rad/s] (the scene's default, in the file's header)
PERIODS = np.arange(1, 1301, dtype=float)


def first_stop(rule, means, min_cycles=MIN_CYCLES, returns=None) -> int | None:
    """The number of closed periods after which a run stops under ``rule`` (None: not within the series);
    ``returns``: the relative returns per period (rule "orbit")."""
    return stop_period(rule, list(means), WINDOW, TOLERANCE, min_cycles, returns=returns)


def reported(means, n) -> float:
    """What a point stopped after period n reports: the mean of its last WINDOW cycle means."""
    return float(np.mean(means[n - WINDOW:n]))


def plateau_then_rise(drift_per_60_periods=0.001, noise=0.0, seed=0) -> np.ndarray:
    """The no-load point of docs/motor-studies.md: an approach from rest (time constant 35 periods) to a 45.7 rpm
    plateau that drifts ``drift_per_60_periods`` (relative) per 60 periods, a rise to 50.5 rpm centred on period
    490 (over about 100 periods), then steady; cycle-to-cycle noise of relative size ``noise``."""
    k = PERIODS
    rise = 1 / (1 + np.exp(-(k - 490) / 15))
    plateau = 45.7 * (1 - np.exp(-k / 35)) + 45.7 * drift_per_60_periods / 60 * k
    rpm = plateau * (1 - rise) + 50.5 * rise
    return rpm * (1 + noise * np.random.default_rng(seed).standard_normal(k.size))


@pytest.mark.parametrize("noise", [0.0, 3e-4, 1e-3])
def test_a_plateau_that_drifts_stops_the_window_rule_not_the_trend_rule(noise):
    """The point that plateaus and then drifts: the window rule stops on the plateau, about 10 % below the final
    speed (as the motor did: 45.7 against 50.5 rpm); the trend rule runs through the plateau and the rise and
    stops within 0.5 % of 50.5 rpm. Measured: window at period 177-189 (-10.0 to -9.8 %), trend at 1065-1081
    (within 0.04 %), with cycle-to-cycle noise up to 0.1 % (the fit's drift is then noisier). Breaking the
    rule's separation of decay and drift (tau up to half the span instead of a quarter) stops it at 267 on the
    plateau with 0.1 % noise (measured)."""
    means = plateau_then_rise(noise=noise)
    final = 50.5
    window = first_stop("window", means)
    assert window is not None and window < 440                    # on the plateau (it ends near period 440)
    assert reported(means, window) < 0.92 * final
    trend = first_stop("trend", means)
    assert trend is not None and trend > 560                      # not before the rise has ended
    assert abs(reported(means, trend) / final - 1) < TOLERANCE


def test_the_trend_rule_holds_plateaus_down_to_a_drift_it_can_see():
    """Its limit, stated in app/loop/steady.py: a plateau drifting 0.05 % per 60 periods still holds the run
    (measured: stop at 1065, after the rise), one drifting 0.04 % per 60 periods does not (stop at 319, on the
    plateau): below that rate, 3 n s stays within the tolerance over the plateau's length. With a horizon of
    2 n instead of 3 n the 0.05 % plateau stops the rule at period 311 (measured): this test fails."""
    held = plateau_then_rise(drift_per_60_periods=0.0005)
    assert abs(reported(held, first_stop("trend", held)) / 50.5 - 1) < TOLERANCE
    fooled = plateau_then_rise(drift_per_60_periods=0.0004)
    assert reported(fooled, first_stop("trend", fooled)) < 0.92 * 50.5


def test_recorded_motor_series_trend_stops_before_500_periods_within_half_a_percent():
    """The free rotor from rest on the coarse stator (1080 periods recorded; final value: the mean of its last 20
    periods, 26.450 rpm, the same to 1e-5 from period 500 on). The window rule stops at period 165, 1.1 % short;
    the 500-period rule at 500 (within 0.002 %); the trend rule at period 372 within 0.02 % (measured)."""
    means = np.loadtxt(RECORDED)
    final = float(np.mean(means[-WINDOW:]))
    assert abs(reported(means, 500) / final - 1) < 1e-4           # the series is steady long before its end
    window = first_stop("window", means)
    assert abs(reported(means, window) / final - 1) > TOLERANCE   # the window rule alone stops early
    trend = first_stop("trend", means)
    assert trend is not None and trend < OLD_MINIMUM
    assert abs(reported(means, trend) / final - 1) < TOLERANCE


def test_recorded_turning_point_does_not_stop_the_trend_rule():
    """The real point that plateaus and then drifts (tests/data/motor-coarse-chained-turning-cycle-means.txt): warm
    from its lighter neighbour, the rotor slows to a minimum of 25.09 rpm near period 160, turns, and climbs to
    26.8-26.9 rpm by period 400. The window rule stops it at period 68, 5.7 % short of the 500-period value; at the
    minimum the fit's drift is nil, and the trend test alone passed there (period 178, 6.9 % short: measured with
    the persistence check removed). Holding the test also at 1/1.1 of the run's age (TREND_PERSISTENCE) rejects the
    turning point: within these 500 periods the trend rule does not stop (measured), so the bench runs such a point
    on (to its end time)."""
    means = np.loadtxt(TURNING)
    final = float(np.mean(means[-WINDOW:]))
    window = first_stop("window", means)
    assert reported(means, window) < 0.95 * final
    trend = first_stop("trend", means)
    assert trend is None or (trend > 400 and abs(reported(means, trend) / final - 1) < TOLERANCE)


@pytest.mark.parametrize("tau", [10.0, 20.0, 40.0])
@pytest.mark.parametrize("noise", [0.0, 1e-3])
def test_exponential_approaches_stop_before_500_periods_within_half_a_percent(tau, noise):
    """m(k) = 10 (1 - 0.95 exp(-k / tau)) (final value 10): the trend rule stops before the 500-period rule for time
    constants up to about 55 periods (it needs about 8 tau: the decay must be resolved by a quarter of the fitted
    half, and the test hold at 1/1.1 of the age too; measured stops at periods 85-336), within 0.5 % (measured:
    0.02-0.08 %); the window rule alone is 0.6-1.0 % short at tau = 40 (measured)."""
    means = 10 * (1 - 0.95 * np.exp(-PERIODS / tau))
    means = means * (1 + noise * np.random.default_rng(int(tau)).standard_normal(means.size))
    trend = first_stop("trend", means)
    assert trend is not None and trend < OLD_MINIMUM
    assert abs(reported(means, trend) / 10 - 1) < TOLERANCE


def test_slow_approach_the_500_period_rule_misses_and_the_trend_rule_waits_for():
    """tau = 120 periods: at period 500 the approach still lacks 0.95 exp(-500/120) = 1.5 %, so the 500-period rule
    stops 1.6 % short (measured); the trend rule waits (period 1005, measured) and ends within 0.03 %."""
    means = 10 * (1 - 0.95 * np.exp(-PERIODS / 120))
    old = first_stop("window", means, OLD_MINIMUM)
    assert abs(reported(means, old) / 10 - 1) > 2 * TOLERANCE
    trend = first_stop("trend", means)
    assert trend is not None and abs(reported(means, trend) / 10 - 1) < TOLERANCE


def test_a_steady_but_noisy_series_stops_at_once():
    """A constant with 0.1 % cycle-to-cycle noise is steady: the trend rule does not mistake the noise's slope for a
    drift (its slope error over the fitted half, times 3 n, is below the tolerance: measured stop at period 47,
    the window rule at 40)."""
    means = 10 * (1 + 1e-3 * np.random.default_rng(3).standard_normal(300))
    assert first_stop("trend", means) < 60


def test_recorded_plateau_then_drift_stops_the_trend_rule_on_it_and_the_orbit_rule_after_it():
    """The pinned stator's no-load point from rest (tests/data/motor-pinned-rest-plateau-means-returns.txt, 720
    periods): the speed levels off at 46.06 rpm from about period 250, then climbs to 50.5 rpm between periods 400
    and 580 and stays. The stator's state tells what the speed does not: its relative return falls to 4e-4 at period
    161, then grows about 1.5x per 20 periods through the plateau (the orbit the rotor sits on is unstable) and
    levels off near 0.26 (the state it settles into is not periodic in the drive period).
    Measured: the trend rule stops at period 268, 8.9 % short of the final value (the mean of the last 20 periods,
    50.54 rpm); the 500-period window rule at 577, 50.48 rpm; the orbit rule at 611, 50.66 rpm (+0.24 % from the final
    value, +0.35 % from the 500-period rule's). Tolerance: the issue's 0.5 %. Without the returns (the orbit rule
    made the trend rule) it stops at 268: this test fails; counting the trend fit from the run's start instead of
    from where the state stopped leaving the orbit, it does not stop within the 720 periods: this test fails."""
    data = np.loadtxt(PLATEAU)
    means, returns = list(data[:, 0]), [None if math.isnan(r) else float(r) for r in data[:, 1]]
    final = float(np.mean(means[-WINDOW:]))

    def stop(rule, min_cycles=MIN_CYCLES):
        return stop_period(rule, means, WINDOW, TOLERANCE, min_cycles, PLATEAU_FLOOR, returns=returns)

    trend = stop("trend")
    assert trend is not None and trend < 400 and reported(means, trend) < 0.92 * final     # on the plateau
    growth = return_growth(returns, WINDOW)
    assert np.all(growth[trend - 60:trend] > ORBIT_GROWTH)          # the return grows there
    old = stop("window", OLD_MINIMUM)
    orbit = stop("orbit")
    assert orbit is not None and orbit > 560                        # after the climb
    assert abs(reported(means, orbit) / final - 1) < TOLERANCE
    assert abs(reported(means, orbit) / reported(means, old) - 1) < TOLERANCE


@pytest.mark.parametrize("tau", [10.0, 40.0])
def test_the_orbit_rule_on_an_approach_stops_where_the_trend_rule_does(tau):
    """An exponential approach (time constant tau periods) whose state returns closer every period (returns decaying
    with the same time constant, and 3 % noise on them): the state never leaves an orbit, so the orbit rule is the
    trend rule on the whole run and stops at the same period."""
    means = list(10 * (1 - 0.95 * np.exp(-PERIODS / tau)))
    noise = 1 + 0.03 * np.random.default_rng(7).standard_normal(PERIODS.size)
    returns = list(0.5 * np.exp(-PERIODS / tau) * noise)
    assert first_stop("orbit", means, returns=returns) == first_stop("trend", means)


def test_the_orbit_rule_stops_on_a_settled_state_that_is_not_periodic_and_never_without_returns():
    """A speed settled to 0.1 % noise whose state returns only to 26 % (the pinned no-load point after its climb),
    the returns scattering 3 % about that level: not leaving an orbit, so the rule stops (measured: at period 43, as
    the trend rule). A run whose returns are unknown (steps that do not end on the period ends) never stops."""
    rng = np.random.default_rng(11)
    means = list(10 * (1 + 1e-3 * rng.standard_normal(300)))
    returns = list(0.26 * (1 + 0.03 * rng.standard_normal(300)))
    assert first_stop("orbit", means, returns=returns) < 60
    assert first_stop("orbit", means, returns=[None] * 300) is None


def _samples(omega_of_t, periods, steps_per_period=40, frequency_Hz=1000.0):
    """(t, speed, torque) of accepted steps over ``periods`` drive periods."""
    dt = 1 / (frequency_Hz * steps_per_period)
    for i in range(1, periods * steps_per_period + 1):
        t = i * dt
        yield t, omega_of_t(t), 0.0


@pytest.mark.parametrize("rule", ["window", "trend", "orbit"])
def test_watch_restored_from_a_snapshot_decides_as_the_uninterrupted_one(rule):
    """The watch's snapshot (what the checkpoint stores) restored into a new watch, which then sees the rest of the
    steps, stops at the same step with the same means and results as the watch that saw every step (the decision
    is a function of the closed means; rtol 0: nothing is recomputed differently)."""
    frequency_Hz = 1000.0

    def omega(t):
        k = t * frequency_Hz
        return 5 * (1 - math.exp(-k / 12)) + 0.002 * math.sin(2 * math.pi * 7.3 * t)

    def watch():
        return SteadyStateWatch("rotor", "w", [], True, frequency_Hz, WINDOW, TOLERANCE, MIN_CYCLES, rule=rule)

    def state(t):
        """The engine's state after the step at t: a drive-period oscillation approaching its orbit."""
        k = t * frequency_Hz
        return lambda: np.array([math.cos(2 * math.pi * k), math.sin(2 * math.pi * k)]) * (1 + 0.5 * math.exp(-k / 12))

    samples = list(_samples(omega, 400))
    whole = watch()
    stop = next(i for i, s in enumerate(samples) if whole.update(*s, state(s[0])))
    split = stop // 2
    first = watch()
    for s in samples[:split]:
        first.update(*s, state(s[0]))
    second = watch()
    second.restore(first.snapshot())
    resumed_stop = next(i for i, s in enumerate(samples[split:], split) if second.update(*s, state(s[0])))
    assert resumed_stop == stop
    assert second.results() == whole.results()
    assert whole.results()["rule"] == rule
    if rule in ("trend", "orbit"):
        assert whole.results()["trend"]["remaining"] <= TOLERANCE * 5
    # the returns of the closed periods (the first, [T, 2T), after the one entered late), in closed form: the period
    # ending at b T returns |x(b T) - x((b - 1) T)| / |x(b T)|
    returns = whole.results()["period_returns"]
    b = np.arange(2, len(returns) + 2)
    size = 1 + 0.5 * np.exp(-b / 12)
    expected = 0.5 * (np.exp(-(b - 1) / 12) - np.exp(-b / 12)) / size
    np.testing.assert_allclose(returns, expected, rtol=1e-8)
    if rule == "orbit":
        assert whole.results()["orbit"]["held_since_period"] == 0


def test_unknown_rule_is_refused_by_the_watch():
    with pytest.raises(ValueError, match="rule"):
        SteadyStateWatch("rotor", "w", [], True, 1000.0, WINDOW, TOLERANCE, MIN_CYCLES, rule="fit")


def test_a_period_end_a_round_off_short_still_closes_the_period_and_gives_its_return():
    """A clock summed step by step lands a round-off short of a period's end: the step at (1 - 1e-11) of it (within
    PERIOD_END_TOLERANCE, 1e-9 of a period, up to period 100) closes the period and gives the state there, so every
    return is known, as with exact times. With the former closing test (1e-12 relative) such a step left every
    return unknown and the orbit rule would never stop (measured: this test fails with it)."""
    frequency_Hz = 1000.0
    watch = SteadyStateWatch("rotor", "w", [], True, frequency_Hz, WINDOW, TOLERANCE, MIN_CYCLES, rule="orbit")
    for t, speed, torque in _samples(lambda t: 5.0, 60):
        t_short = t * (1 - 1e-11)
        k = t_short * frequency_Hz
        watch.update(t_short, speed, torque, lambda k=k: np.array([math.cos(2 * math.pi * k), 1 + math.exp(-k)]))
    returns = watch.results()["period_returns"]
    assert len(returns) == 59 and all(r is not None for r in returns)
    assert watch.results()["orbit"]["unknown_returns"] == 0
