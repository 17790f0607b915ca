"""The modal tier's compiled time loop (numba): one kernel for every scene.

A reduced structure (Craig-Bampton, app/reduced/craig_bampton.py: coordinates q, some of them prescribed
inputs: driven electrodes, base-motion patterns) and rigid bodies (translations and rotations about fixed
axes) interact through

* contact *sites* on the structure: points whose displacement is a row block of the basis, y = R q (a
  surface contact's sample points, a node contact's node), each with the penalty law of its contact
  (surface: pressure x the site's area; node: a power law, Hertz) against the obstacle shape of a rigid body
  (plane, sphere, cone), regularised Coulomb friction with the body's spin in the slip;
* rigid-rigid links (Kelvin-Voigt, optional friction).

The laws are those of forms/contact_law.py (the scalar twins of the FE tier's UFL), compiled here.

One step (generalized-alpha; Newmark for alpha_m = alpha_f = 0; the equations imposed at the generalized
mid-points, forces evaluated there, as the FE tier does) is condensed into the *contact space*: the
structure's equations are linear, so for site forces f on the structure its increments are
dq = w + A^-1 R^T f (A = K_eff of the free coordinates, w the contact-free increment), and the site
increments are d = d_w + H f with H = R_F A^-1 R_F^T, formed once per step size (cached). Newton then runs
on the increments of the sites that carry a force (the active set, updated every iteration: a separated
site follows from the others without a solve) and on the corrections of the free body coordinates to their
predictors (no m c_acc z-sized terms in a residual), damped by the natural monotonicity test (Deuflhard).
A failed step is cut back and retried; steps by contact state (open / closed / change, event refinement,
approach to a predicted closure) as the FE tier (app/transient/control.py).
A structure whose M and K are diagonal on the free coordinates (a model in its free modes,
app/reduced/coordinates.py) takes its contact-free increment with one dense product, by K_eff^-1
(:func:`_free_increment_modal`), instead of four (M, C, K, K_eff^-1).

Every argument travels as a structured record (NamedTuple of arrays, :func:`make_records`); the state
arrays (q, v, a, z, zd, zdd, istate, fstate, sums, site_force) hold everything the next call needs, so where a
run is split into calls (checkpoints, field outputs) does not change it.

Cost (issue 27, BENCHMARKS.md): numba reference-counts every array a compiled function receives, member by member of
each record, with an atomic operation on entry and exit, and every array it allocates. With records of ~150 arrays
passed to the per-step functions, that was ~70 % of a drill step. So the functions below the loop are compiled
without reference counting (``_nrt=False``: they may neither allocate nor return arrays; numba refuses to compile
one that does), their work arrays allocated once per call (:class:`StepWork`, :class:`NewtonWork`), and the loop
fills its vectors index by index in the order of the array expressions they replace and calls the LAPACK and BLAS
routines numba's np.linalg.solve, np.linalg.inv and np.dot call (numba's bindings of SciPy's), so the numbers are
the same to the bit. (The Woodbury system is since factored and solved by triangular sweeps written here,
:func:`_factor` and :func:`_lu_apply`, instead of np.linalg.inv's explicit inverse: a motor's series moved by 5e-11,
BENCHMARKS.md "the Woodbury system by its LU factors".) ``_nrt``, ``numba.np.linalg._LAPACK`` and its ``numba_xx*``
symbols are numba's private names (numba 0.56.4, as Debian bookworm ships it): should a later numba drop them, the
decorators' ``_nrt=False`` and these bindings give way to plain ``njit`` and np.linalg / np.dot, with the same
results and the reference counts' cost back. Of the motor's step what remained (issue 27, BENCHMARKS.md "the contact
law on the sites that can touch"): the contact law runs only on the sites that can touch (:func:`_surely_open`, a
bound on each site's gap from its last evaluation: exact), and the row updates of the Woodbury matrix and of G f are
1-D loops of their own (:func:`_subtract_scaled`), which LLVM vectorises where, written inline on rows of the 2-D
work arrays, it did not (the same numbers). With the rotor lying on the whole ring (1 536 active site rows on 192 of
the 221 free coordinates: S) the products with G^T's rows, dense although a site's rows R_F touch ~12 coordinates
(a row 4 or 8), were then most of the step (BENCHMARKS.md "the products through K_eff^-1"): G x, the Woodbury matrix
and its solves go through K_eff^-1 itself (kept transposed per step size, :class:`Cache` invT) wherever that costs
less, chosen per call by counting the operations, gathered elements weighted GATHER_COST and indexed updates
INDEXED_COST against a vectorised multiply-add: G x = K_eff^-1 (R_F^T x), INDEXED_COST nnz + |S| nf against
n_rows nf (:func:`_respond`); I - R_A^T D G_A^T = I - (R_A^T D R_A) K_eff^-T on S, 4 GATHER_COST |S|^2 +
INDEXED_COST nnz (gdim + widest row) + nfb (INDEXED_COST nnz + |S|^2) + nnz(R_A^T D R_A) |S| against n_rows |S|
(GATHER_COST + gdim) + nnz |S| + nfb n_rows |S| (:func:`_fill_woodbury`); the solves' G_A^T[:, S] sol =
R_A (K_eff^-T[S, S] sol), |S|^2 + GATHER_COST nnz against GATHER_COST n_rows |S| (:func:`_solve_takes_inverse`).
The collapsing run's loop: 9.1 -> 6.1 ms a step. Dense rows (a model in its free modes: the drill) keep G^T's rows
and their numbers to the bit; where K_eff^-1 is taken the sums run in another order (round-off). """

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.np.linalg import _LAPACK

from app.contact.law import (
    CONE,
    NODE,
    PLANE,
    SPHERE,
    SURFACE,
    Bodies,
    Contacts,
    DriveClock,
    Links,
    SiteAccumulators,
    Sites,
    SiteSample,
    SiteWork,
    _body_rotations,
    _cross,
    _dot3,
    _friction_coefficient,
    _penalty_energy,
    _penalty_pressure,
    accumulate_site,
    friction_tangent,
    link_force,
    shape_gap,
    site_force,
    site_position,
    site_work,
    stick_speed,
)

__all__ = ["CONE", "NODE", "PLANE", "SPHERE", "SURFACE", "Bodies", "Contacts", "Links", "Sites", "shape_gap",
           "site_force", "site_work"]

# integer state slots
I_STEPS, I_ATTEMPTS, I_CUTBACKS, I_REFINEMENTS, I_NEWTON, I_CHANGED = range(6)
N_ISTATE = 6
# float state slots: time [s], step cap after cut-backs [s], the call's stop time [s], time of the last
# diagnostics row [s]
F_TIME, F_CAP, F_STOP, F_SITES = range(4)
N_FSTATE = 4
# return codes
DONE, BUFFER_FULL, STEP_FAILED, STOPPED = 0, 1, 2, 3
# input kinds: an electrode's A sin(wt + phase) (A cos after a harmonic start); a base motion's pattern
# coefficients r(t) cos(wt + phase), r(t) sin(wt + phase) (r the smooth ramp)
ELECTRODE, PATTERN_COS, PATTERN_SIN = 0, 1, 2

MAX_NEWTON = 60
ROUND_OFF_FACTOR = 1e3
#: unknown scales of the monotonicity test: site increments and body translations [m], rotation rates [rad/s]
LENGTH_SCALE_M = 1e-12
RATE_SCALE_RAD_PER_S = 1e-4
#: absolute displacement tolerance of a site equation [m]; relative one on its increment
SITE_TOL_M = 1e-14
SITE_RTOL = 1e-9
#: the Newton system goes to the structure's coordinates (Woodbury) when gdim x active sites exceed this multiple
#: of the free coordinates their rows touch (S, :func:`_woodbury_columns`). Set when that system was inverted
#: (|S|^3 against the contact-space LU's (gdim n_active)^3 / 3); its LU factors (2/3 |S|^3) move the break-even of
#: the factorisations alone to about 1.26, not measured: the switch stays where it was measured
WOODBURY_FACTOR = 1.5
FORCE_RTOL = 1e-10
#: the cost rules' weights (:func:`_respond`, :func:`_fill_woodbury`, :func:`_woodbury_solve_into`; issue 27), against
#: one multiply-add of a vectorised row update (:func:`_subtract_scaled`): an element read through an index list
#: (``row[cols[j]]``, a branchy scan) and an indexed scalar update (``y[index] += a x``). Measured on the collapsed
#: motor's Woodbury matrix, each part timed in isolation inside numba: 0.17 ns a row update's multiply-add, 0.57 ns a
#: gathered element, ~1.5 ns an indexed update (BENCHMARKS.md "the products through K_eff^-1")
GATHER_COST = 3
INDEXED_COST = 8
#: a gap's round-off relative to the size of its terms (|d|, the radius, the excluded reference gap): the margin by
#: which a site must be clear of its obstacle to be skipped (:func:`_open_bound`; the rounding is ~1e-16 of them)
GAP_ROUND_OFF = 1e-12
EPS = 2.220446049250313e-16
#: LAPACK's dgesv as numba's np.linalg.solve calls it (numba's binding of SciPy's LAPACK; a symbol, so the compiled
#: functions that call it stay cacheable)
_xgesv = _LAPACK().numba_xgesv(types.float64)
_xgetrf = _LAPACK().numba_xxgetrf(types.float64)
#: BLAS's gemv as numba's np.dot(matrix, vector) calls it (np.dot returns its output: not in a function compiled
#: without reference counts)
_xgemv = types.ExternalFunction("numba_xxgemv", types.intc(
    types.char, types.char, types.intp, types.intp, types.CPointer(types.float64), types.CPointer(types.float64),
    types.intp, types.CPointer(types.float64), types.CPointer(types.float64), types.CPointer(types.float64)))
_XGESV_KIND = ord("d")
_TRANSPOSED, _NOT_TRANSPOSED = ord("t"), ord("n")


class Structure(NamedTuple):
    """The reduced structure: K, M, C (n x n), the constant generalized load [N], the free and the prescribed
    (input) coordinates."""

    K: np.ndarray
    M: np.ndarray
    C: np.ndarray
    load: np.ndarray
    free: np.ndarray
    inputs: np.ndarray


class Inputs(NamedTuple):
    """Time functions of the prescribed coordinates (one entry per input coordinate)."""

    kind: np.ndarray          # ELECTRODE, PATTERN_COS, PATTERN_SIN
    amplitude: np.ndarray     # [V] or 1 (a pattern carries its amplitude)
    phase: np.ndarray         # [rad]
    ramp_s: np.ndarray        # smooth ramp time of a pattern [s] (0: none)
    omega: float              # [rad/s]
    cosine: bool              # a harmonic start: electrodes A cos(wt + phase)


class Scheme(NamedTuple):
    beta: float
    gamma: float
    alpha_m: float
    alpha_f: float


class Control(NamedTuple):
    """Step sizes [s] (app/transient/control.py) and the growth after cut-backs."""

    open_s: float
    closed_s: float
    change_s: float
    min_s: float
    growth: float


class Outputs(NamedTuple):
    """Row buffers (one row per accepted step) and the per-site diagnostics accumulators."""

    time: np.ndarray          # (cap,)
    dt: np.ndarray
    samples: np.ndarray       # (cap, n_samples) sample_rows @ q
    inputs: np.ndarray        # (cap, n_inputs) prescribed coordinate values
    z: np.ndarray             # (cap, m)
    zd: np.ndarray
    force: np.ndarray         # (cap, n_contacts + n_links, 3) force on the rigid body (upper body of a link)
    torque: np.ndarray        # (cap, n_contacts, 3) torque of the contact on its body about its reference point
    normal: np.ndarray        # (cap, n_contacts) total normal force [N]
    area: np.ndarray          # (cap, n_contacts) area (surface) or count (node) of sites in contact
    closed: np.ndarray        # (cap, n_contacts + n_links)
    dissipated: np.ndarray    # (cap, n_contacts + n_links) friction and damping energy since t = 0 [J]
    energy: np.ndarray        # (cap, 5): kinetic, strain, rigid kinetic, contact penalty [J], damping loss [J]
    probe: np.ndarray         # (cap, n_contacts, 3) displacement of each contact's first site in its frame
    peak: np.ndarray          # (cap, n_contacts) largest site pressure fn / weight of a surface contact [Pa]
    site_sums: np.ndarray     # (n_sites, 14): the per-site diagnostics' time integrals (app/contact/tables.py)
    site_bins: np.ndarray     # (groups, bins, 8): their wave-frame bins (app/contact/law.py accumulate_site)
    site_group: np.ndarray    # (n_sites,) int64 each site's group of bins
    site_phase: np.ndarray    # (n_sites,) each site's wave-phase reference [rad] (NaN: none yet)


class Frames(NamedTuple):
    """Field frames taken inside a call (app/transient/fields.py's schedule, the loop's rule): a frame (the time,
    the coordinates q, the body coordinates z after the step) at the first accepted step at or after
    ``times[next] - due_s``; the next frame time is then the first one after t + ``after_s``. A call returns
    (BUFFER_FULL) before a step when the frame buffers are full and (STOPPED) after taking the last of ``times``:
    the caller empties the buffers or gives the next times, so the loop need not stop the kernel at every frame.
    ``slots``: [index of the next frame time, frames in the buffers]."""

    times: np.ndarray         # (k,) increasing frame times [s]
    due_s: float              # a frame is due this much before its time [s]
    after_s: float            # a step at t took the frames up to t + after_s [s]
    slots: np.ndarray         # (2,) int64
    t: np.ndarray             # (cap,) [s]
    q: np.ndarray             # (cap, n)
    z: np.ndarray             # (cap, m)


def no_frames(n: int, m: int) -> Frames:
    """Frames of a call that takes none (field output off, or taken by the loop)."""
    return Frames(np.zeros(0), 0.0, 0.0, np.zeros(2, np.int64), np.zeros(0), np.zeros((0, n)), np.zeros((0, m)))


class Model(NamedTuple):
    """Everything constant through a run: the structure, its inputs, the scheme and step control, the bodies,
    sites, contacts and links, and the rows of the sampled outputs (named points, electrode charges)."""

    structure: Structure
    inputs: Inputs
    scheme: Scheme
    control: Control
    bodies: Bodies
    sites: Sites
    contacts: Contacts
    links: Links
    sample_rows: np.ndarray


class Sums(NamedTuple):
    """Running sums the loop carries between calls (part of the state)."""

    dissipated: np.ndarray    # (n_contacts + n_links,) [J]
    power: np.ndarray         # (n_contacts + n_links,) dissipation power of the last step [W]
    damping: np.ndarray       # (2,) structural damping loss [J], its power at the last step [W]


class State(NamedTuple):
    """Everything the next call needs (changed in place): the structure's coordinates, rates and accelerations,
    the bodies', the integer and float controller slots and the running sums."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    z: np.ndarray
    zd: np.ndarray
    zdd: np.ndarray
    istate: np.ndarray
    fstate: np.ndarray
    sums: Sums
    site_force: np.ndarray    # (n_sites, 3) the sites' forces on the structure at the last accepted step [N]: the
    #                           next step's Newton starts from them (a state: a run split into calls is unchanged)


class SparseRows(NamedTuple):
    """Rows of a matrix by their nonzero entries (a contact site's row touches a few interface coordinates):
    row r is sum_j value[r, j] x[index[r, j]] over j < count[r]."""

    index: np.ndarray         # (rows, width) int64
    value: np.ndarray         # (rows, width)
    count: np.ndarray         # (rows,) int64


class Compliance(NamedTuple):
    """The contact space of one step size: H = R_F K_eff^-1 R_F^T (site increments per unit site force), its
    factor G^T = R_F K_eff^-1 (nr x nf) and the site rows on the free coordinates, so a force on a few active
    sites costs n_active x nf + nnz(R_F) (u = G f, H f = R_F u) instead of n_active x nr of H's columns; and
    K_eff^-1 itself, transposed (``invT``: G^T = R_F invT, G x = invT^T (R_F^T x)), so a force on many active sites
    whose rows touch few coordinates S costs nnz + |S| x nf instead (:func:`_respond`)."""

    H: np.ndarray             # (nr, nr)
    GT: np.ndarray            # (nr, nf)
    RF: SparseRows            # the site rows on the free coordinates (free numbering)
    u: np.ndarray             # (nf,) K_eff^-1 R_F^T f of the last evaluation: the structure's response
    du: np.ndarray            # (nf,) work
    invT: np.ndarray          # (nf, nf) K_eff^-T (row l: K_eff^-1's column l); (0, 0): not given, G^T's rows alone
    g: np.ndarray             # (nf,) work: R_F^T x


@njit(cache=True)
def sparse_rows(rows, columns):
    """The nonzero entries of ``rows[:, columns]`` (``columns`` in the new numbering's order)."""
    width = 0
    for r in range(rows.shape[0]):
        count = 0
        for j in range(columns.size):
            if rows[r, columns[j]] != 0.0:
                count += 1
        width = max(width, count)
    index = np.zeros((rows.shape[0], max(width, 1)), np.int64)
    value = np.zeros((rows.shape[0], max(width, 1)))
    count = np.zeros(rows.shape[0], np.int64)
    for r in range(rows.shape[0]):
        for j in range(columns.size):
            x = rows[r, columns[j]]
            if x != 0.0:
                index[r, count[r]] = j
                value[r, count[r]] = x
                count[r] += 1
    return SparseRows(index, value, count)


@njit(cache=True, _nrt=False)
def _row_dot(rows, r, x):
    value = 0.0
    for j in range(rows.count[r]):
        value += rows.value[r, j] * x[rows.index[r, j]]
    return value


def compliance_of(H: np.ndarray, GT: np.ndarray, RF: np.ndarray, invT: np.ndarray | None = None) -> Compliance:
    """The compliance record of H = R_F G, G^T and dense site rows R_F (nr x nf), and K_eff^-T with G^T = R_F invT
    (None: not given, the products by G^T's rows alone): for tests of the condensed step."""
    nf = RF.shape[1]
    invT = np.zeros((0, 0)) if invT is None else np.ascontiguousarray(invT, dtype=float)
    return Compliance(np.ascontiguousarray(H), np.ascontiguousarray(GT), sparse_rows(RF, np.arange(nf, dtype=np.int64)),
                      np.zeros(nf), np.zeros(nf), invT, np.zeros(nf))


def dense_compliance(H: np.ndarray) -> Compliance:
    """The compliance of sites that are the coordinates themselves (R_F = I, K_eff^-1 = H symmetric): for tests of
    the condensed step with a given H."""
    return compliance_of(H, H.T, np.eye(H.shape[0]), H.T)


@njit(cache=True, _nrt=False)
def _subtract_scaled(n, a, x, y):
    """y[:n] -= a x[:n]. A loop on its own 1-D arguments: the compiler vectorises it (the same loop written inline
    on rows of 2-D work arrays it does not), each entry's result unchanged."""
    for j in range(n):
        y[j] -= a * x[j]


@njit(cache=True, _nrt=False)
def _combine_rows(n, gdim, F, G, out):
    """out[:n] = sum_c F[c] G[c, :n], the terms added in the order of c from 0.0 (as the loop it replaces: each
    entry's sum the same), a row at a time (vectorised)."""
    for j in range(n):
        out[j] = 0.0
    for c in range(gdim):
        _subtract_scaled(n, -F[c], G[c], out)          # out + F[c] G[c] exactly


@njit(cache=True, _nrt=False)
def _respond(compliance, active, n_active, gdim, x, out):
    """out = G x (nf) for site forces ``x`` (n_sites, 3) on the active sites (the rest carry none); H x = R_F out.
    The cheaper of two ways (issue 27): G^T's rows, one dense row of nf per loaded site row (:func:`_respond_rows`:
    n_rows x nf), or K_eff^-1 on the support S of the scatter g = R_F^T x (:func:`_respond_inverse`: nnz indexed
    updates, weighted INDEXED_COST, + |S| x nf). A collapsed rotor's 1 536 loaded rows touch 192 coordinates: ~6x
    fewer multiply-adds. Dense rows (a model in its free modes: nnz = n_rows x nf) never pay for the scatter, so they
    keep the first way and its numbers. |S| is at least the widest loaded row's count: the scatter is formed only
    where that bound leaves the second way cheaper."""
    RF = compliance.RF
    nf = compliance.GT.shape[1]
    n_rows = 0
    nnz = 0
    widest = 0
    for a in range(n_active):
        i = active[a]
        for k in range(gdim):
            if x[i, k] != 0.0:
                count = RF.count[i * gdim + k]
                n_rows += 1
                nnz += count
                widest = max(widest, count)
    cost_rows = n_rows * nf
    if compliance.invT.shape[0] == nf and INDEXED_COST * nnz + widest * nf < cost_rows:
        support = _scatter_rows(RF, active, n_active, gdim, x, compliance.g)
        if INDEXED_COST * nnz + support * nf < cost_rows:
            _respond_inverse(compliance.invT, compliance.g, out)
            return
    _respond_rows(compliance.GT, active, n_active, gdim, x, out)


@njit(cache=True, _nrt=False)
def _respond_rows(GT, active, n_active, gdim, x, out):
    """:func:`_respond` by G^T's rows: out = sum over the loaded site rows r of x_r G^T[r] (n_rows x nf)."""
    nf = GT.shape[1]
    for j in range(nf):
        out[j] = 0.0
    for a in range(n_active):
        i = active[a]
        for k in range(gdim):
            xk = x[i, k]
            if xk != 0.0:
                _subtract_scaled(nf, -xk, GT[i * gdim + k], out)     # out + xk row, exactly (vectorised)


@njit(cache=True, _nrt=False)
def _scatter_rows(RF, active, n_active, gdim, x, g):
    """g (nf) <- R_F^T x for site forces ``x`` (n_sites, 3) on the active sites: the loaded rows' entries scattered
    (nnz), the rows in the order of ``active``. Returns the count of nonzero entries of g (its support S)."""
    for j in range(g.size):
        g[j] = 0.0
    for a in range(n_active):
        i = active[a]
        for k in range(gdim):
            xk = x[i, k]
            if xk != 0.0:
                row = i * gdim + k
                for e in range(RF.count[row]):
                    g[RF.index[row, e]] += RF.value[row, e] * xk
    support = 0
    for j in range(g.size):
        if g[j] != 0.0:
            support += 1
    return support


@njit(cache=True, _nrt=False)
def _respond_inverse(invT, g, out):
    """:func:`_respond` through K_eff^-1: out = K_eff^-1 g = sum over the support of g of g_l invT[l] (|S| x nf; invT's
    rows are K_eff^-1's columns, contiguous), g = R_F^T x from :func:`_scatter_rows`. K_eff^-1 as G^T was formed from
    it (G = K_eff^-1 R_F^T): it is symmetric to round-off only."""
    nf = out.size
    for j in range(nf):
        out[j] = 0.0
    for l in range(nf):
        gl = g[l]
        if gl != 0.0:
            _subtract_scaled(nf, -gl, invT[l], out)          # out + gl row, exactly (vectorised)


@njit(cache=True, _nrt=False)
def _ramp(t, ramp_s):
    if ramp_s <= 0.0 or t >= ramp_s:
        return 1.0
    if t <= 0.0:
        return 0.0
    return 0.5 * (1.0 - math.cos(math.pi * t / ramp_s))


@njit(cache=True, _nrt=False)
def input_values(t, inputs, out):
    """Values of the prescribed coordinates at time t."""
    for p in range(inputs.kind.size):
        arg = inputs.omega * t + inputs.phase[p]
        kind = inputs.kind[p]
        if kind == ELECTRODE:
            out[p] = inputs.amplitude[p] * (math.cos(arg) if inputs.cosine else math.sin(arg))
        elif kind == PATTERN_COS:
            out[p] = inputs.amplitude[p] * _ramp(t, inputs.ramp_s[p]) * math.cos(arg)
        else:
            out[p] = inputs.amplitude[p] * _ramp(t, inputs.ramp_s[p]) * math.sin(arg)


# ------------------------------------------------------------------ one step: the condensed system
class StepWork(NamedTuple):
    """Per-step arrays (allocated once per call)."""

    y0: np.ndarray            # (ns, 3) site displacement at the step's start
    v0: np.ndarray            # (ns, 3) its velocity
    a0: np.ndarray            # (ns, 3) its acceleration
    dw: np.ndarray            # (ns * gdim,) contact-free site increments
    dd: np.ndarray            # (ns * gdim,) site increments (the iterate)
    dd_try: np.ndarray
    f: np.ndarray             # (ns, 3) site forces on the structure
    fn: np.ndarray            # (ns,) normal forces
    gap: np.ndarray           # (ns,)
    slip: np.ndarray          # (ns, 3): e1, e2 components and speed
    Fd: np.ndarray            # (ns, 3, 3)
    Fz: np.ndarray            # (ns, 3, kmax) derivatives w.r.t. the site body's coordinates
    lever: np.ndarray         # (ns, 3)
    Hf: np.ndarray            # (ns * gdim,)
    R: np.ndarray             # (ns * gdim,) site residuals
    rz: np.ndarray            # (m,) body residuals
    rz_try: np.ndarray
    xi: np.ndarray            # (m,) body corrections to the predictor
    xi_try: np.ndarray
    Q: np.ndarray             # (m,) generalized loads of the contacts on the bodies
    dQ: np.ndarray            # (m, m) their derivative w.r.t. the body corrections
    y_mid: np.ndarray         # (3,)
    v_mid: np.ndarray
    work: SiteWork
    lf: np.ndarray            # (3,) a link's force
    lP: np.ndarray            # (3, m)
    link_fn: np.ndarray       # (n_links,)
    active: np.ndarray        # (ns,) int64 positions of the active sites
    z_mid: np.ndarray         # (m,) the bodies at the generalized mid-point and at the step's end
    zd_mid: np.ndarray
    z1: np.ndarray
    zd1: np.ndarray
    zdd1: np.ndarray
    fxa: np.ndarray           # (3,) work: f x a of a rotation
    link_work: np.ndarray     # (5, 3) link_force's work
    link_D: np.ndarray        # (m,) a link's d delta / d coordinates
    link_v: np.ndarray        # (3, 3) its dF/dN, slip, relative velocity
    link_M: np.ndarray        # (3, 3, 3) its dF/ds, the tangential projector, their product
    link_dF: np.ndarray       # (3, m) its dF / d coordinates
    d_ref: np.ndarray         # (ns, 3) each site's relative position d of its last evaluation by the law [m]
    clear: np.ndarray         # (ns,) how far d may move from d_ref with the site surely open [m] (<= 0: not known);
    #                           d_ref and clear belong to the sites of one model (a new work record per call)
    rate: np.ndarray          # (ns,) each site's gap rate dg/dt at its last evaluation by the law [m/s] (the
    #                           damping's dissipation, also while a clipped pressure holds no force)


@njit(cache=True)
def step_work(ns, gdim, m, kmax, n_links):
    """A :class:`StepWork` (its site references :func:`_open_bound` unknown: every site's first evaluation is the
    law's)."""
    return StepWork(np.zeros((ns, 3)), np.zeros((ns, 3)), np.zeros((ns, 3)), np.zeros(ns * gdim),
                    np.zeros(ns * gdim), np.zeros(ns * gdim), np.zeros((ns, 3)), np.zeros(ns), np.zeros(ns),
                    np.zeros((ns, 3)), np.zeros((ns, 3, 3)), np.zeros((ns, 3, max(kmax, 1))), np.zeros((ns, 3)),
                    np.zeros(ns * gdim), np.zeros(ns * gdim), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m),
                    np.zeros(m), np.zeros((m, m)), np.zeros(3), np.zeros(3), site_work(kmax), np.zeros(3),
                    np.zeros((3, max(m, 1))), np.zeros(max(n_links, 1)), np.zeros(max(ns, 1), np.int64), np.zeros(m),
                    np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(3), np.zeros((5, 3)), np.zeros(m),
                    np.zeros((3, 3)), np.zeros((3, 3, 3)), np.zeros((3, max(m, 1))), np.zeros((ns, 3)),
                    np.full(ns, -1.0), np.zeros(ns))


@njit(cache=True, _nrt=False)
def _body_kinematics(xi, state, dt, model, wk):
    """End-of-step and mid-point body coordinates (into ``wk``) for corrections ``xi`` of the free coordinates to
    their predictors (held coordinates move at their rate)."""
    z0, zd0, zdd0 = state.z, state.zd, state.zdd
    z_mid, zd_mid, z1, zd1, zdd1 = wk.z_mid, wk.zd_mid, wk.z1, wk.zd1, wk.zdd1
    bodies = model.bodies
    beta, gamma, am, af = model.scheme
    c_acc = 1.0 / (beta * dt * dt)
    for j in range(z0.size):
        if bodies.free[j]:
            zdd1[j] = zdd0[j] + c_acc * xi[j]
            dz = dt * zd0[j] + 0.5 * dt * dt * zdd0[j] + xi[j]
            zd1[j] = zd0[j] + dt * ((1.0 - gamma) * zdd0[j] + gamma * zdd1[j])
        else:
            zdd1[j] = 0.0
            zd1[j] = bodies.rate[j]
            dz = bodies.rate[j] * dt
        z1[j] = z0[j] + dz
        z_mid[j] = z0[j] + (1.0 - af) * dz
        zd_mid[j] = (1.0 - af) * zd1[j] + af * zd0[j]


@njit(cache=True, _nrt=False)
def _open_bound(i, gap, d, sites, contacts, wk):
    """Site i's reference for :func:`_surely_open` after an evaluation by the law at the relative position ``d``
    (site_force's, [m]) where its gap was ``gap`` [m]: wk.d_ref[i] = d and wk.clear[i] = (gap - margin) / L, L the
    Lipschitz constant of the gap in d (:func:`_gap_lipschitz`), margin the gap's round-off (GAP_ROUND_OFF of the
    size of its terms); -1 (no bound) for a site not clear of the obstacle by that margin."""
    c = sites.contact[i]
    scale = abs(d[0]) + abs(d[1]) + abs(d[2]) + abs(contacts.radius[c]) + abs(sites.gap_ref[i])
    margin = GAP_ROUND_OFF * scale
    for k in range(3):
        wk.d_ref[i, k] = d[k]
    lipschitz = _gap_lipschitz(contacts, c)
    wk.clear[i] = (gap - margin) / lipschitz if gap > margin and lipschitz < np.inf else -1.0


@njit(cache=True, _nrt=False)
def _gap_lipschitz(contacts, c):
    """A Lipschitz constant of contact c's gap as a function of the site's relative position d (app/contact/law.py
    shape_gap, site_force): |g(d) - g(d')| <= L |d - d'|. A plane's and a node's gap n.d (minus constants): |n|.
    A sphere's |d| - R, or with a unit pole p, (|d|^2 + 2 R p.d) / (|d + R p| + R) = |d + R p| - R: 1. A cone's
    (rho - R - h tan a) cos a = rho cos a - h sin a - R cos a about a unit axis: rho = |d - h axis| and h = d.axis
    are the lengths of orthogonal parts of d, so |dg| <= sqrt(cos^2 + sin^2) |dd| = |dd|: 1. Inf (no bound) where
    a formula needs a unit vector it was not given; times 1 + 1e-9 against the rounding of these numbers."""
    v = contacts.vector[c]
    norm = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    unit = abs(norm - 1.0) <= 1e-12
    if contacts.kind[c] == NODE or contacts.shape[c] == PLANE:
        return norm * (1.0 + 1e-9)
    if contacts.shape[c] == SPHERE:
        return 1.0 + 1e-9 if norm == 0.0 or unit else np.inf
    return 1.0 + 1e-9 if unit else np.inf


@njit(cache=True, _nrt=False)
def _surely_open(i, y_mid, z_mid, sites, contacts, bodies, wk, sw):
    """Whether site i is open at the site displacement ``y_mid`` and the bodies' ``z_mid`` by its reference
    (:func:`_open_bound`): its relative position d (app/contact/law.py site_position, into the site work ``sw``, as
    the law forms it) within wk.clear[i] of wk.d_ref[i], so its gap is at least L (clear - |d - d_ref|) + margin > 0
    and the law would give no force (issue 27: the law is evaluated only on the sites that can touch). If so, writes
    what the law gives an open site (no force, no slip, its lever arm) and, in wk.gap, clear - |d - d_ref| (> 0,
    below its gap)."""
    d, lever = sw.d, sw.lever
    site_position(i, y_mid, z_mid, sites, contacts.body[sites.contact[i]], bodies, d, lever)
    distance2 = 0.0
    for k in range(3):
        e = d[k] - wk.d_ref[i, k]
        distance2 += e * e
    clear = wk.clear[i]
    if not distance2 < clear * clear:
        return False
    wk.fn[i] = 0.0
    wk.gap[i] = clear - math.sqrt(distance2)
    for k in range(3):
        wk.slip[i, k] = 0.0
        wk.f[i, k] = 0.0
        wk.lever[i, k] = lever[k]
    return True


@njit(cache=True, _nrt=False)
def _evaluate(dd, xi, wk, cp, state, dt, model, want):
    """Site forces at the iterate (site increments ``dd``, body corrections ``xi``), the site residuals
    R = dd - dw - H f (``cp``: the step's :class:`Compliance`; cp.u gets G f), the body residuals rz, and
    (``want``) the derivatives of the active sites and the bodies' load derivative dQ. Returns the number of
    active sites (listed in wk.active)."""
    bodies, sites, contacts, links = model.bodies, model.sites, model.contacts, model.links
    z0, zdd0 = state.z, state.zdd
    z_mid, zd_mid = wk.z_mid, wk.zd_mid
    gdim = bodies.gdim
    beta, gamma, am, af = model.scheme
    w_f = 1.0 - af
    c_acc = 1.0 / (beta * dt * dt)
    c_vel = gamma / (beta * dt)
    _body_kinematics(xi, state, dt, model, wk)
    ns = sites.contact.size
    m = z0.size
    for j in range(m):
        wk.Q[j] = 0.0
        if want:
            for k in range(m):
                wk.dQ[j, k] = 0.0
    n_active = 0
    sw = wk.work
    for i in range(ns):
        for k in range(3):
            wk.y_mid[k] = 0.0
            wk.v_mid[k] = 0.0
        for k in range(gdim):
            wk.y_mid[k] = wk.y0[i, k] + w_f * dd[i * gdim + k]
        if wk.clear[i] > 0.0 and _surely_open(i, wk.y_mid, z_mid, sites, contacts, bodies, wk, sw):
            continue            # no force, no slip: what the law gives an open site (wk.gap: a lower bound)
        for k in range(gdim):
            inc = dd[i * gdim + k]
            a1 = (inc - dt * wk.v0[i, k]) * c_acc - (1.0 / (2.0 * beta) - 1.0) * wk.a0[i, k]
            v1 = wk.v0[i, k] + dt * ((1.0 - gamma) * wk.a0[i, k] + gamma * a1)
            wk.v_mid[k] = w_f * v1 + af * wk.v0[i, k]
        fn, gap, s1, s2, speed = site_force(i, wk.y_mid, wk.v_mid, z_mid, zd_mid, sites, contacts, bodies, c_vel,
                                            w_f, want, sw)
        wk.fn[i] = fn
        wk.gap[i] = gap
        wk.rate[i] = _dot3(sw.n, sw.vrel)
        wk.slip[i, 0] = s1
        wk.slip[i, 1] = s2
        wk.slip[i, 2] = speed
        for k in range(3):
            wk.f[i, k] = sw.f[k]
            wk.lever[i, k] = sw.lever[k]
        _open_bound(i, gap, sw.d, sites, contacts, wk)
        if fn <= 0.0:
            continue
        wk.active[n_active] = i
        n_active += 1
        c = sites.contact[i]
        b = contacts.body[c]
        s0, n_rot = _body_rotations(bodies, b)
        nb = gdim + n_rot
        if want:
            for r in range(3):
                for k in range(3):
                    wk.Fd[i, r, k] = sw.Fd[r, k]
                for k in range(nb):
                    wk.Fz[i, r, k] = sw.Fz[r, k]
        # the body takes -f at the site: translation -f, angle q: -a_q . (lever x f)
        axl = sw.axl
        for k in range(gdim):
            wk.Q[s0 + k] -= sw.f[k]
        for q in range(n_rot):
            j = s0 + gdim + q
            _cross(bodies.axis[j], sw.lever, axl)          # a x lever: a.(lever x f) = f.(a x lever)
            wk.Q[j] -= _dot3(axl, sw.f)
        if want:
            for k in range(gdim):
                for kk in range(nb):
                    wk.dQ[s0 + k, s0 + kk] -= sw.Fz[k, kk]
            for q in range(n_rot):
                j = s0 + gdim + q
                _cross(bodies.axis[j], sw.lever, axl)
                fxa = wk.fxa
                _cross(sw.f, bodies.axis[j], fxa)
                for kk in range(nb):
                    value = axl[0] * sw.Fz[0, kk] + axl[1] * sw.Fz[1, kk] + axl[2] * sw.Fz[2, kk]
                    if kk < gdim:
                        value -= w_f * fxa[kk]       # the lever arm shortens as the body moves
                    wk.dQ[j, s0 + kk] -= value
    # links between bodies
    for l in range(links.lower.size):
        lo, up = links.lower[l], links.upper[l]
        slo, nlo = _body_rotations(bodies, lo)
        sup, nup = _body_rotations(bodies, up)
        f, delta, rate, kf, cf, T, dT_ds, dT_dfn, reg, speed = link_force(l, z_mid, zd_mid, bodies, links, wk.lf,
                                                                          wk.lP, want, wk.link_work)
        wk.link_fn[l] = f
        if f <= 0.0:
            continue
        n = links.direction[l]
        # generalized forces: upper gets F at its contact point, lower -F
        for k in range(gdim):
            wk.Q[sup + k] += wk.lf[k]
            wk.Q[slo + k] -= wk.lf[k]
        if links.mu[l] > 0.0 or nlo + nup > 0:
            for j in range(m):
                value = 0.0
                for k in range(3):
                    value += wk.lP[k, j] * wk.lf[k]
                # P^T F holds the translations again: keep the rotational part only
                if not (sup <= j < sup + gdim or slo <= j < slo + gdim):
                    wk.Q[j] += value
        if want:
            # dF/dq = (n + dF/dN) (k + c c_vel) w_f D + c_vel w_f dF/ds P, D = d delta / d coordinates
            D = wk.link_D
            for j in range(m):
                D[j] = 0.0
            for k in range(gdim):
                D[slo + k] += n[k]
                D[sup + k] -= n[k]
            dFdN = wk.link_v[0]
            dFds = wk.link_M[0]
            for r in range(3):
                dFdN[r] = 0.0
                for k in range(3):
                    dFds[r, k] = 0.0
            if links.mu[l] > 0.0:
                s = wk.link_v[1]
                vrel = wk.link_v[2]
                for k in range(3):
                    vrel[k] = 0.0
                for k in range(3):
                    for j in range(m):
                        vrel[k] += wk.lP[k, j] * zd_mid[j]
                vn = _dot3(vrel, n)
                for k in range(3):
                    s[k] = vrel[k] - vn * n[k]
                friction_tangent(T, dT_dfn, dT_ds, s, reg, speed, dFds, dFdN)
                # the slip is the tangential part: d s / d v = I - n n
                tang = wk.link_M[1]
                for r in range(3):
                    for k in range(3):
                        tang[r, k] = (1.0 if r == k else 0.0) - n[r] * n[k]
                product = wk.link_M[2]
                for r in range(3):
                    for k in range(3):
                        value = 0.0
                        for j in range(3):
                            value += dFds[r, j] * tang[j, k]
                        product[r, k] = value
                dFds = product
            dF = wk.link_dF
            for r in range(3):
                for j in range(m):
                    dF[r, j] = (n[r] + dFdN[r]) * (kf + cf * c_vel) * w_f * D[j]
                    for k in range(3):
                        dF[r, j] += c_vel * w_f * dFds[r, k] * wk.lP[k, j]
            # Q_upper translation += F, lower -= F, angles: P^T F (rotational rows)
            for j in range(m):
                for k in range(gdim):
                    wk.dQ[sup + k, j] += dF[k, j]
                    wk.dQ[slo + k, j] -= dF[k, j]
                for jj in range(m):
                    if not (sup <= jj < sup + gdim or slo <= jj < slo + gdim):
                        value = 0.0
                        for k in range(3):
                            value += wk.lP[k, jj] * dF[k, j]
                        wk.dQ[jj, j] += value
    # site residuals R = dd - dw - H f
    nr = ns * gdim
    _respond(cp, wk.active, n_active, gdim, wk.f, cp.u)
    for r in range(nr):
        wk.Hf[r] = _row_dot(cp.RF, r, cp.u)
        wk.R[r] = dd[r] - wk.dw[r] - wk.Hf[r]
    # body residuals: m (zdd0 + (1 - am) c_acc xi) - load + brake zd_mid - Q
    for j in range(m):
        if bodies.free[j]:
            wk.rz[j] = bodies.mass[j] * (zdd0[j] + (1.0 - am) * c_acc * xi[j]) - bodies.load[j] \
                + bodies.brake[j] * zd_mid[j] - wk.Q[j]
        else:
            wk.rz[j] = 0.0
    return n_active


@njit(cache=True, _nrt=False)
def _scales(bodies, dt, scheme, out):
    """Per-unknown scales of the monotonicity test of the body coordinates (into ``out``, m)."""
    c_vel = scheme[1] / (scheme[0] * dt)
    gdim = bodies.gdim
    for j in range(out.size):
        translation = True
        for b in range(bodies.start.size):
            if j >= bodies.start[b] + gdim and (b + 1 == bodies.start.size or j < bodies.start[b + 1]):
                translation = False
        out[j] = LENGTH_SCALE_M if translation else RATE_SCALE_RAD_PER_S / c_vel


@njit(cache=True)
def _newton_matrix(n_active, wk, cp, model, free_body, dt, site_block=True):
    """J and -R of the Newton system on the active sites' increments and the free body corrections. Without
    ``site_block``, J holds the body rows only (nfb x N: what :func:`_woodbury` needs besides the compliance)."""
    N = n_active * model.bodies.gdim + free_body.size
    J = np.empty((N - (0 if site_block else n_active * model.bodies.gdim), N))
    rhs = np.empty(N)
    _fill_newton_matrix(n_active, wk, cp, model, free_body, dt, site_block, J, rhs, np.empty(wk.xi.size, np.int64))
    return J, rhs


@njit(cache=True, _nrt=False)
def _fill_newton_matrix(n_active, wk, cp, model, free_body, dt, site_block, J, rhs, body_pos):
    """:func:`_newton_matrix` into ``J`` ((N or nfb) x N), ``rhs`` (N) and the work ``body_pos`` (m, int64)."""
    bodies, contacts, sites = model.bodies, model.contacts, model.sites
    gdim = bodies.gdim
    beta, gamma, am, af = model.scheme
    c_acc = 1.0 / (beta * dt * dt)
    c_vel = gamma / (beta * dt)
    w_f = 1.0 - af
    H = cp.H
    nfb = free_body.size
    N = n_active * gdim + nfb
    row0 = 0 if site_block else n_active * gdim
    for r in range(N - row0):
        for c in range(N):
            J[r, c] = 0.0
    for r in range(N):
        rhs[r] = 0.0
    for j in range(body_pos.size):
        body_pos[j] = -1
    for q in range(nfb):
        body_pos[free_body[q]] = n_active * gdim + q
    axl = wk.work.axl
    fxa = wk.fxa
    for a in range(n_active):
        i = wk.active[a]
        for r in range(gdim):
            rhs[a * gdim + r] = -wk.R[i * gdim + r]
    for q in range(nfb):
        rhs[n_active * gdim + q] = -wk.rz[free_body[q]]
    for a in range(n_active):
        k = wk.active[a]
        c = sites.contact[k]
        b = contacts.body[c]
        s0, n_rot = _body_rotations(bodies, b)
        nb = gdim + n_rot
        # site rows: J[i, k] = delta_ik I - H_ik Fd_k ; J[i, body] = - H_ik Fz_k
        for a2 in range(n_active if site_block else 0):
            i = wk.active[a2]
            for r in range(gdim):
                row = a2 * gdim + r
                for cc in range(gdim):
                    value = 0.0
                    for m in range(gdim):
                        value += H[i * gdim + r, k * gdim + m] * wk.Fd[k, m, cc]
                    J[row, a * gdim + cc] -= value
                for kk in range(nb):
                    col = body_pos[s0 + kk]
                    if col < 0:
                        continue
                    value = 0.0
                    for m in range(gdim):
                        value += H[i * gdim + r, k * gdim + m] * wk.Fz[k, m, kk]
                    J[row, col] -= value
        # body rows: the body takes -f_k: d(-Q)/d dd_k
        for r in range(gdim):
            row = body_pos[s0 + r]
            if row < 0:
                continue
            for cc in range(gdim):
                J[row - row0, a * gdim + cc] += wk.Fd[k, r, cc]
        for q in range(n_rot):
            j = s0 + gdim + q
            row = body_pos[j]
            if row < 0:
                continue
            lever = wk.lever[k]
            _cross(bodies.axis[j], lever, axl)
            fk = wk.f[k]
            _cross(fk, bodies.axis[j], fxa)
            for cc in range(gdim):
                J[row - row0, a * gdim + cc] += axl[0] * wk.Fd[k, 0, cc] + axl[1] * wk.Fd[k, 1, cc] \
                    + axl[2] * wk.Fd[k, 2, cc] + w_f * fxa[cc]
    for a in range(n_active if site_block else 0):
        for r in range(gdim):
            J[a * gdim + r, a * gdim + r] += 1.0
    for q in range(nfb):
        j = free_body[q]
        row = n_active * gdim + q
        J[row - row0, row] += bodies.mass[j] * (1.0 - am) * c_acc + bodies.brake[j] * w_f * c_vel
        for q2 in range(nfb):
            J[row - row0, n_active * gdim + q2] -= wk.dQ[j, free_body[q2]]


@njit(cache=True, _nrt=False)
def _woodbury_columns(n_active, active, gdim, RF, col_pos, cols):
    """The free coordinates the active sites' rows touch (the support S of every R_A^T x): ``cols[:n]`` (nf,
    int64) in increasing order and ``col_pos`` (nf, int64) each free coordinate's place in it (-1: not in S).
    Returns n = |S|."""
    nf = col_pos.size
    for j in range(nf):
        col_pos[j] = -1
    for a in range(n_active):
        k = active[a]
        for r in range(gdim):
            row = k * gdim + r
            for e in range(RF.count[row]):
                col_pos[RF.index[row, e]] = 0
    n = 0
    for j in range(nf):
        if col_pos[j] == 0:
            col_pos[j] = n
            cols[n] = j
            n += 1
    return n


class InverseWork(NamedTuple):
    """Work of the Woodbury system's products through K_eff^-1 on S (:func:`_fill_woodbury_inverse`,
    :func:`_woodbury_solve_inverse`; issue 27): K_eff^-T's block on S and R_A^T D R_A, each |S| x |S| in C order in
    the first |S|^2 entries, and one site's block on the coordinates its rows touch."""

    W: np.ndarray             # (s_max * s_max,) W[l, j] = invT[cols[l], cols[j]]: G_A^T's columns S = R_A W
    B: np.ndarray             # (s_max * s_max,) R_A^T D R_A on S (D the active sites' Fd)
    t: np.ndarray             # (s_max,) work: W sol, a body row's R_A^T p
    site: np.ndarray          # (3, u_max) a site's D_k R_k on the coordinates of S its rows touch
    local: np.ndarray         # (u_max,) int64 those coordinates' places in S
    mark: np.ndarray          # (nf,) int64 a place in S -> its place among the site's (-1: none)
    gathered: np.ndarray      # (1,) int64 |S| when the iteration's solves go through K_eff^-1, W gathered on S (-1:
    #                           they take G^T's rows); decided once per matrix (:func:`_fill_woodbury`)
    scalars: np.ndarray       # (2,) work: gemv's alpha and beta


@njit(cache=True)
def inverse_work(s_max, gdim, nf, RF):
    """:class:`InverseWork` for S of at most ``s_max`` coordinates (of ``nf``) and the site rows ``RF``
    (:class:`SparseRows`: a site touches at most gdim x its width)."""
    u_max = max(gdim * RF.index.shape[1], 1)
    return InverseWork(np.zeros(s_max * s_max), np.zeros(s_max * s_max), np.zeros(s_max), np.zeros((3, u_max)),
                       np.zeros(u_max, np.int64), np.full(nf, -1, np.int64), np.full(1, -1, np.int64), np.zeros(2))


#: the ways of the Woodbury matrix and solve: the cheaper (:func:`_fill_woodbury`), G^T's rows, K_eff^-1
WOODBURY_AUTO, WOODBURY_ROWS, WOODBURY_INVERSE = 0, 1, 2


@njit(cache=True)
def _woodbury(n_active, wk, cp, model, free_body, body_rows, full=False, way=WOODBURY_AUTO):
    """The Newton system of many active sites in the structure's free coordinates (Woodbury): with the site
    block I - H_AA D - H_AA E = I - G_A^T R_A^T (D, E) (G^T = R_F K_eff^-1, R_A the active rows; D, E the
    sites' derivatives), y = R_A^T (D x_A + E x_b) and x_A = rhs_A + G_A^T y turn it into
    [[I - R_A^T D G_A^T, -R_A^T E], [P G_A^T, Q]] [y, x_b] = [R_A^T D rhs_A, rhs_b - P rhs_A]
    (``body_rows`` = [P, Q]), of size nf + nfb instead of gdim n_active + nfb. Every R_A^T x lives on the
    coordinates S the active rows touch (:func:`_woodbury_columns`), so y does and G_A^T y needs G^T's columns S
    alone: the same system restricted to S (size |S| + nfb, ``full``: all nf coordinates) is exact. ``way``: the
    cheaper of G^T's rows and K_eff^-1 (:func:`_fill_woodbury`), or the one named. Returns that matrix's LU factors
    ((LU, ipiv): :func:`_factor`), the active sites' D (the next evaluation overwrites wk.Fd), S's columns and
    positions, and the :class:`InverseWork` (``gathered``: whether the solves take K_eff^-1, W gathered)."""
    nf = cp.GT.shape[1]
    cols = np.empty(nf, np.int64)
    col_pos = np.empty(nf, np.int64)
    if full:
        for j in range(nf):
            cols[j] = j
            col_pos[j] = j
        n = nf
    else:
        n = _woodbury_columns(n_active, wk.active, model.bodies.gdim, cp.RF, col_pos, cols)
    k = n + free_body.size
    S = np.empty((k, k))
    D = np.empty((n_active, 3, 3))
    pos = np.empty(wk.xi.size, np.int64)
    iw = inverse_work(n, model.bodies.gdim, nf, cp.RF)
    if way == WOODBURY_AUTO:
        _fill_woodbury(n_active, wk, cp, model, free_body, body_rows, cols[:n], col_pos, S, D, pos, np.empty((6, n)),
                       iw)
    elif way == WOODBURY_ROWS:
        iw.gathered[0] = -1
        _fill_woodbury_rows(n_active, wk, cp, model, free_body, body_rows, cols[:n], col_pos, S, D, pos,
                            np.empty((6, n)))
    else:
        if cp.invT.shape[0] != nf:
            raise ValueError("the Woodbury matrix through K_eff^-1 needs K_eff^-1 (the compliance's invT)")
        _gather_block(cols[:n], cp.invT, iw.W[:n * n].reshape((n, n)))
        iw.gathered[0] = n
        _site_products(n_active, wk, cp.RF, model.bodies.gdim, col_pos, n, D, iw)
        _fill_woodbury_inverse(n_active, wk, cp.RF, model, free_body, body_rows, cols[:n], col_pos, S, pos, iw)
    LU, ipiv = np.empty(k * k), np.empty(k, np.int32)
    _factor(k, S, LU, ipiv)
    return (LU, ipiv), D, cols[:n].copy(), col_pos, iw


@njit(cache=True, _nrt=False)
def _fill_woodbury(n_active, wk, cp, model, free_body, body_rows, cols, col_pos, S, D, pos, FG, iw):
    """:func:`_woodbury`'s matrix on the coordinates ``cols`` into ``S`` and the sites' derivatives into ``D``, the
    cheaper of two ways (issue 27), by their counts weighted as GATHER_COST and INDEXED_COST say: G^T's rows of every
    active site row gathered on S (:func:`_fill_woodbury_rows`: n_rows x |S| gathers, n_rows x |S| x gdim for
    D_k G_k^T, nnz_A x |S| for the updates of S, nfb x n_rows x |S| for the body rows), or K_eff^-1: its block W on S
    gathered (|S|^2), B = R_A^T D R_A summed site by site (:func:`_site_products`: indexed updates on each site's few
    touched coordinates, ~nnz_A x their count), then S = I - B W (nnz(B) x |S|) and the body rows through R_A^T
    (nfb x (nnz_A + |S|^2); :func:`_fill_woodbury_inverse`). The collapsed rotor (1 536 rows, |S| = 192, nnz(B)
    = 4 032): ~4.0 M against ~2.2 M weighted; the seated one (207 rows on 72) keeps G^T's rows (0.22 M against
    >= 0.26 M; taken through K_eff^-1 it cost 0.39 against 0.26 ms a step). nnz(B) is known once B is summed: B is
    formed where a lower bound (|S| x the widest row) leaves K_eff^-1 cheaper (dense rows never), then kept or dropped
    by the whole count. Also gathers W (``iw``, :class:`InverseWork`) where :func:`_woodbury_solve_into` will take
    K_eff^-1."""
    gdim = model.bodies.gdim
    RF = cp.RF
    ns = cols.size
    nfb = free_body.size
    n_rows = n_active * gdim
    nnz = 0
    widest = 0
    for a in range(n_active):
        for r in range(gdim):
            count = RF.count[wk.active[a] * gdim + r]
            nnz += count
            widest = max(widest, count)
    iw.gathered[0] = -1
    if cp.invT.shape[0] != cp.GT.shape[1]:
        _fill_woodbury_rows(n_active, wk, cp, model, free_body, body_rows, cols, col_pos, S, D, pos, FG)
        return
    # the iteration's solves (one per Newton correction and line-search trial) on the same rows: decided here, once
    solves_inverse = _solve_takes_inverse(ns, nnz, n_rows)
    # G^T's rows: the gathers, D_k G_k^T, the updates of S's site rows, the body rows
    cost_rows = n_rows * ns * (GATHER_COST + gdim) + nnz * ns + nfb * n_rows * ns
    # K_eff^-1: W gathered, B zeroed and counted, its rows scanned; B's sum (indexed updates, >= nnz x widest); the
    # body rows' scatters and products; then nnz(B) x |S| for B W, at least |S| x widest (each row of B holds a
    # site's whole block) before B is summed
    cost_inverse = 4 * GATHER_COST * ns * ns + INDEXED_COST * nnz * (gdim + widest) \
        + nfb * (INDEXED_COST * nnz + ns * ns)
    W = iw.W[:ns * ns].reshape((ns, ns))
    have_W = False
    if cost_inverse + ns * widest * ns < cost_rows:
        _gather_block(cols, cp.invT, W)
        have_W = True
        nnz_B = _site_products(n_active, wk, RF, gdim, col_pos, ns, D, iw)
        if cost_inverse + nnz_B * ns < cost_rows:
            _fill_woodbury_inverse(n_active, wk, RF, model, free_body, body_rows, cols, col_pos, S, pos, iw)
            if solves_inverse:
                iw.gathered[0] = ns
            return
    _fill_woodbury_rows(n_active, wk, cp, model, free_body, body_rows, cols, col_pos, S, D, pos, FG)
    if solves_inverse:
        if not have_W:
            _gather_block(cols, cp.invT, W)
        iw.gathered[0] = ns


@njit(cache=True, _nrt=False)
def _solve_takes_inverse(ns, nnz, n_rows):
    """The Woodbury solve's cost rule, asked once per matrix by :func:`_fill_woodbury` (its answer in
    InverseWork.gathered, which :func:`_woodbury_solve_into` reads): R_A (W sol), |S|^2 + nnz_A gathered elements,
    against G^T's rows gathered on S, n_rows x |S|."""
    return ns * ns + GATHER_COST * nnz < GATHER_COST * n_rows * ns


@njit(cache=True, _nrt=False)
def _gather_block(cols, A, W):
    """W[l, j] = A[cols[l], cols[j]] (|S|^2): with A = K_eff^-T, G^T[r, cols[j]] = sum_l R_F[r, cols[l]] W[l, j]."""
    n = cols.size
    for l in range(n):
        row = A[cols[l]]
        target = W[l]
        for j in range(n):
            target[j] = row[cols[j]]


@njit(cache=True, _nrt=False)
def _site_products(n_active, wk, RF, gdim, col_pos, ns, D, iw):
    """B = R_A^T D R_A on S (``iw.B``, ns x ns) summed over the active sites k of R_k^T (D_k R_k), D_k = wk.Fd[k]
    (copied into ``D``: the next evaluation overwrites wk.Fd), each on the coordinates of S site k's rows touch (its
    union, ``iw.local``, u of them): D_k R_k is gdim x u (gdim x its rows' nnz), its product with R_k^T is the rows'
    nnz x u, scattered into B. Returns nnz(B)."""
    B = iw.B[:ns * ns].reshape((ns, ns))
    for i in range(ns):
        for j in range(ns):
            B[i, j] = 0.0
    mark, local, site = iw.mark, iw.local, iw.site
    for a in range(n_active):
        k = wk.active[a]
        for r in range(3):
            for c in range(3):
                D[a, r, c] = 0.0
        for r in range(gdim):
            for c in range(gdim):
                D[a, r, c] = wk.Fd[k, r, c]
        u = 0
        for c in range(gdim):
            row = k * gdim + c
            for e in range(RF.count[row]):
                place = col_pos[RF.index[row, e]]
                if mark[place] < 0:
                    mark[place] = u
                    local[u] = place
                    u += 1
        for r in range(gdim):
            for t in range(u):
                site[r, t] = 0.0
        for c in range(gdim):
            row = k * gdim + c
            for e in range(RF.count[row]):
                t = mark[col_pos[RF.index[row, e]]]
                value = RF.value[row, e]
                for r in range(gdim):
                    site[r, t] += D[a, r, c] * value
        for r in range(gdim):
            row = k * gdim + r
            for e in range(RF.count[row]):
                Bi = B[col_pos[RF.index[row, e]]]
                value = RF.value[row, e]
                for t in range(u):
                    Bi[local[t]] += value * site[r, t]
        for t in range(u):
            mark[local[t]] = -1
    nnz = 0
    for i in range(ns):
        for j in range(ns):
            if B[i, j] != 0.0:
                nnz += 1
    return nnz


@njit(cache=True, _nrt=False)
def _fill_woodbury_inverse(n_active, wk, RF, model, free_body, body_rows, cols, col_pos, S, pos, iw):
    """:func:`_fill_woodbury` through K_eff^-1, with ``iw.W`` gathered and ``iw.B`` summed (:func:`_site_products`):
    S's site block I - R_A^T D G_A^T on S = I - B W (row i: the nonzeros l of B's row i, W's rows l, vectorised:
    :func:`_subtract_scaled`), the body columns -R_A^T E as :func:`_fill_woodbury_rows` has them, the body rows
    P G_A^T on S = (R_A^T p_q)^T W (p_q: row q of ``body_rows``' site part)."""
    gdim = model.bodies.gdim
    ns = cols.size
    nfb = free_body.size
    W = iw.W[:ns * ns].reshape((ns, ns))
    B = iw.B[:ns * ns].reshape((ns, ns))
    h = iw.t
    _woodbury_start(S, ns, free_body, pos)
    for i in range(ns):
        Bi = B[i]
        for l in range(ns):
            value = Bi[l]
            if value != 0.0:
                _subtract_scaled(ns, value, W[l], S[i])
    _subtract_body_columns(n_active, wk, RF, model, col_pos, ns, pos, S)
    for q in range(nfb):
        for j in range(ns):
            h[j] = 0.0
        for a in range(n_active):
            k = wk.active[a]
            for cc in range(gdim):
                p = body_rows[q, a * gdim + cc]
                if p != 0.0:
                    row = k * gdim + cc
                    for e in range(RF.count[row]):
                        h[col_pos[RF.index[row, e]]] += p * RF.value[row, e]
        target = S[ns + q]
        for l in range(ns):
            if h[l] != 0.0:
                _subtract_scaled(ns, -h[l], W[l], target)          # + h_l W[l], exactly
    for q in range(nfb):
        for q2 in range(nfb):
            S[ns + q, ns + q2] = body_rows[q, n_active * gdim + q2]


@njit(cache=True, _nrt=False)
def _fill_woodbury_rows(n_active, wk, cp, model, free_body, body_rows, cols, col_pos, S, D, pos, FG):
    """:func:`_woodbury`'s matrix by G^T's rows: on the coordinates ``cols`` (their places ``col_pos``) into ``S``
    (k x k, k = cols.size + nfb) and the sites' derivatives into ``D`` (n_active, 3, 3); ``pos`` (m,) int64 and
    ``FG`` (6, >= cols.size) work: a site's rows of G^T on S gathered (rows 3-5), D_k times them (rows 0-2), so every
    update of S is a whole row of contiguous numbers (:func:`_subtract_scaled`, which the compiler vectorises: issue
    27, BENCHMARKS.md), each entry's terms added in the order of the loops they replace (the same numbers)."""
    gdim = model.bodies.gdim
    GT, RF = cp.GT, cp.RF
    ns = cols.size
    nfb = free_body.size
    _woodbury_start(S, ns, free_body, pos)
    for a in range(n_active):
        for r in range(3):
            for c in range(3):
                D[a, r, c] = 0.0
    G = FG[3:]
    for a in range(n_active):
        k = wk.active[a]
        for cc in range(gdim):
            row = GT[k * gdim + cc]
            g = G[cc]
            for j in range(ns):
                g[j] = row[cols[j]]
        for r in range(gdim):
            for cc in range(gdim):
                D[a, r, cc] = wk.Fd[k, r, cc]
            _combine_rows(ns, gdim, wk.Fd[k, r], G, FG[r])
        for r in range(gdim):
            row = k * gdim + r
            for e in range(RF.count[row]):
                idx = col_pos[RF.index[row, e]]
                val = RF.value[row, e]
                _subtract_scaled(ns, val, FG[r], S[idx])
        for q in range(nfb):
            for cc in range(gdim):
                p = body_rows[q, a * gdim + cc]
                if p != 0.0:
                    _subtract_scaled(ns, -p, G[cc], S[ns + q])      # y - (-p) x = y + p x exactly
    _subtract_body_columns(n_active, wk, RF, model, col_pos, ns, pos, S)
    for q in range(nfb):
        for q2 in range(nfb):
            S[ns + q, ns + q2] = body_rows[q, n_active * gdim + q2]


@njit(cache=True, _nrt=False)
def _woodbury_start(S, ns, free_body, pos):
    """The Woodbury matrix S (k x k, k = ns + nfb) set to I on its site block and 0 elsewhere, and ``pos`` (m,)
    each body coordinate's place among the free ones (-1: not free)."""
    k = ns + free_body.size
    for r in range(k):
        for c in range(k):
            S[r, c] = 0.0
    for j in range(ns):
        S[j, j] = 1.0
    for j in range(pos.size):
        pos[j] = -1
    for q in range(free_body.size):
        pos[free_body[q]] = q


@njit(cache=True, _nrt=False)
def _subtract_body_columns(n_active, wk, RF, model, col_pos, ns, pos, S):
    """The Woodbury matrix's body columns, -R_A^T E (E the active sites' derivatives by their body's free
    coordinates, wk.Fz), into S[:ns, ns:]: each entry's terms subtracted site by site, row by row (the order both
    ways of :func:`_fill_woodbury` share)."""
    bodies, contacts, sites = model.bodies, model.contacts, model.sites
    gdim = bodies.gdim
    for a in range(n_active):
        k = wk.active[a]
        s0, n_rot = _body_rotations(bodies, contacts.body[sites.contact[k]])
        for r in range(gdim):
            row = k * gdim + r
            for e in range(RF.count[row]):
                idx = col_pos[RF.index[row, e]]
                val = RF.value[row, e]
                for kk in range(gdim + n_rot):
                    q = pos[s0 + kk]
                    if q >= 0:
                        S[idx, ns + q] -= val * wk.Fz[k, r, kk]


@njit(cache=True, _nrt=False)
def _fortran_copy(k, A, out):
    """out[:k * k] <- the k x k block of A in Fortran order, as np.linalg's LAPACK calls copy it, refusing infs and
    NaNs with its message."""
    for r in range(k):
        for c in range(k):
            value = A[r, c]
            if not math.isfinite(value):
                raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
            out[c * k + r] = value


@njit(cache=True, _nrt=False)
def _factor(k, S, LU, ipiv):
    """LU (k * k) <- the LU factors of S (P S = L U, L unit lower) in Fortran order, ipiv (k, int32) LAPACK's row
    interchanges, by getrf on a Fortran-order copy of S. Each Newton iteration solves with its matrix once plus
    once per line-search trial, so the factors (2/3 k^3) and a pair of triangular solves per right side (2 k^2,
    :func:`_lu_apply`) cost less than an explicit inverse (getri: another 4/3 k^3, the larger part of a collapsed
    rotor's step, k ~ 220)."""
    _fortran_copy(k, S, LU)
    if k > 0:
        if _xgetrf(_XGESV_KIND, k, k, LU.ctypes, k, ipiv.ctypes) != 0:
            raise np.linalg.LinAlgError("Matrix is singular to machine precision.")


@njit(cache=True, _nrt=False)
def _lu_apply(k, LU, ipiv, b, x):
    """x (k) <- S^-1 b from :func:`_factor`'s LU and ipiv (x may be b): LAPACK getrs' steps (the row interchanges
    in order, then L y = P b forward and U x = y backward), column by column over the Fortran-order factors so the
    inner loops run over contiguous memory."""
    for i in range(k):
        x[i] = b[i]
    for i in range(k):
        p = ipiv[i] - 1
        if p != i:
            value = x[i]
            x[i] = x[p]
            x[p] = value
    for j in range(k):
        xj = x[j]
        if xj != 0.0:
            base = j * k
            for i in range(j + 1, k):
                x[i] -= LU[base + i] * xj
    for j in range(k - 1, -1, -1):
        base = j * k
        x[j] /= LU[base + j]
        xj = x[j]
        if xj != 0.0:
            for i in range(j):
                x[i] -= LU[base + i] * xj


@njit(cache=True)
def _woodbury_solve(factors, D, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, iw, way=WOODBURY_AUTO):
    """x of J x = rhs through :func:`_woodbury`'s matrix (its LU ``factors``, the sites' ``D``, its coordinates
    ``cols`` and their places ``col_pos``, its :class:`InverseWork` ``iw``); ``way`` as :func:`_woodbury`'s."""
    LU, ipiv = factors
    k = ipiv.size
    x = np.empty(rhs.size)
    if way == WOODBURY_AUTO:
        _woodbury_solve_into(LU, ipiv, D, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, x, np.empty(k),
                             np.empty(k), iw)
    elif way == WOODBURY_ROWS:
        _woodbury_solve_rows(LU, ipiv, D, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, x, np.empty(k),
                             np.empty(k))
    else:
        if iw.gathered[0] != cols.size or cp.invT.shape[0] != cp.GT.shape[1]:
            raise ValueError("the solve through K_eff^-1 needs K_eff^-1 and its block W on these coordinates gathered")
        _woodbury_solve_inverse(LU, ipiv, D, cols, col_pos, active, n_active, gdim, cp.RF, body_rows, rhs, x,
                                np.empty(k), np.empty(k), iw)
    return x


@njit(cache=True, _nrt=False)
def _woodbury_solve_into(LU, ipiv, D, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, x, small, sol, iw):
    """:func:`_woodbury_solve` into ``x`` (may be ``rhs``) with the matrix's factors (``LU``, ``ipiv``:
    :func:`_factor`; its size |S| + nfb); ``small`` and ``sol`` (>= that size) work. The active rows' part
    x_A = rhs_A + G_A^T[:, S] sol the cheaper of two ways (issue 27): G^T's rows gathered on S
    (:func:`_woodbury_solve_rows`: n_rows x |S| gathered elements), or R_A (W sol) with K_eff^-1's block W on S
    (:func:`_woodbury_solve_inverse`: |S|^2 by gemv + nnz_A gathered), as :func:`_fill_woodbury` decided for the
    matrix (``iw.gathered``: :func:`_solve_takes_inverse`)."""
    if iw.gathered[0] == cols.size:
        _woodbury_solve_inverse(LU, ipiv, D, cols, col_pos, active, n_active, gdim, cp.RF, body_rows, rhs, x,
                                small, sol, iw)
        return
    _woodbury_solve_rows(LU, ipiv, D, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, x, small, sol)


@njit(cache=True, _nrt=False)
def _woodbury_right_side(D, col_pos, active, n_active, gdim, RF, body_rows, rhs, ns, small):
    """The Woodbury system's right side [R_A^T D rhs_A, rhs_b - P rhs_A] into ``small`` (|S| + nfb)."""
    na = n_active * gdim
    nfb = rhs.size - na
    for j in range(ns + nfb):
        small[j] = 0.0
    for a in range(n_active):
        k = active[a]
        for r in range(gdim):
            value = 0.0
            for cc in range(gdim):
                value += D[a, r, cc] * rhs[a * gdim + cc]
            row = k * gdim + r
            for e in range(RF.count[row]):
                small[col_pos[RF.index[row, e]]] += RF.value[row, e] * value
    for q in range(nfb):
        value = rhs[na + q]
        for col in range(na):
            value -= body_rows[q, col] * rhs[col]
        small[ns + q] = value


@njit(cache=True, _nrt=False)
def _woodbury_solve_inverse(LU, ipiv, D, cols, col_pos, active, n_active, gdim, RF, body_rows, rhs, x, small, sol,
                            iw):
    """:func:`_woodbury_solve_into` through K_eff^-1: G_A^T[:, S] = R_A W (W = iw.W, K_eff^-T on S x S), so
    x_A = rhs_A + R_A t with t = W sol (gemv, |S|^2) and each active row's few entries of t (nnz_A)."""
    ns = cols.size
    na = n_active * gdim
    nfb = rhs.size - na
    _woodbury_right_side(D, col_pos, active, n_active, gdim, RF, body_rows, rhs, ns, small)
    _lu_apply(ns + nfb, LU, ipiv, small, sol)
    t = iw.t[:ns]
    _matvec(iw.W[:ns * ns].reshape((ns, ns)), sol[:ns], t, iw.scalars)
    for a in range(n_active):
        k = active[a]
        for r in range(gdim):
            row = k * gdim + r
            value = 0.0
            for e in range(RF.count[row]):
                value += RF.value[row, e] * t[col_pos[RF.index[row, e]]]
            x[a * gdim + r] = rhs[a * gdim + r] + value
    for q in range(nfb):
        x[na + q] = sol[ns + q]


@njit(cache=True, _nrt=False)
def _woodbury_solve_rows(LU, ipiv, D, cols, col_pos, active, n_active, gdim, cp, body_rows, rhs, x, small, sol):
    """:func:`_woodbury_solve_into` by G^T's rows gathered on S (n_rows x |S|)."""
    GT, RF = cp.GT, cp.RF
    ns = cols.size
    na = n_active * gdim
    nfb = rhs.size - na
    _woodbury_right_side(D, col_pos, active, n_active, gdim, RF, body_rows, rhs, ns, small)
    _lu_apply(ns + nfb, LU, ipiv, small, sol)
    for a in range(n_active):
        k = active[a]
        for r in range(gdim):
            row = GT[k * gdim + r]
            value = rhs[a * gdim + r]
            for j in range(ns):
                value += row[cols[j]] * sol[j]
            x[a * gdim + r] = value
    for q in range(nfb):
        x[na + q] = sol[ns + q]


class NewtonWork(NamedTuple):
    """The Newton iteration's arrays (allocated once per call): its system in the contact space (at most ``size``
    unknowns: the active sites' increments and the free body corrections; C order in the first N^2 entries of
    ``J``), its copy in Fortran order for LAPACK's gesv, the corrections, and the Woodbury system of many active
    sites on the coordinates their rows touch (:func:`_woodbury`; empty where it cannot be taken)."""

    J: np.ndarray             # (size * size,)
    LU: np.ndarray            # (size * size,)
    ipiv: np.ndarray          # (size,) int32 (LAPACK's integer)
    rhs: np.ndarray           # (nr + m,) -R of the active sites and the free body coordinates
    dy: np.ndarray            # (nr + m,) the Newton correction
    trial: np.ndarray         # (nr + m,) -R at the trial point, then the simplified correction
    scale: np.ndarray         # (nr + m,) the unknowns' scales
    scale_b: np.ndarray       # (m,) the body coordinates' scales
    body_pos: np.ndarray      # (m,) int64
    active: np.ndarray        # (ns,) int64 the active sites of the iteration's matrix
    du: np.ndarray            # (nr,) every site's correction
    df: np.ndarray            # (ns, 3) the active sites' force corrections
    dxi: np.ndarray           # (m,) the body corrections
    S: np.ndarray             # (k * k,) the Woodbury matrix, k = |S| + m, |S| at most newton_work's s_max
    S_LU: np.ndarray          # (k * k,) its LU factors in Fortran order (getrf in place: _factor)
    S_ipiv: np.ndarray        # (k,) int32
    FG: np.ndarray            # (6, s_max) work (:func:`_fill_woodbury_rows`)
    small: np.ndarray         # (k,) work
    sol: np.ndarray           # (k,) work
    scalars: np.ndarray       # (2,) work: gemv's alpha and beta
    D: np.ndarray             # (ns, 3, 3) the active sites' derivatives for it
    body_rows: np.ndarray     # (m * (nr + m),) the body rows of J for it
    cols: np.ndarray          # (nf,) int64 the coordinates S the active rows touch (:func:`_woodbury_columns`)
    col_pos: np.ndarray       # (nf,) int64 each free coordinate's place in S (-1: none)
    inverse: InverseWork      # the Woodbury system's products through K_eff^-1 (:func:`_fill_woodbury`)


@njit(cache=True)
def newton_work(ns, gdim, m, nf, RF):
    """:class:`NewtonWork` of ``ns`` sites, ``m`` body coordinates, ``nf`` free structure coordinates and the
    site rows ``RF`` (:class:`SparseRows`, free numbering). The Woodbury system is taken on |S| coordinates when
    gdim n_active > WOODBURY_FACTOR |S| (:func:`_newton`), so |S| stays below nr / WOODBURY_FACTOR, nf and the
    count of coordinates any site row touches: s_max, its buffers' size."""
    nr = ns * gdim
    size = min(nr, int(WOODBURY_FACTOR * nf)) + m
    touched = np.zeros(nf, np.bool_)
    for row in range(min(nr, RF.count.size)):
        for e in range(RF.count[row]):
            touched[RF.index[row, e]] = True
    s_max = min(int(np.sum(touched)), int(nr / WOODBURY_FACTOR) + 1)
    woodbury = nr > 0
    k = s_max + m if woodbury else 0
    return NewtonWork(np.zeros(size * size), np.zeros(size * size), np.zeros(size, np.int32), np.zeros(nr + m),
                      np.zeros(nr + m), np.zeros(nr + m), np.zeros(nr + m), np.zeros(m), np.zeros(m, np.int64),
                      np.zeros(max(ns, 1), np.int64), np.zeros(nr), np.zeros((ns, 3)), np.zeros(m),
                      np.zeros(k * k), np.zeros(k * k), np.zeros(k, np.int32),
                      np.zeros((6, s_max if woodbury else 0)), np.zeros(k), np.zeros(k), np.zeros(2),
                      np.zeros((ns if woodbury else 0, 3, 3)), np.zeros(m * (nr + m) if woodbury else 0),
                      np.zeros(nf, np.int64), np.zeros(nf, np.int64),
                      inverse_work(s_max if woodbury else 0, gdim, nf, RF))


@njit(cache=True, _nrt=False)
def _matvec(A, x, y, scalars):
    """y = A x (A C- or Fortran-ordered) by BLAS's gemv as np.dot(A, x, y) calls it (the same numbers);
    ``scalars`` (2) work."""
    scalars[0] = 1.0
    scalars[1] = 0.0
    if A.shape[1] == 0:
        for i in range(y.size):
            y[i] = 0.0
        return
    if A.strides[0] >= A.strides[1]:        # C order: the transposed product of the Fortran view
        _xgemv(_XGESV_KIND, _TRANSPOSED, A.shape[1], A.shape[0], scalars[0:].ctypes, A.ctypes, A.shape[1], x.ctypes,
               scalars[1:].ctypes, y.ctypes)
    else:
        _xgemv(_XGESV_KIND, _NOT_TRANSPOSED, A.shape[0], A.shape[1], scalars[0:].ctypes, A.ctypes, A.shape[0], x.ctypes,
               scalars[1:].ctypes, y.ctypes)


@njit(cache=True, _nrt=False)
def _lu_solve(N, J, LU, ipiv, x):
    """x (N, holding the right side) <- J^-1 x by LAPACK's gesv: the routine np.linalg.solve calls, on the same
    Fortran-order copy of J (kept), so the same result to the bit, without its three allocations per call."""
    _fortran_copy(N, J, LU)
    for r in range(N):
        if not math.isfinite(x[r]):
            raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
    if N == 0:
        return
    info = _xgesv(_XGESV_KIND, N, 1, LU.ctypes, N, ipiv.ctypes, x.ctypes, N)
    if info != 0:
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")


@njit(cache=True, _nrt=False)
def _newton(wk, nw, cp, state, dt, model, free_body):
    """Newton on the condensed step; True when converged (wk.dd, wk.xi hold the solution). Returns
    (converged, iterations). Compiled without reference counts (as the evaluation): its arrays are the work
    records' (``nw``: :class:`NewtonWork`)."""
    bodies, sites, contacts = model.bodies, model.sites, model.contacts
    scheme = model.scheme
    zdd0, zd_mid = state.zdd, wk.zd_mid
    gdim = bodies.gdim
    nr = wk.dd.size
    m = wk.xi.size
    nfb = free_body.size
    tol_site = SITE_TOL_M
    for r in range(nr):
        tol_site = max(tol_site, SITE_RTOL * abs(wk.dw[r]))
    n_active = _evaluate(wk.dd, wk.xi, wk, cp, state, dt, model, True)
    scale_b = nw.scale_b
    _scales(bodies, dt, scheme, scale_b)
    active_rows = nw.active
    du, df, dxi = nw.du, nw.df, nw.dxi
    its = 0
    for its in range(1, MAX_NEWTON + 1):
        res = 0.0
        for r in range(nr):
            res = max(res, abs(wk.R[r]) / tol_site)
        for q in range(nfb):
            j = free_body[q]
            scale = abs(bodies.load[j]) + abs(bodies.mass[j] * zdd0[j]) + abs(wk.Q[j]) \
                + abs(bodies.brake[j] * zd_mid[j])
            tol = FORCE_RTOL * scale + 1e-300
            res = max(res, abs(wk.rz[j]) / tol)
        if res <= 1.0:
            return True, its
        # many active sites (a rotor lying on the ring): the system on the structure's coordinates their rows touch
        # (S, of |S| coordinates) is smaller
        for a in range(n_active):
            active_rows[a] = wk.active[a]
        n_cols = _woodbury_columns(n_active, active_rows, gdim, cp.RF, nw.col_pos, nw.cols)
        woodbury = n_active * gdim > WOODBURY_FACTOR * n_cols
        N = n_active * gdim + nfb
        dy = nw.dy[:N]
        NJ = 0 if woodbury else N          # the contact-space matrix (its buffer holds no larger one)
        J = nw.J[:NJ * NJ].reshape((NJ, NJ))
        # the Woodbury system's views (empty when it is not taken: its buffers may be)
        k_s = n_cols + nfb if woodbury else 0       # the Woodbury matrix's size (k is a site below)
        cols = nw.cols[:n_cols if woodbury else 0]
        D = nw.D[:n_active if woodbury else 0]
        body_rows = nw.body_rows[:nfb * N if woodbury else 0].reshape((nfb if woodbury else 0, N))
        if woodbury:
            rhs = nw.rhs[:N]
            _fill_newton_matrix(n_active, wk, cp, model, free_body, dt, False, body_rows, rhs, nw.body_pos)
            _fill_woodbury(n_active, wk, cp, model, free_body, body_rows, cols, nw.col_pos,
                           nw.S[:k_s * k_s].reshape((k_s, k_s)), D, nw.body_pos, nw.FG, nw.inverse)
            _factor(k_s, nw.S[:k_s * k_s].reshape((k_s, k_s)), nw.S_LU, nw.S_ipiv)
            _woodbury_solve_into(nw.S_LU, nw.S_ipiv, D, cols, nw.col_pos, active_rows, n_active, gdim, cp,
                                 body_rows, rhs, dy, nw.small, nw.sol, nw.inverse)
        else:
            rhs = nw.rhs[:N]
            _fill_newton_matrix(n_active, wk, cp, model, free_body, dt, True, J, rhs, nw.body_pos)
            for r in range(N):
                dy[r] = rhs[r]
            _lu_solve(N, J, nw.LU, nw.ipiv, dy)
        # the correction of every site: active ones from dy; a separated one follows from the others
        # (its force is zero): du_I = -R_I + H_IA (Fd_A du_A + Fz_A dxi)
        for r in range(nr):
            du[r] = -wk.R[r]
        for i in range(df.shape[0]):
            for r in range(3):
                df[i, r] = 0.0
        for a in range(n_active):
            k = wk.active[a]
            c = sites.contact[k]
            b = contacts.body[c]
            s0, n_rot = _body_rotations(bodies, b)
            for r in range(gdim):
                value = 0.0
                for cc in range(gdim):
                    value += wk.Fd[k, r, cc] * dy[a * gdim + cc]
                for kk in range(gdim + n_rot):
                    for q in range(nfb):
                        if free_body[q] == s0 + kk:
                            value += wk.Fz[k, r, kk] * dy[n_active * gdim + q]
                df[k, r] = value
        _respond(cp, wk.active, n_active, gdim, df, cp.du)
        for r in range(nr):
            du[r] += _row_dot(cp.RF, r, cp.du)
        for a in range(n_active):
            k = wk.active[a]
            for r in range(gdim):
                du[k * gdim + r] = dy[a * gdim + r]
        for j in range(m):
            dxi[j] = 0.0
        for q in range(nfb):
            dxi[free_body[q]] = dy[n_active * gdim + q]
        # damped Newton, natural monotonicity test (Deuflhard): the simplified correction at the trial point,
        # J^-1 R(trial) with this iteration's J, must be shorter than the Newton correction (scaled unknowns)
        scale = nw.scale
        for r in range(n_active * gdim):
            scale[r] = LENGTH_SCALE_M
        for q in range(nfb):
            scale[n_active * gdim + q] = scale_b[free_body[q]]
        size0 = _scaled_norm(dy, scale, N)
        lam = 1.0
        n_trial = n_active
        trial = nw.trial[:N]
        for _ in range(14):
            for r in range(nr):
                wk.dd_try[r] = wk.dd[r] + lam * du[r]
            for j in range(m):
                wk.xi_try[j] = wk.xi[j] + lam * dxi[j]
            n_trial = _evaluate(wk.dd_try, wk.xi_try, wk, cp, state, dt, model, True)
            for a in range(n_active):
                i = active_rows[a]
                for r in range(gdim):
                    trial[a * gdim + r] = -wk.R[i * gdim + r]
            for q in range(nfb):
                trial[n_active * gdim + q] = -wk.rz[free_body[q]]
            if woodbury:
                _woodbury_solve_into(nw.S_LU, nw.S_ipiv, D, cols, nw.col_pos, active_rows, n_active, gdim, cp,
                                     body_rows, trial, trial, nw.small, nw.sol, nw.inverse)
            else:
                _lu_solve(N, J, nw.LU, nw.ipiv, trial)
            if _scaled_norm(trial, scale, N) <= (1.0 - 0.5 * lam) * size0 + 1e-300:
                break
            lam *= 0.5
        for r in range(nr):
            wk.dd[r] = wk.dd_try[r]
        for j in range(m):
            wk.xi[j] = wk.xi_try[j]
        n_active = n_trial
        if lam < 1e-3 and res < ROUND_OFF_FACTOR:
            return True, its          # no descent left within a few of the tolerances: round-off floor
    return False, its


@njit(cache=True, _nrt=False)
def _scaled_norm(x, scale, N):
    """sqrt(sum((x / scale)^2)) over the first N entries, summed in order (as np.sum)."""
    total = 0.0
    for r in range(N):
        value = x[r] / scale[r]
        total += value * value
    return math.sqrt(total)


# ------------------------------------------------------------------ the loop
class Cache(NamedTuple):
    """Per step size: K_eff^-1 of the free coordinates (also transposed: its columns as contiguous rows, for the
    products through it, :func:`_respond`), G = K_eff^-1 R_F^T (kept as G^T: its rows are the sites') and H = R_F G
    (kept between calls; a function of dt alone, so they change the cost of a call, never its result)."""

    dt: np.ndarray            # (slots,), -1 = empty
    inv: np.ndarray           # (slots, nf, nf)
    GT: np.ndarray            # (slots, nr, nf)
    H: np.ndarray             # (slots, nr, nr)
    next: np.ndarray          # (1,) the slot to fill next
    invT: np.ndarray          # (slots, nf, nf) inv transposed: its rows are K_eff^-1's columns (Compliance.invT)


def make_cache(nf: int, nr: int, budget_bytes: float = 3e8) -> Cache:
    per_slot = 8.0 * (2 * nf * nf + nf * nr + nr * nr) + 8
    slots = int(max(2, min(24, budget_bytes // per_slot)))
    return Cache(np.full(slots, -1.0), np.zeros((slots, nf, nf)), np.zeros((slots, nr, nf)),
                 np.zeros((slots, nr, nr)), np.zeros(1, np.int64), np.zeros((slots, nf, nf)))


@njit(cache=True, _nrt=False)
def _cached_slot(dts, dt):
    """The slot of step size ``dt`` among the cache's step sizes ``dts`` (-1: an empty slot), or -1. Takes the one
    array, not the cache record, so the loop asks it every step without reference counts."""
    for c in range(dts.size):
        if dts[c] > 0 and abs(dts[c] - dt) <= 1e-12 * dt:
            return c
    return -1


@njit(cache=True)
def _effective(structure, rows, dt, scheme, cache):
    """The cache slot of step size dt (formed on first use)."""
    slot = _cached_slot(cache.dt, dt)
    if slot >= 0:
        return slot
    beta, gamma, am, af = scheme
    c_acc = 1.0 / (beta * dt * dt)
    c_vel = gamma / (beta * dt)
    free = structure.free
    nf = free.size
    A = np.empty((nf, nf))
    for i in range(nf):
        for k in range(nf):
            a, b = free[i], free[k]
            A[i, k] = (1.0 - am) * c_acc * structure.M[a, b] + (1.0 - af) * c_vel * structure.C[a, b] \
                + (1.0 - af) * structure.K[a, b]
    slot = cache.next[0]
    cache.next[0] = (slot + 1) % cache.dt.size
    cache.dt[slot] = dt
    cache.inv[slot] = np.linalg.inv(A)
    for i in range(nf):
        for k in range(nf):
            cache.invT[slot, k, i] = cache.inv[slot, i, k]
    RF = np.empty((rows.shape[0], nf))
    for r in range(rows.shape[0]):
        for i in range(nf):
            RF[r, i] = rows[r, free[i]]
    G = cache.inv[slot] @ RF.T
    cache.GT[slot] = G.T
    cache.H[slot] = RF @ G
    return slot


@njit(cache=True, _nrt=False)
def _diagonal_free(structure):
    """True when M and K are diagonal on the free coordinates (exact zeros off the diagonal: the model in its free
    modes, app/reduced/coordinates.py), so :func:`_free_increment_modal` applies."""
    free, M, K = structure.free, structure.M, structure.K
    for i in range(free.size):
        for k in range(free.size):
            if i != k and (M[free[i], free[k]] != 0.0 or K[free[i], free[k]] != 0.0):
                return False
    return True


@njit(cache=True)
def _modal_terms(structure):
    """What :func:`_free_increment_modal` reads of the structure, contiguous (formed once per call of the loop; read
    in place, the diagonals and input columns of the n x n matrices cost a cache line per entry): (3, nf) the free
    diagonal of M and of K and the free load; (3, inputs, nf) the free rows of M, C and K on each input column."""
    free, P = structure.free, structure.inputs
    diagonal = np.empty((3, free.size))
    coupling = np.empty((3, P.size, free.size))
    for i in range(free.size):
        diagonal[0, i] = structure.M[free[i], free[i]]
        diagonal[1, i] = structure.K[free[i], free[i]]
        diagonal[2, i] = structure.load[free[i]]
        for p in range(P.size):
            coupling[0, p, i] = structure.M[free[i], P[p]]
            coupling[1, p, i] = structure.C[free[i], P[p]]
            coupling[2, p, i] = structure.K[free[i], P[p]]
    return diagonal, coupling


@njit(cache=True, _nrt=False)
def _predictor(q, v, a, pq, dt, P, scheme, dq, y):
    """The contact-free step's predictor: ``dq`` (n) = dt v + dt^2 a / 2, the prescribed inputs ``P`` at their
    values ``pq`` at t1; ``y`` (3, n) the generalized mid-point arguments of M, C and K: (1 - am) a1 + am a,
    (1 - af) v1 + af v, q + (1 - af) dq, with a1, v1 Newmark's end-of-step rates of dq. Both contact-free
    increments (the dense one in :func:`run`, :func:`_free_increment_modal`) start from it."""
    beta, gamma, am, af = scheme
    c_acc = 1.0 / (beta * dt * dt)
    n = q.size
    for j in range(n):
        dq[j] = dt * v[j] + 0.5 * dt * dt * a[j]
    for p in range(P.size):
        dq[P[p]] = pq[p] - q[P[p]]
    for j in range(n):
        a1 = (dq[j] - dt * v[j]) * c_acc - (1.0 / (2.0 * beta) - 1.0) * a[j]
        v1 = v[j] + dt * ((1.0 - gamma) * a[j] + gamma * a1)
        y[0, j] = (1.0 - am) * a1 + am * a[j]
        y[1, j] = (1.0 - af) * v1 + af * v[j]
        y[2, j] = q[j] + (1.0 - af) * dq[j]


@njit(cache=True, _nrt=False)
def _free_increment_modal(q, v, a, pq, dt, structure, scheme, A_inv, diagonal, coupling, dq, y, b, w, scalars):
    """The contact-free increment ``dq`` (predictor, inputs at t1, correction w = -K_eff^-1 r0 on the free
    coordinates) of a structure with diagonal M_FF and K_FF, with one dense product: r0 = M y1 + C y2 + K y3 - load
    at the predictor's generalized mid-point, and C_FF y2_F = (K_eff y2_F - c_M M_FF y2_F - c_K K_FF y2_F) / c_C
    (K_eff = c_M M + c_C C + c_K K on the free block), so w = -y2_F / c_C - K_eff^-1 b with b the diagonal and input
    terms. ``diagonal``, ``coupling``: :func:`_modal_terms`; ``y`` (3, n: y1, y2, y3), ``b``, ``w`` (nf) and
    ``scalars`` (2) are work arrays."""
    beta, gamma, am, af = scheme
    c_acc = 1.0 / (beta * dt * dt)
    c_vel = gamma / (beta * dt)
    c_m, c_c, c_k = (1.0 - am) * c_acc, (1.0 - af) * c_vel, 1.0 - af
    free, P = structure.free, structure.inputs
    _predictor(q, v, a, pq, dt, P, scheme, dq, y)
    m_over_c, k_over_c = c_m / c_c, c_k / c_c
    for i in range(free.size):
        f = free[i]
        b[i] = diagonal[0, i] * (y[0, f] - m_over_c * y[1, f]) + diagonal[1, i] * (y[2, f] - k_over_c * y[1, f]) \
            - diagonal[2, i]
    for p in range(P.size):
        j = P[p]
        y1, y2, y3 = y[0, j], y[1, j], y[2, j]
        for i in range(free.size):
            b[i] += coupling[0, p, i] * y1 + coupling[1, p, i] * y2 + coupling[2, p, i] * y3
    _matvec(A_inv, b, w, scalars)
    for i in range(free.size):
        dq[free[i]] -= y[1, free[i]] / c_c + w[i]


@njit(cache=True)
def _snap(level, dt):
    if dt >= level:
        return level
    k = np.ceil(np.log2(level / dt) - 1e-12)
    return level / 2.0 ** k


@njit(cache=True, _nrt=False)
def _status(y, v, z, zd, wk, model, closed_sites, closed):
    """Contact status at an end-of-step state (site displacements ``y`` (ns, 3), velocities ``v``): closed per
    contact and link (into ``closed``) and per site, and the earliest predicted closure [s] (inf if none)."""
    sites, contacts, bodies, links = model.sites, model.contacts, model.bodies, model.links
    closure = np.inf
    n_c = contacts.kind.size
    for c in range(closed.size):
        closed[c] = False
    sw = wk.work
    for i in range(sites.contact.size):
        _, gap, _, _, _ = site_force(i, y[i], v[i], z, zd, sites, contacts, bodies, 1.0, 1.0, False, sw)
        rate = _dot3(sw.n, sw.vrel)
        closed_sites[i] = gap < 0.0
        if gap < 0.0:
            closed[sites.contact[i]] = True
        elif rate < 0.0:
            closure = min(closure, gap / -rate)
    for l in range(links.lower.size):
        _, delta, rate, _, _, _, _, _, _, _ = link_force(l, z, zd, bodies, links, wk.lf, wk.lP, False,
                                                        wk.link_work)
        closed[n_c + l] = delta > 0.0
        if delta <= 0.0 and rate > 0.0:
            closure = min(closure, -delta / rate)
    return closure


@njit(cache=True, nogil=True)     # the GIL released: the field output's writer thread works meanwhile
def run(t_end, state, model, cache, out, track_energy, frames):
    """Advance ``state`` (in place) until ``t_end``, until the output buffers (``out`` or ``frames``) are full, until
    the first accepted step at or after ``state.fstate[F_STOP]``, or until the last of ``frames.times`` is taken.
    Returns (code, rows written): one output row per accepted step (``out``), the per-site diagnostics integrated
    into ``out.site_sums``, the field frames due at the steps in ``frames`` (:class:`Frames`)."""
    q, v, a, z, zd, zdd, istate, fstate, sums, f_last = state
    structure, inputs, scheme, control, bodies, sites, contacts, links, sample_rows = model
    gdim = bodies.gdim
    free = structure.free
    nf = free.size
    P = structure.inputs
    m = z.size
    ns = sites.contact.size
    nr = ns * gdim
    n_c = contacts.kind.size
    n_l = links.lower.size
    rows_R = sites.rows
    kmax = 0
    for b in range(bodies.start.size):
        s0, n_rot = _body_rotations(bodies, b)
        kmax = max(kmax, gdim + n_rot)
    wk = step_work(ns, gdim, m, kmax, n_l)
    free_count = 0
    for j in range(m):
        if bodies.free[j]:
            free_count += 1
    free_body = np.empty(free_count, np.int64)
    free_count = 0
    for j in range(m):
        if bodies.free[j]:
            free_body[free_count] = j
            free_count += 1
    pq = np.zeros(P.size)
    # the site rows by their nonzeros: on every coordinate (site values) and on the free ones (the compliance)
    site_rows = sparse_rows(rows_R, np.arange(q.size))
    free_rows = sparse_rows(rows_R, free)
    nw = newton_work(ns, gdim, m, nf, free_rows)
    u = np.zeros(nf)
    u_work = np.zeros(nf)
    g_work = np.zeros(nf)
    # the structure's step: increments, end-of-step rates and coordinates, the generalized mid-point arguments of
    # M, C and K and their products, the free residual and its contact-free correction (filled index by index, in
    # the order of the array expressions they replace, so the same numbers; no array allocated per step)
    n = q.size
    dq = np.zeros(n)
    a1 = np.zeros(n)
    v1 = np.zeros(n)
    q1 = np.zeros(n)
    r_M = np.zeros(n)
    r_C = np.zeros(n)
    r_K = np.zeros(n)
    r0F = np.zeros(nf)
    w = np.zeros(nf)
    # M_FF and K_FF diagonal (the model in its free modes, app/reduced/coordinates.py): one product per step
    modal = _diagonal_free(structure)
    diagonal, coupling = _modal_terms(structure)
    y_mid = np.zeros((3, n))          # the mid-point arguments of M, C and K (_predictor)
    y_end = np.zeros((ns, 3))
    v_end = np.zeros((ns, 3))
    closed_sites = np.zeros(ns, np.bool_)
    closed_new_sites = np.zeros(ns, np.bool_)
    closed = np.zeros(n_c + n_l, np.bool_)
    closed_new = np.zeros(n_c + n_l, np.bool_)
    record_power = np.zeros(n_c + n_l)
    record_seen = np.zeros(n_c, np.bool_)
    # the status of the current state
    for i in range(ns):
        for k in range(gdim):
            y_end[i, k] = _row_dot(site_rows, i * gdim + k, q)
            v_end[i, k] = _row_dot(site_rows, i * gdim + k, v)
    closure = _status(y_end, v_end, z, zd, wk, model, closed_sites, closed)
    beta, gamma, am, af = scheme
    rows = 0
    capacity = out.time.size
    t = fstate[F_TIME]
    stop_at = fstate[F_STOP]
    while t < t_end * (1.0 - 1e-12):
        if rows >= capacity or (frames.slots[1] >= frames.t.size and frames.slots[0] < frames.times.size):
            fstate[F_TIME] = t
            return BUFFER_FULL, rows
        any_closed = False
        for c in range(n_c + n_l):
            any_closed = any_closed or closed[c]
        if istate[I_CHANGED]:
            dt = control.change_s
        elif any_closed:
            dt = control.closed_s
        else:
            dt = control.open_s
            if closure < dt:
                dt = max(control.change_s, _snap(control.open_s, max(0.5 * closure, 1e-300)))
        if dt > fstate[F_CAP]:
            dt = _snap(dt, fstate[F_CAP])
        while True:
            remainder = t_end - t
            dt_try = dt if remainder >= dt * (1.0 - 1e-9) else remainder
            istate[I_ATTEMPTS] += 1
            t1 = t + dt_try
            slot = _cached_slot(cache.dt, dt_try)       # the one-array lookup; _effective forms a new slot
            if slot < 0:
                slot = _effective(structure, rows_R, dt_try, scheme, cache)
            A_inv = cache.inv[slot]
            cp = Compliance(cache.H[slot], cache.GT[slot], free_rows, u, u_work, cache.invT[slot], g_work)
            c_acc = 1.0 / (beta * dt_try * dt_try)
            input_values(t1, inputs, pq)
            # contact-free increments: predictor, the prescribed inputs at t1, w = -K_eff^-1 r0,
            # r0 = M ((1 - am) a1 + am a) + C ((1 - af) v1 + af v) + K (q + (1 - af) dq) - load
            if modal:
                _free_increment_modal(q, v, a, pq, dt_try, structure, scheme, A_inv, diagonal, coupling, dq, y_mid,
                                      r0F, w, nw.scalars)
            else:
                _predictor(q, v, a, pq, dt_try, P, scheme, dq, y_mid)
                np.dot(structure.M, y_mid[0], r_M)
                np.dot(structure.C, y_mid[1], r_C)
                np.dot(structure.K, y_mid[2], r_K)
                for i in range(nf):
                    j = free[i]
                    r0F[i] = r_M[j] + r_C[j] + r_K[j] - structure.load[j]
                np.dot(A_inv, r0F, w)
                for i in range(nf):
                    dq[free[i]] += -w[i]
            # the sites' start values and contact-free increments
            for i in range(ns):
                for k in range(gdim):
                    r = i * gdim + k
                    wk.y0[i, k] = _row_dot(site_rows, r, q)
                    wk.v0[i, k] = _row_dot(site_rows, r, v)
                    wk.a0[i, k] = _row_dot(site_rows, r, a)
                    wk.dw[r] = _row_dot(site_rows, r, dq)
            # Newton starts from the last step's site forces: dd = dw + H f_last (the separated sites included)
            n_loaded = 0
            for i in range(ns):
                if f_last[i, 0] != 0.0 or f_last[i, 1] != 0.0 or f_last[i, 2] != 0.0:
                    wk.active[n_loaded] = i
                    n_loaded += 1
            _respond(cp, wk.active, n_loaded, gdim, f_last, u_work)
            for r in range(nr):
                wk.dd[r] = wk.dw[r] + (_row_dot(free_rows, r, u_work) if n_loaded else 0.0)
            for j in range(m):
                wk.xi[j] = 0.0
            converged, its = _newton(wk, nw, cp, state, dt_try, model, free_body)
            istate[I_NEWTON] += max(its, 1)
            if not converged:
                istate[I_CUTBACKS] += 1
                dt = 0.5 * dt_try
                if dt < control.min_s:
                    fstate[F_TIME] = t
                    return STEP_FAILED, rows
                fstate[F_CAP] = dt
                continue
            # the structure's increments for the converged site forces: dq_F += G f (cp.u: the Newton iteration
            # evaluated the forces last at its solution)
            for i in range(nf):
                dq[free[i]] += u[i]
            for i in range(n):
                a1[i] = (dq[i] - dt_try * v[i]) * c_acc - (1.0 / (2.0 * beta) - 1.0) * a[i]
                v1[i] = v[i] + dt_try * ((1.0 - gamma) * a[i] + gamma * a1[i])
                q1[i] = q[i] + dq[i]
            for i in range(ns):
                for k in range(gdim):
                    y_end[i, k] = wk.y0[i, k] + wk.dd[i * gdim + k]
                    v_end[i, k] = _row_dot(site_rows, i * gdim + k, v1)
            new_closure = _status(y_end, v_end, wk.z1, wk.zd1, wk, model, closed_new_sites, closed_new)
            changed = False
            for c in range(n_c + n_l):
                changed = changed or (closed_new[c] != closed[c])
            if changed and dt_try > control.change_s * (1.0 + 1e-9):
                istate[I_REFINEMENTS] += 1
                dt = max(0.25 * dt_try, control.change_s)
                continue
            break
        # accepted: the step's forces (at its mid-point) were evaluated last by the Newton iteration
        _record(rows, t1, dt_try, q1, pq, wk, state, model, out, closed_new, y_end, record_power, record_seen,
                nw.scalars)
        if track_energy:
            _record_energy(rows, dt_try, q1, v1, v, structure, bodies, model.sites, model.contacts, wk, sums, out)
        rows += 1
        q[:] = q1
        v[:] = v1
        a[:] = a1
        for i in range(ns):
            for k in range(3):
                f_last[i, k] = wk.f[i, k] if wk.fn[i] > 0.0 else 0.0
        z[:] = wk.z1
        zd[:] = wk.zd1
        zdd[:] = wk.zdd1
        for c in range(n_c + n_l):
            closed[c] = closed_new[c]
        closure = new_closure
        istate[I_CHANGED] = 1 if changed else 0
        istate[I_STEPS] += 1
        t = t1
        if fstate[F_CAP] < np.inf:
            fstate[F_CAP] = dt_try * control.growth
            if fstate[F_CAP] >= max(control.open_s, control.closed_s):
                fstate[F_CAP] = np.inf
        k = frames.slots[0]
        if k < frames.times.size and t >= frames.times[k] - frames.due_s:
            # a field frame: the state after the step, as the loop would take it after a stop here
            r = frames.slots[1]
            frames.t[r] = t
            frames.q[r, :] = q
            frames.z[r, :] = z
            frames.slots[1] = r + 1
            after = t + frames.after_s
            while k < frames.times.size and frames.times[k] <= after:
                k += 1
            frames.slots[0] = k
            if k >= frames.times.size:
                fstate[F_TIME] = t
                return STOPPED, rows
        if t >= stop_at:
            fstate[F_TIME] = t
            return STOPPED, rows
    fstate[F_TIME] = t
    return DONE, rows


@njit(cache=True, _nrt=False)
def _record(row, t1, dt, q1, pq, wk, state, model, out, closed, y_end, power, seen, scalars):
    """One output row, the dissipated energies and the per-site diagnostics of an accepted step (``power``
    (n_contacts + n_links,), ``seen`` (n_contacts,) bool and ``scalars`` (2): work); the energy columns are
    :func:`_record_energy`'s."""
    sites, contacts, links, sample_rows = model.sites, model.contacts, model.links, model.sample_rows
    sums, z1, zd1 = state.sums, wk.z1, wk.zd1
    n_c = contacts.kind.size
    n_l = links.lower.size
    out.time[row] = t1
    out.dt[row] = dt
    _matvec(sample_rows, q1, out.samples[row], scalars)
    for p in range(pq.size):
        out.inputs[row, p] = pq[p]
    for j in range(z1.size):
        out.z[row, j] = z1[j]
        out.zd[row, j] = zd1[j]
    for c in range(n_c + n_l):
        for k in range(3):
            out.force[row, c, k] = 0.0
        out.closed[row, c] = closed[c]
    for c in range(n_c):
        for k in range(3):
            out.torque[row, c, k] = 0.0
        out.normal[row, c] = 0.0
        out.area[row, c] = 0.0
        out.peak[row, c] = 0.0
    for c in range(n_c + n_l):
        power[c] = 0.0
    tq = wk.fxa
    fneg = wk.link_work[0]
    # diagnostics: the forces act at the generalized mid-point t1 - alpha_f dt, the displacements y_end at t1
    diagnose = out.site_sums.shape[0] == sites.contact.size
    acc = SiteAccumulators(out.site_sums, out.site_bins, out.site_group, out.site_phase)
    omega = model.inputs.omega
    phase_f = omega * (t1 - model.scheme.alpha_f * dt)
    clock = DriveClock(dt, math.cos(phase_f), math.sin(phase_f), phase_f, math.cos(omega * t1), math.sin(omega * t1))
    for i in range(sites.contact.size):
        c = sites.contact[i]
        if wk.gap[i] < 0.0:
            out.area[row, c] += sites.weight[i]
        fn = wk.fn[i]
        if fn <= 0.0:
            if wk.gap[i] < 0.0:     # penetrated, its pressure k d + c dd/dt clipped to zero: the elastic energy the
                #                     penalty holds is lost as the gap opens, (0 - elastic) times the closing rate
                power[c] += _elastic_force(i, c, wk.gap[i], sites, contacts) * wk.rate[i]
            if diagnose:        # an open site: its displacement's harmonic and its time in the wave-frame bins
                accumulate_site(i, SiteSample(0.0, 0.0, 0.0, 0.0, 0.0, -_dot3(sites.frame[i, 0], y_end[i]),
                                              sites.weight[i], 0.0), clock, acc)
            continue
        for k in range(3):
            fneg[k] = -wk.f[i, k]
            out.force[row, c, k] += fneg[k]
        _cross(wk.lever[i], fneg, tq)
        for k in range(3):
            out.torque[row, c, k] += tq[k]
        out.normal[row, c] += fn
        if contacts.kind[c] != NODE:
            out.peak[row, c] = max(out.peak[row, c], fn / sites.weight[i])
        # dissipated power: damping (the force beyond its elastic part times the closing rate) and friction
        elastic = _elastic_force(i, c, wk.gap[i], sites, contacts)
        tangential = 0.0            # -f_t . s = T |s|^2 / reg
        T = 0.0
        if contacts.mu[c] > 0.0:
            mu_, _ = _friction_coefficient(wk.slip[i, 2], contacts.mu[c], contacts.fact[c], contacts.decay[c])
            T = min(mu_ * fn, contacts.cap[c] * sites.weight[i])
            speed = wk.slip[i, 2]
            eps = contacts.eps[c]
            tangential = T * speed * speed / math.sqrt(speed * speed + eps * eps)
        # diagnostics: time integrals of the pressure and of the site's state over accepted steps
        if diagnose:
            accumulate_site(i, SiteSample(fn, wk.slip[i, 0], wk.slip[i, 1], wk.slip[i, 2], T / sites.weight[i],
                                          -_dot3(sites.frame[i, 0], y_end[i]), sites.weight[i],
                                          stick_speed(contacts, c)), clock, acc)
        power[c] += (fn - elastic) * -wk.rate[i] + tangential
    for l in range(n_l):
        f = wk.link_fn[l]
        if f > 0.0:
            n = links.direction[l]
            for k in range(3):
                out.force[row, n_c + l, k] = f * n[k]
    for c in range(n_c + n_l):
        previous = power[c] if math.isnan(sums.power[c]) else sums.power[c]     # a first step: its own power
        sums.dissipated[c] += 0.5 * dt * (previous + power[c])
        sums.power[c] = power[c]
        out.dissipated[row, c] = sums.dissipated[c]
    # each contact's first site: its displacement in its frame (the contact point's path)
    for c in range(n_c):
        for k in range(3):
            out.probe[row, c, k] = 0.0
    for c in range(n_c):
        seen[c] = False
    for i in range(sites.contact.size):
        c = sites.contact[i]
        if seen[c]:
            continue
        seen[c] = True
        for r in range(3):
            out.probe[row, c, r] = _dot3(sites.frame[i, r], y_end[i])


@njit(cache=True)
def _record_energy(row, dt, q1, v1, v0, structure, bodies, sites, contacts, wk, sums, out):
    """The energy columns of an output row and the structural damping loss (output.energies: allocates)."""
    z1, zd1 = wk.z1, wk.zd1
    vm = 0.5 * (v0 + v1)
    p_damp = vm @ (structure.C @ vm)
    sums.damping[0] += dt * p_damp
    sums.damping[1] = p_damp
    out.energy[row, 0] = 0.5 * (v1 @ (structure.M @ v1))
    out.energy[row, 1] = 0.5 * (q1 @ (structure.K @ q1))
    kin = 0.0
    for j in range(z1.size):
        kin += 0.5 * bodies.mass[j] * zd1[j] * zd1[j]
    out.energy[row, 2] = kin
    pen = 0.0
    for i in range(sites.contact.size):
        c = sites.contact[i]
        if wk.gap[i] < 0.0:
            if contacts.kind[c] == NODE:
                e = contacts.exponent[c]
                pen += contacts.stiffness[c] * (-wk.gap[i]) ** (e + 1.0) / (e + 1.0)
            else:
                pen += sites.weight[i] * _penalty_energy(wk.gap[i], contacts.stiffness[c], contacts.rounding[c])
    out.energy[row, 3] = pen
    out.energy[row, 4] = sums.damping[0]


@njit(cache=True, _nrt=False)
def _elastic_force(i, c, gap, sites, contacts):
    """The elastic part of site i's normal force [N] at ``gap`` < 0 (contact c's law without its damping). Its
    damping's dissipation is (force - this) times the closing rate -dg/dt, the rate the law saw: a closing rate
    recovered from the force, (force - this) / c, misses the clipped part (the force zero while still penetrated,
    as a Kelvin-Voigt contact lets go); the FE tier's form (app/transient/contact.py) counts it."""
    if contacts.kind[c] == NODE:
        return contacts.stiffness[c] * (-gap) ** contacts.exponent[c]
    return sites.weight[i] * _penalty_pressure(gap, 0.0, contacts.stiffness[c], 0.0, contacts.rounding[c])[0]
