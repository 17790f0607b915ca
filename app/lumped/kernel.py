"""Event-driven exact propagation (numba).

Time lives on an integer lattice: one sampling step h is 2**30 units. A step ("piece") starting at
lattice time T has the size of T's lowest set bit (a full step h on grid points), so every piece
is one cached matrix exponential. Per piece and contact the event function (the gap of an open
contact, the force of a closed one) is checked at both ends together with its slope:

* armed (known > 0 at the piece start) and <= 0 at the end: a crossing; predicate "f <= 0";
* armed, > 0 at both ends but slope < 0 then > 0: an interior minimum; if the cubic Hermite
  interpolant's minimum is not comfortably positive, bisect with "f <= 0 or f' >= 0" and accept
  only if f <= 0 there (a dip through zero: grazing contact);
* disarmed (just switched, value exactly at zero) and < 0 at the end: predicate "f < 0".

Under the assumption that an event function has at most one extremum per piece (the sampling step
is a fraction of the shortest period of any contact state) each predicate is false then true over
the piece, so bisection on the dyadic sub-steps (30 matrix-vector products) finds the first
lattice point where it holds. The state is then advanced there exactly, with the ledger, and the
contact switches. The new state is always on the far side of the root ("after" side), so a layer
that just opened starts with gap exactly 0 and zero slope and cannot re-close spuriously.
"""

from __future__ import annotations

import numpy as np
from numba import njit

LEVELS = 30
UNITS = 1 << LEVELS
N = 14
NOISE_FACTOR = 64.0 * 2.220446049250313e-16

# integer state slots
S_MODE, S_TIME, S_SAMPLES, S_EVENTS, S_ZENO_LOCKS, S_HERMITE_SKIPS, S_BISECTIONS = range(7)
N_ISTATE = 7
# float state slots
F_OFFSET = 0  # 3: gap offsets of open contacts
F_LAST_SWITCH = 3  # 3: time of last switch per contact
F_IMPULSE_OPEN = 6  # 3: impulse since the contact closed
F_LEDGER = 9  # 5: electrical input, c_m loss, layer losses
F_IMPULSE_TOTAL = 14  # 3
N_FSTATE = 17
# per-contact integer flags
C_ARMED, C_LOCKED_UNTIL, C_ZENO_COUNT = range(3)
# event record columns
EV_TIME, EV_CONTACT, EV_CLOSING, EV_REL_VELOCITY, EV_Z, EV_ZDOT, EV_IMPULSE, EV_LAYER_LOSS = range(8)
N_EVCOL = 8
# return status
DONE, SAMPLES_FULL, EVENTS_FULL = 0, 1, 2


@njit(cache=True, inline="always")
def _dot(a, y):
    s = 0.0
    for k in range(N):
        s += a[k] * y[k]
    return s


@njit(cache=True, inline="always")
def _matvec(m, y, out):
    for a in range(N):
        s = 0.0
        for b in range(N):
            s += m[a, b] * y[b]
        out[a] = s


@njit(cache=True, inline="always")
def _quad(w, y):
    s = 0.0
    for a in range(N):
        t = 0.0
        for b in range(N):
            t += w[a, b] * y[b]
        s += y[a] * t
    return s


@njit(cache=True, inline="always")
def _noise(a, y, offset):
    """Round-off level of a . y - offset: values within it have no sign."""
    s = abs(offset)
    for k in range(N):
        s += abs(a[k] * y[k])
    return NOISE_FACTOR * s


@njit(cache=True, inline="always")
def _predicate(kind, f, d, noise):
    if kind == 0:
        return f <= 0.0
    if kind == 1:
        return f <= 0.0 or d >= 0.0
    return f < -noise


@njit(cache=True)
def _hermite_min(f0, d0, f1, d1, h):
    """Minimum over [0, 1] of the cubic Hermite interpolant of (f0, h d0) and (f1, h d1)."""
    m0 = h * d0
    m1 = h * d1
    # H(s) = a s^3 + b s^2 + c s + f0
    a = 2.0 * f0 + m0 - 2.0 * f1 + m1
    b = -3.0 * f0 - 2.0 * m0 + 3.0 * f1 - m1
    c = m0
    best = min(f0, f1)
    qa = 3.0 * a
    qb = 2.0 * b
    if qa == 0.0:
        if qb != 0.0:
            s = -c / qb
            if 0.0 < s < 1.0:
                best = min(best, ((a * s + b) * s + c) * s + f0)
        return best
    disc = qb * qb - 4.0 * qa * c
    if disc < 0.0:
        return best
    r = np.sqrt(disc)
    for s in ((-qb + r) / (2.0 * qa), (-qb - r) / (2.0 * qa)):
        if 0.0 < s < 1.0:
            best = min(best, ((a * s + b) * s + c) * s + f0)
    return best


@njit(cache=True)
def _bisect(expm_mode, value_row, slope_row, offset, level, y0, kind, noise, yl, ym):
    """First lattice offset in (0, 2**(LEVELS-level)] where the predicate holds (it holds at the end).
    Returns (offset_units, f_at_offset)."""
    for k in range(N):
        yl[k] = y0[k]
    pos = 0
    for lv in range(level + 1, LEVELS + 1):
        _matvec(expm_mode[lv], yl, ym)
        f = _dot(value_row, ym) - offset
        d = _dot(slope_row, ym)
        if not _predicate(kind, f, d, noise):
            pos += 1 << (LEVELS - lv)
            for k in range(N):
                yl[k] = ym[k]
    _matvec(expm_mode[LEVELS], yl, ym)
    return pos + 1, _dot(value_row, ym) - offset


@njit(cache=True)
def _advance(expm_mode, ledger_mode, impulse_mode, mode, y, level, units, fstate, ytmp):
    """Advance y in place by ``units`` lattice units (< or = 2**(LEVELS-level)), largest pieces first,
    accumulating the energy ledger and contact impulses exactly."""
    for lv in range(level, LEVELS + 1):
        size = 1 << (LEVELS - lv)
        if units & size:
            for q in range(5):
                fstate[F_LEDGER + q] += _quad(ledger_mode[lv, q], y)
            for i in range(3):
                if (mode >> i) & 1:
                    imp = _dot(impulse_mode[lv, i], y)
                    fstate[F_IMPULSE_OPEN + i] += imp
                    fstate[F_IMPULSE_TOTAL + i] += imp
            _matvec(expm_mode[lv], y, ytmp)
            for k in range(N):
                y[k] = ytmp[k]


@njit(cache=True)
def run_kernel(
    expm,
    ledger,
    impulse,
    event_value,
    event_slope,
    gap_rows,
    force_rows,
    velocity_rows,
    y,
    istate,
    fstate,
    cflags,
    time_end_units,
    sample_every,
    unit_s,
    zeno_window_s,
    zeno_max,
    samples_t,
    samples_y,
    samples_mode,
    events,
):
    """Propagate until lattice time ``time_end_units`` or until an output buffer is full."""
    y1 = np.empty(N)
    yl = np.empty(N)
    ym = np.empty(N)
    ytmp = np.empty(N)
    cand = np.empty(3, dtype=np.int64)
    mode = istate[S_MODE]
    time = istate[S_TIME]
    n_samples = istate[S_SAMPLES]
    n_events = istate[S_EVENTS]
    max_samples = samples_t.shape[0]
    max_events = events.shape[0]
    status = DONE
    while time < time_end_units:
        if n_events + 6 > max_events:
            status = EVENTS_FULL
            break
        low = time & (UNITS - 1)
        if low == 0:
            level = 0
        else:
            tz = 0
            while (low >> tz) & 1 == 0:
                tz += 1
            level = LEVELS - tz
        length = 1 << (LEVELS - level)
        e_mode = expm[mode]
        _matvec(e_mode[level], y, y1)
        best = length + 1
        for i in range(3):
            cand[i] = length + 1
            if cflags[i, C_LOCKED_UNTIL] > time:
                continue
            closed = (mode >> i) & 1
            offset = 0.0 if closed else fstate[F_OFFSET + i]
            f1 = _dot(event_value[mode, i], y1) - offset
            d1 = _dot(event_slope[mode, i], y1)
            kind = -1
            noise = 0.0
            if cflags[i, C_ARMED]:
                if f1 <= 0.0:
                    kind = 0
                elif d1 > 0.0:
                    d0 = _dot(event_slope[mode, i], y)
                    if d0 < 0.0:
                        f0 = _dot(event_value[mode, i], y) - offset
                        hmin = _hermite_min(f0, d0, f1, d1, length * unit_s)
                        # Hermite error is ~(omega h)^4/384 of the oscillation; near the minimum the
                        # function varies by ~(omega h)^2/8 of it, so a minimum above a quarter of
                        # that variation is certainly positive.
                        if hmin <= 0.25 * (max(f0, f1) - hmin):
                            kind = 1
                        else:
                            istate[S_HERMITE_SKIPS] += 1
            else:
                # Just switched: the value starts at zero and has no sign within round-off.
                noise = _noise(event_value[mode, i], y1, offset)
                if f1 < -noise:
                    kind = 2
            if kind >= 0:
                istate[S_BISECTIONS] += 1
                u, fu = _bisect(
                    e_mode, event_value[mode, i], event_slope[mode, i], offset, level, y, kind, noise, yl, ym
                )
                if kind == 1 and fu > 0.0:
                    continue
                cand[i] = u
                if u < best:
                    best = u
        if best <= length:
            _advance(e_mode, ledger[mode], impulse[mode], mode, y, level, best, fstate, ytmp)
            time += best
            t_now = time * unit_s
            for i in range(3):
                if cand[i] != best:
                    continue
                closed = (mode >> i) & 1
                rel_velocity = _dot(velocity_rows[i], y)
                row = n_events
                events[row, EV_TIME] = t_now
                events[row, EV_CONTACT] = i
                events[row, EV_REL_VELOCITY] = rel_velocity
                events[row, EV_Z] = y[2]
                events[row, EV_ZDOT] = y[3]
                events[row, EV_LAYER_LOSS] = fstate[F_LEDGER + 2 + i]
                if closed:
                    events[row, EV_CLOSING] = 0.0
                    events[row, EV_IMPULSE] = fstate[F_IMPULSE_OPEN + i]
                    mode = mode & ~(1 << i)
                    fstate[F_OFFSET + i] = _dot(gap_rows[i], y)
                    cflags[i, C_ARMED] = 0
                else:
                    events[row, EV_CLOSING] = 1.0
                    events[row, EV_IMPULSE] = 0.0
                    mode = mode | (1 << i)
                    fstate[F_IMPULSE_OPEN + i] = 0.0
                    force = _dot(force_rows[i], y)
                    cflags[i, C_ARMED] = 1 if force > _noise(force_rows[i], y, 0.0) else 0
                n_events += 1
                # Chattering guard: many switches within the Zeno window hold the contact closed
                # for one window (the force stays within round-off of zero meanwhile).
                if t_now - fstate[F_LAST_SWITCH + i] < zeno_window_s:
                    cflags[i, C_ZENO_COUNT] += 1
                else:
                    cflags[i, C_ZENO_COUNT] = 0
                fstate[F_LAST_SWITCH + i] = t_now
                if cflags[i, C_ZENO_COUNT] >= zeno_max:
                    if not (mode >> i) & 1:
                        mode = mode | (1 << i)
                        row = n_events
                        events[row, EV_TIME] = t_now
                        events[row, EV_CONTACT] = i
                        events[row, EV_CLOSING] = 1.0
                        events[row, EV_REL_VELOCITY] = rel_velocity
                        events[row, EV_Z] = y[2]
                        events[row, EV_ZDOT] = y[3]
                        events[row, EV_IMPULSE] = 0.0
                        events[row, EV_LAYER_LOSS] = fstate[F_LEDGER + 2 + i]
                        n_events += 1
                        fstate[F_IMPULSE_OPEN + i] = 0.0
                    cflags[i, C_LOCKED_UNTIL] = time + max(1, int(zeno_window_s / unit_s))
                    cflags[i, C_ZENO_COUNT] = 0
                    istate[S_ZENO_LOCKS] += 1
        else:
            for q in range(5):
                fstate[F_LEDGER + q] += _quad(ledger[mode, level, q], y)
            for i in range(3):
                if (mode >> i) & 1:
                    imp = _dot(impulse[mode, level, i], y)
                    fstate[F_IMPULSE_OPEN + i] += imp
                    fstate[F_IMPULSE_TOTAL + i] += imp
            for k in range(N):
                y[k] = y1[k]
            time += length
        # (re)arm: a function is armed once it is strictly on its admissible side
        for i in range(3):
            if cflags[i, C_LOCKED_UNTIL] > 0 and cflags[i, C_LOCKED_UNTIL] <= time:
                cflags[i, C_LOCKED_UNTIL] = 0
                cflags[i, C_ARMED] = 0
            if not cflags[i, C_ARMED] and cflags[i, C_LOCKED_UNTIL] == 0:
                offset = 0.0 if (mode >> i) & 1 else fstate[F_OFFSET + i]
                if _dot(event_value[mode, i], y) - offset > _noise(event_value[mode, i], y, offset):
                    cflags[i, C_ARMED] = 1
        if (time & (UNITS - 1)) == 0 and ((time >> LEVELS) % sample_every) == 0:
            samples_t[n_samples] = time * unit_s
            for k in range(N):
                samples_y[n_samples, k] = y[k]
            samples_mode[n_samples] = mode
            n_samples += 1
            if n_samples >= max_samples and time < time_end_units:
                status = SAMPLES_FULL
                break
    istate[S_MODE] = mode
    istate[S_TIME] = time
    istate[S_SAMPLES] = n_samples
    istate[S_EVENTS] = n_events
    return status
