"""The motor in the modal tier: a Craig-Bampton stator pressing a rigid cone rotor (docs/motor-rotor.md).

Case -> FE stator (mesh, forms, electrodes) -> Craig-Bampton basis whose interface is ``reduction.ring_points``
nodes of the contact band, evenly round the contact circle (all three displacement DOFs each; driven
electrodes as input coordinates) -> the compiled loop of :mod:`app.reduced.ring_kernel`, called one drive
period at a time until the rotor turns steadily ([transient.steady_state]) or end_time_s -> the time series
(``transient.h5``), the operating point (speed, torque, powers, efficiency, contact states, pressure round the
ring, the contact point's path) in summary.json and ``motor_ring.csv``.

The reduced model depends only on the stator, its electrodes, its damping, the basis settings and the band; it
is kept in a cache (``PIEZODYN_CACHE_DIR``, default ``~/.cache/piezodyn``) keyed by those sections, so a sweep
over load torque, preload, voltage or rotor data builds it once. Checkpoints at period ends and ``--resume``:
app/reduced/motor_restart.py.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from app import series as S
from app.errors import CaseError, NumericalFailure
from app.files import atomic_write, replace_file
from app.killpoint import kill_point
from app.motor.rotor_case import check_motor_case, is_motor_case  # noqa: F401 (the runner's entry points)
from app.reduced import motor_restart as restart
from app.reduced import ring_kernel as rk
from app.reduced.craig_bampton import ReducedBasis, harmonic_response
from app.series import TimeSeriesWriter

CACHE_VERSION = 2      # 2: enrichment frequencies stored
MAX_CUTBACK_LEVEL = 4
#: interface displacement tolerance of the Newton iteration [m] (1e-8 of a micrometre wave)
NEWTON_TOL_M = 1e-14


@dataclass
class RingModel:
    """The reduced stator and its contact band: everything the kernel needs, as arrays (cacheable)."""

    K: np.ndarray
    M: np.ndarray
    C: np.ndarray
    electrodes: list
    charge_rows: np.ndarray          # (n_electrodes, n) Q_e = row @ q [C]
    mode_frequencies_Hz: np.ndarray
    node_xyz: np.ndarray             # (n_points, 3) reference positions of the band nodes [m]
    band_area_m2: float
    reduction_wall_s: float
    enrichment_frequencies_Hz: np.ndarray   # the full model's modes in the basis (reduction.enrich_modes) [Hz]

    @property
    def n_points(self) -> int:
        return self.node_xyz.shape[0]

    def resonances_Hz(self, near_Hz: float, count: int = 2) -> np.ndarray:
        """The reduced stator's ``count`` natural frequencies nearest ``near_Hz`` with the electrodes held (short
        circuit, as the driven transient sees them) [Hz], ascending."""
        import scipy.linalg

        n_b, n_e = 3 * self.n_points, len(self.electrodes)
        keep = np.r_[0:n_b, n_b + n_e:self.K.shape[0]]
        eigenvalues = scipy.linalg.eigh(self.K[np.ix_(keep, keep)], self.M[np.ix_(keep, keep)], eigvals_only=True)
        frequencies = np.sqrt(np.abs(eigenvalues)) / (2 * math.pi)
        return np.sort(frequencies[np.argsort(np.abs(frequencies - near_Hz))[:count]])

    def basis(self) -> ReducedBasis:
        rows = {name: self.charge_rows[i] for i, name in enumerate(self.electrodes)}
        return ReducedBasis(self.K, self.M, self.C, np.arange(3 * self.n_points), list(self.electrodes),
                            self.mode_frequencies_Hz, rows, [], None)


def _cache_key(case) -> str:
    cfg = case.transient
    c = cfg.contacts[0]
    # the contact points are evaluated on the reduced model: they do not change it
    reduction = {key: value for key, value in asdict(case.reduction).items() if key != "contact_points"}
    relevant = {"version": CACHE_VERSION, "geometry": asdict(case.geometry), "materials": repr(case.materials),
                "regions": repr(case.regions), "electrodes": repr(case.electrodes), "supports": repr(case.supports),
                "damping": asdict(case.damping), "reduction": reduction,
                "drive_Hz": cfg.drive.frequency_Hz, "facets": c.facets, "radius_m": c.radius_m,
                "z_m": cfg.bodies[0].position_m[2], "half_angle_deg": c.half_angle_deg}
    text = json.dumps(relevant, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _cache_dir() -> Path:
    return Path(os.environ.get("PIEZODYN_CACHE_DIR", Path.home() / ".cache" / "piezodyn"))


def load_or_build(case, comm, log) -> RingModel:
    path = _cache_dir() / f"motor-{_cache_key(case)}.npz"
    found = path.is_file() if comm is None else comm.bcast(path.is_file(), root=0)   # one verdict for all ranks
    if found:
        model = restart.read_ring(path, RingModel)
        log(f"modal tier (motor): reduced stator from the cache {path}")
        return model
    model = build_ring_model(case, comm, log)
    if comm.rank == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}.npz")     # per process: sweep points may build it at once
        with open(tmp, "wb") as fh:
            restart.write_ring(fh, model)
        os.replace(tmp, path)
    return model


def _band_nodes(model, tag: int):
    """(coordinates (n, 3), global DOFs (n, 3)) of every displacement node on facet group ``tag``, the same
    arrays on every rank (sorted by coordinates)."""
    from dolfinx import fem

    mesh = model.mesh
    fdim = mesh.topology.dim - 1
    facets = model.mesh_data.facet_tags.find(tag)
    W = model.W
    imap = W.dofmap.index_map
    n_owned = imap.size_local
    held = set(np.asarray(model.support_dofs).tolist())
    per_component = []
    for k in range(3):
        V, _ = W.sub(0).sub(k).collapse()
        parent, child = fem.locate_dofs_topological((W.sub(0).sub(k), V), fdim, facets)
        coords = V.tabulate_dof_coordinates()[np.asarray(child)]
        parent = np.asarray(parent)
        owned = parent < n_owned
        glob = imap.local_to_global(parent[owned].astype(np.int32))
        glob = np.where([p in held for p in parent[owned]], -1, glob)
        gathered = model.comm.allgather((coords[owned], glob))
        xyz = np.concatenate([g[0] for g in gathered])
        dofs = np.concatenate([g[1] for g in gathered])
        order = np.lexsort((xyz[:, 2], xyz[:, 1], xyz[:, 0]))
        per_component.append((xyz[order], dofs[order]))
    xyz = per_component[0][0]
    for k in (1, 2):
        if per_component[k][0].shape != xyz.shape or not np.allclose(per_component[k][0], xyz, atol=1e-12):
            raise NumericalFailure("contact band: the displacement components do not share their nodes")
    return xyz, np.column_stack([per_component[k][1] for k in range(3)])


def build_ring_model(case, comm, log) -> RingModel:
    import ufl
    from dolfinx import fem

    from app.fe.model import build_model, facet_group_tag
    from app.fe.operators import assemble_operators
    from app.reduced.craig_bampton import reduce_model

    cfg = case.transient
    contact = cfg.contacts[0]
    file = case.source
    model = build_model(case, comm)
    if model.mesh.geometry.dim != 3:
        raise CaseError(file, "geometry.model", "the modal tier's motor is a 3D model")
    if model.electrodes_of("floating"):
        raise CaseError(file, "electrodes", "floating electrodes are not supported by the transient analysis")
    tag = facet_group_tag(model.mesh_data.facet_names, contact.facets, file, "transient.contacts[0].facets")
    xyz, dofs = _band_nodes(model, tag)
    if xyz.shape[0] == 0:
        raise CaseError(file, "transient.contacts[0].facets", "the facet group has no nodes")
    if (dofs < 0).any():
        raise CaseError(file, "transient.contacts[0].facets", "the contact band touches a support")
    n_points = case.reduction.ring_points
    if n_points > xyz.shape[0]:
        raise CaseError(file, "reduction.ring_points", f"the band has only {xyz.shape[0]} nodes")
    # the band node nearest each of n_points targets evenly round the contact circle
    r_c = contact.radius_m
    z_c = cfg.bodies[0].position_m[2]
    angles = 2 * math.pi * np.arange(n_points) / n_points
    targets = np.column_stack([r_c * np.cos(angles), r_c * np.sin(angles), np.full(n_points, z_c)])
    chosen = [int(np.argmin(np.linalg.norm(xyz - t, axis=1))) for t in targets]
    if len(set(chosen)) != n_points:
        raise CaseError(file, "reduction.ring_points", "more points than band nodes round the circle: use fewer")
    interface = dofs[chosen].reshape(-1).astype(np.int64)
    ds = ufl.Measure("ds", domain=model.mesh, subdomain_data=model.mesh_data.facet_tags)
    band_area = comm.allreduce(fem.assemble_scalar(fem.form(1.0 * ds(tag))), op=MPI.SUM)

    damping_Hz = case.damping.reference_frequency_Hz or cfg.drive.frequency_Hz
    ops = assemble_operators(model, damping_frequency_Hz=damping_Hz)
    fixed = np.concatenate([model.support_dofs, model.grounded_dofs]
                           + [model.electrode_dofs[n] for n in model.electrodes_of("ground")])
    electrodes = {n: model.electrode_dofs[n] for n in model.electrodes_of("voltage")}
    red = case.reduction
    cutoff = red.cutoff_Hz if red.cutoff_Hz is not None else (
        None if red.n_modes is not None else red.cutoff_factor * cfg.drive.frequency_Hz)
    start = time.perf_counter()
    basis = reduce_model(ops.K, ops.M, ops.C, model.W, fixed, interface, electrodes, n_modes=red.n_modes,
                         cutoff_Hz=cutoff, n_enrich=red.enrich_modes, enrich_near_Hz=cfg.drive.frequency_Hz)
    wall = time.perf_counter() - start
    ops.destroy()
    enriched = basis.enrichment_frequencies_Hz
    log(f"modal tier (motor): {n_points} band nodes ({basis.n_interface} interface DOFs), {len(electrodes)} "
        f"electrodes, {basis.n_modes} fixed-interface modes up to {basis.mode_frequencies_Hz.max():.0f} Hz"
        + (f", the full model's modes at {', '.join(f'{f:.1f}' for f in enriched)} Hz" if enriched.size else "")
        + f", {basis.size} coordinates ({wall:.1f} s)")
    rows = np.array([basis.charge_rows[n] for n in basis.electrodes])
    out = RingModel(basis.K, basis.M, basis.C if basis.C is not None else np.zeros_like(basis.K),
                    list(basis.electrodes), rows, basis.mode_frequencies_Hz, xyz[chosen], band_area, wall,
                    enriched)
    basis.destroy()
    return out


@dataclass
class Geometry:
    """The contact points: where the gap and the friction are evaluated, and how they see the interface nodes."""

    frame: np.ndarray     # (n_c, 3, 3): n, e_theta, t_m per contact point
    g0: np.ndarray        # geometric gap at the rotor's reference height [m]
    rho: np.ndarray       # distance from the axis [m]
    area: np.ndarray      # band area per contact point [m^2]
    angle_deg: np.ndarray  # azimuth of each contact point [deg]
    idx: np.ndarray       # (n_c, n_s) interface nodes of each point's interpolation stencil
    B: np.ndarray         # (n_c, n_s, 3, 3) u_c = sum_s B[c, s] u_node[idx[c, s]] (global components)
    sin_a: float
    cos_a: float

    @property
    def n_points(self) -> int:
        return self.rho.size

    def displacement(self, uB: np.ndarray) -> np.ndarray:
        """(n_c, 3) displacements of the contact points from the interface nodes' (n_b, 3)."""
        return np.einsum("csij,csj->ci", self.B, uB[self.idx])


def _cone_frames(angles, sin_a, cos_a):
    """(n, 3, 3) rows n (the cone's outward normal), e_theta, t_m (meridional tangent) at the given azimuths."""
    c, s = np.cos(angles), np.sin(angles)
    e_r = np.column_stack([c, s, np.zeros_like(c)])
    e_t = np.column_stack([-s, c, np.zeros_like(c)])
    e_z = np.tile([0.0, 0.0, 1.0], (c.size, 1))
    return np.stack([cos_a * e_r - sin_a * e_z, e_t, sin_a * e_r + cos_a * e_z], axis=1)


def interpolation_stencil(node_angles: np.ndarray, point_angles: np.ndarray, order: int = 3):
    """Lagrange interpolation round the ring, in angle: for each point, the ``order + 1`` nodes nearest it
    (half before, half after, periodic) and their weights, from the nodes' own (unevenly spaced) angles [rad]."""
    n_b = node_angles.size
    order_of = np.argsort(node_angles)
    theta = node_angles[order_of]
    width = order + 1
    idx = np.empty((point_angles.size, width), np.int64)
    weights = np.empty((point_angles.size, width))
    for c, phi in enumerate(point_angles % (2 * math.pi)):
        right = int(np.searchsorted(theta, phi, side="right"))   # first node after phi (may be n_b: wraps)
        ks = np.arange(right - (width + 1) // 2, right - (width + 1) // 2 + width)
        turns = np.floor_divide(ks, n_b)
        x = theta[ks % n_b] + 2 * math.pi * turns
        for s in range(width):
            others = np.delete(x, s)
            weights[c, s] = np.prod((phi - others) / (x[s] - others))
        idx[c] = order_of[ks % n_b]
    return idx, weights


def ring_geometry(ring: RingModel, case) -> Geometry:
    """Contact points of the band: ``reduction.contact_points`` points evenly round the contact circle, each
    carrying band area / contact_points, whose displacement is interpolated (cubic, in angle, in the local
    n / theta / meridional components) from the interface nodes; with contact_points = 0, the interface nodes
    themselves, each carrying band area / ring_points (the node-sampled contact)."""
    contact = case.transient.contacts[0]
    alpha = math.radians(contact.half_angle_deg)
    sin_a, cos_a = math.sin(alpha), math.cos(alpha)
    x, y, _ = ring.node_xyz.T
    node_angles = np.arctan2(y, x) % (2 * math.pi)
    node_frames = _cone_frames(node_angles, sin_a, cos_a)
    n_c = case.reduction.contact_points
    if n_c == 0:
        n_c = ring.n_points
        angles = node_angles
        rho = np.hypot(x, y)
        frame = node_frames
        idx = np.arange(n_c).reshape(-1, 1)
        B = np.tile(np.eye(3), (n_c, 1, 1, 1))
    else:
        angles = 2 * math.pi * (np.arange(n_c) + 0.5) / n_c
        rho = np.full(n_c, contact.radius_m)
        frame = _cone_frames(angles, sin_a, cos_a)
        idx, weights = interpolation_stencil(node_angles, angles)
        # local components at the node (F_j u), interpolated, back to global at the point (F_c^T): w F_c^T F_j
        B = weights[:, :, None, None] * np.einsum("cki,cskj->csij", frame, node_frames[idx])
    # The band's nodes are taken on the design cone: the straight-edged mesh puts mid-edge nodes up to h^2/(8 r)
    # inside it (2.4 um at 0.5 mm elements, more than the wave's amplitude), a faceting error, not a gap. As
    # ANSYS's KEYOPT(9) = 1 (exclude initial geometric penetration or gap), the initial gap is zero.
    g0 = np.zeros(n_c)
    area = np.full(n_c, ring.band_area_m2 / n_c)
    return Geometry(np.ascontiguousarray(frame), g0, rho, area, np.degrees(angles) % 360.0,
                    np.ascontiguousarray(idx), np.ascontiguousarray(B), sin_a, cos_a)


class SteadyWatch:
    """Cycle means of the watched quantity (the kernel gives them per period); the FE tier's steady-state test
    (:func:`app.loop.steady.window_is_steady`), with ``floor`` as the smallest scale."""

    def __init__(self, section, floor: float):
        self.section, self.floor = section, floor
        self.means: list[float] = []

    def add(self, mean: float) -> bool:
        from app.loop.steady import window_is_steady

        self.means.append(mean)
        s = self.section
        return window_is_steady(self.means, s.window_cycles, s.relative_tolerance, s.min_cycles, self.floor)


def run(case, out_dir, comm, log, resume: bool = False, warm_start: str | Path | None = None) -> dict:
    """Run the motor case in the modal tier into ``out_dir``; returns the summary's transient results.

    The state at the end (stator coordinates, rotor, time) is written to ``motor_state.npz``; ``warm_start``
    names such a file of an earlier run on the same reduced model to continue from (time and drive phase go
    on; a prescribed or held spin takes this case's rate): a continuation, used by the sampling study
    (bench/bench_motor_sampling.py) to skip the start's transient.

    Checkpoints at period ends (app/reduced/motor_restart.py); with ``resume`` the run continues from the
    checkpoint in ``out_dir`` (same case except the end time, the checkpoint interval and the outputs) with the
    checkpoint's reduced stator, and repeats the interrupted run's periods bit for bit."""
    from app.blas import limit_blas_threads

    limit_blas_threads()
    file = case.source
    check_motor_case(case, file)
    cfg = case.transient
    if math.floor(cfg.end_time_s * cfg.drive.frequency_Hz + 1e-9) < 1:      # the loop runs whole periods
        raise CaseError(file, "transient.end_time_s", f"{cfg.end_time_s:g} s is shorter than one drive period "
                                                      f"({1 / cfg.drive.frequency_Hz:.6g} s)")
    out_dir = Path(out_dir)
    setup_start = time.perf_counter()
    digest = restart.run_digest(case, warm_start)
    found = restart.find(out_dir, comm, case, digest, RingModel) if resume else None
    if found is not None:
        meta, data, ring = found
        log(f"modal tier (motor): reduced stator from the checkpoint {out_dir / 'checkpoint'}")
    else:
        if resume:
            log(f"transient (modal tier, motor): {out_dir} holds a run killed before its first checkpoint: "
                "starting it again")
        restart.mark_started(out_dir, comm, digest)
        ring = load_or_build(case, comm, log)
        if comm.size > 1:
            # every rank runs the loop, and the checkpoints are collective: a reduction just built on several ranks
            # may differ between them in round-off, so all take rank 0's (the one checkpointed and written)
            ring = comm.bcast(ring, root=0)
        restart.save_ring(out_dir, comm, ring)
    geo = ring_geometry(ring, case)
    contact, body = cfg.contacts[0], cfg.bodies[0]
    rotation = body.rotations[0]
    friction = contact.friction
    mu_d, fact, decay, tau_cap, eps = ((friction.mu_dynamic, friction.static_ratio, friction.decay_s_per_m,
                                        friction.shear_cap_Pa, friction.regularisation_speed_m_per_s)
                                       if friction is not None else (0.0, 1.0, 0.0, 1e20, 1e-4))
    preload = -float((body.applied_force_N or [0.0, 0.0, 0.0])[2])
    spin_free = rotation.motion == "free"
    spin0 = rotation.rate_rad_per_s if rotation.motion != "fixed" else 0.0
    f_drive = cfg.drive.frequency_Hz
    period = 1.0 / f_drive
    per_period = max(4, int(round(period / cfg.steps.closed_s)))
    dt = period / per_period
    beta, gamma = cfg.scheme.beta, cfg.scheme.gamma
    omega = 2 * math.pi * f_drive
    names = list(ring.electrodes)
    amplitudes = np.array([case.electrodes[n].amplitude_V if case.electrodes[n].amplitude_V is not None
                           else cfg.drive.voltage_V for n in names], dtype=float)
    phases = np.radians([case.electrodes[n].phase_deg for n in names])
    n = ring.K.shape[0]
    n_el = len(names)
    prescribed = np.arange(3 * ring.n_points, 3 * ring.n_points + n_el, dtype=np.int64)
    free = np.setdiff1d(np.arange(n), prescribed).astype(np.int64)
    invs = np.empty((MAX_CUTBACK_LEVEL + 1, free.size, free.size))
    for level in range(MAX_CUTBACK_LEVEL + 1):
        h = dt / 2**level
        K_eff = ring.K + gamma / (beta * h) * ring.C + ring.M / (beta * h * h)
        invs[level] = np.linalg.inv(K_eff[np.ix_(free, free)])

    # initial state: the stator's free harmonic steady state (or rest), the rotor resting on the highest crest
    q, v, a = np.zeros(n), np.zeros(n), np.zeros(n)
    cosine = cfg.initial_state == "harmonic"
    basis = ring.basis()
    if cosine:
        x = harmonic_response(basis, f_drive, {nm: A * np.exp(1j * p) for nm, A, p in zip(names, amplitudes, phases)})
        q, v = x.real.copy(), -omega * x.imag
        a = -omega**2 * x.real
    else:
        q[prescribed] = amplitudes * np.sin(phases)
        v[prescribed] = amplitudes * omega * np.cos(phases)
        a[prescribed] = -amplitudes * omega**2 * np.sin(phases)
        MFF = ring.M[np.ix_(free, free)]
        q[free] = -np.linalg.solve(MFF, ring.M[np.ix_(free, prescribed)] @ q[prescribed])
        v[free] = -np.linalg.solve(MFF, ring.M[np.ix_(free, prescribed)] @ v[prescribed])
        rhs = -ring.K @ q - ring.C @ v - ring.M[:, prescribed] @ a[prescribed]
        a[free] = np.linalg.solve(MFF, rhs[free])
    uc = geo.displacement(q[:3 * ring.n_points].reshape(-1, 3))
    gaps = geo.g0 + np.einsum("ij,ij->i", geo.frame[:, 0, :], uc)
    dz0 = -float(gaps.min()) / geo.sin_a
    rot = np.array([dz0, 0.0, -preload / body.mass_kg, rotation.angle_rad, spin0, 0.0])
    t_start = 0.0
    if warm_start is not None and found is None:
        with np.load(warm_start) as saved:
            if saved["q"].shape != q.shape or bool(saved["cosine"]) != cosine:
                raise CaseError(file, "warm start", f"{warm_start} is the state of another reduced model or drive")
            q, v, a, rot = (saved[key].astype(float) for key in ("q", "v", "a", "rot"))
            t_start = float(saved["t"])
        if not spin_free:
            rot[4], rot[5] = spin0, 0.0
    energies = np.zeros(7)
    istate = np.zeros(rk.N_ISTATE, np.int64)
    if found is None:
        if cosine:
            kill_point("harmonic_start")
        resumed_rows, seq = None, 0
    else:
        q, v, a, rot, energies, istate = (np.array(data[k]) for k in ("q", "v", "a", "rot", "energies", "istate"))
        t_start = float(data["t_s"])
        resumed_rows, seq = int(meta["rows"]), int(meta["seq"])
        log(f"transient (modal tier, motor): resuming at t = {t_start * 1e3:.6g} ms, period {int(data['periods'])} "
            f"({resumed_rows} time-series rows kept)")
    n_b = ring.n_points
    kernel_args = (ring.K, ring.M, ring.C, free, prescribed, n_b, amplitudes, phases, omega, cosine, beta, gamma,
                   geo.frame, geo.g0, geo.rho, geo.area, geo.idx, geo.B, geo.sin_a, geo.cos_a, contact.stiffness,
                   mu_d, fact, decay, tau_cap, eps, body.mass_kg, preload, rotation.inertia_kg_m2, rotation.torque_N_m,
                   rotation.brake_N_m_s_per_rad, spin_free, NEWTON_TOL_M, ring.charge_rows)
    columns = np.zeros((per_period, rk.N_COLUMNS))
    point_state = np.zeros((per_period, geo.n_points), np.int64)
    point_fn = np.zeros((per_period, geo.n_points))
    trajectory = np.zeros((per_period, 3))

    def one_period(t):
        columns[:] = 0.0
        trajectory[:] = 0.0
        return rk.run_period(t, per_period, dt, invs, MAX_CUTBACK_LEVEL, q, v, a, rot, energies, istate,
                             *kernel_args, columns, point_state, point_fn, trajectory)

    # compile (or load) the kernel on a copy of the state: set-up, not time-loop cost
    saved = (q.copy(), v.copy(), a.copy(), rot.copy(), energies.copy(), istate.copy())
    one_period(0.0)
    q[:], v[:], a[:], rot[:], energies[:], istate[:] = saved
    setup_wall = time.perf_counter() - setup_start

    h5_path = out_dir / S.TIME_SERIES_FILE
    units = motor_units(body.name, contact.name, names)
    series = TimeSeriesWriter(h5_path, units, comm, resume_rows=resumed_rows)
    checkpoint = restart.writer(out_dir, comm, digest, float(amplitudes.max()), seq)
    every = restart.interval_periods(cfg.checkpoint_interval_steps, per_period)
    steady = None
    if cfg.steady_state is not None:
        torque_bound = mu_d * fact * preload / geo.sin_a * float(np.mean(geo.rho))
        wave_speed = omega * 1e-6 / float(np.mean(geo.rho))     # rotor speed of a 1 um tangential wave [rad/s]
        steady = SteadyWatch(cfg.steady_state, 0.02 * (wave_speed if spin_free else torque_bound))
    max_periods = int(math.floor(cfg.end_time_s / period + 1e-9))
    log(f"transient (modal tier, motor): {cfg.initial_state} start, {amplitudes.max():.4g} V at {f_drive:.2f} Hz, "
        f"preload {preload:.4g} N, {per_period} steps per period, up to {max_periods} periods"
        + (f" (resumed after {int(data['periods'])})" if found is not None else ""))
    window = cfg.steady_state.window_cycles if cfg.steady_state is not None else 20
    # per period of the last `window`: (columns, point_state, point_fn, trajectory, the row before the period)
    history = []
    t = t_start
    if found is None:
        last_row = np.zeros(rk.N_COLUMNS)       # the state before the first step: energies 0, the stored energy
        last_row[rk.C_TIME] = t
        gaps = geo.g0 + geo.sin_a * rot[0] + np.einsum("ij,ij->i", geo.frame[:, 0, :],
                                                       geo.displacement(q[:3 * n_b].reshape(-1, 3)))
        penalty0 = sum(rk._penalty(-g, contact.stiffness * A)[2] for g, A in zip(gaps, geo.area) if g < 0)
        last_row[rk.C_E_STORED] = (0.5 * v @ ring.M @ v + 0.5 * q @ ring.K @ q
                                   + 0.5 * rotation.inertia_kg_m2 * rot[4]**2 + 0.5 * body.mass_kg * rot[1]**2
                                   + preload * rot[0] + penalty0)
        reached_steady = False
        periods = 0
    else:
        last_row = np.array(data["last_row"])
        history = restart.history_of(data)
        reached_steady = bool(data["steady"])
        periods = int(data["periods"])
        if steady is not None:
            steady.means = [float(m) for m in data["steady_means"]]
    start = time.perf_counter()
    checkpoint_wall = 0.0
    try:
        while periods < max_periods and not reached_steady:
            t = one_period(t)
            if istate[rk.I_FAILED]:
                raise NumericalFailure(f"modal tier (motor): a step failed at t = {t:.6e} s after "
                                       f"{MAX_CUTBACK_LEVEL} halvings of dt")
            periods += 1
            series.write_block(motor_block(columns, geo, body, contact.name, names, amplitudes, phases, omega,
                                           cosine, cfg.bodies[0].position_m[2]))
            kill_point("series_block")
            history.append((columns.copy(), point_state.copy(), point_fn.copy(), trajectory.copy(), last_row))
            last_row = columns[-1].copy()
            if len(history) > window:
                history.pop(0)
            if steady is not None:
                watched = columns[:, rk.C_SPIN] if spin_free else columns[:, rk.C_TORQUE]
                reached_steady = steady.add(float(np.mean(watched)))
            if reached_steady or periods == max_periods or (every and periods % every == 0):
                mark = time.perf_counter()
                arrays = restart.state_arrays(q, v, a, rot, energies, istate, t, periods, reached_steady,
                                              steady.means if steady is not None else [], last_row, history)
                counters = {"periods": periods, "steps": int(istate[rk.I_STEPS]),
                            "cutbacks": int(istate[rk.I_CUTBACKS]), "steady": reached_steady}
                # the record's time is the run's own clock, the one end_time_s bounds (a warm start's run begins
                # at its state's time); the state's own time is in the arrays
                checkpoint.write_arrays(periods * period, arrays, counters, rows_of=lambda: series.rows_written,
                                        meta={restart.MODEL_KEY: restart.MODEL_FILE})
                checkpoint_wall += time.perf_counter() - mark
    finally:
        series.close()
    wall = time.perf_counter() - start
    state_path = out_dir / "motor_state.npz"
    if comm.rank == 0:
        atomic_write(state_path, lambda fh: np.savez(fh, q=q, v=v, a=a, rot=rot, t=t, cosine=cosine))
    point = operating_point(history, geo, case, spin_free)
    simulated = t - t_start                 # in this process (a resumed run: from the checkpoint)
    results = {"tier": "modal", "scene": "motor", "steps": int(istate[rk.I_STEPS]),
               "newton_iterations": int(istate[rk.I_NEWTON]), "cutbacks": int(istate[rk.I_CUTBACKS]),
               "periods": periods, "steps_per_period": per_period, "simulated_time_s": t, "wall_time_s": wall,
               "setup_wall_s": setup_wall, "reduction_wall_s": ring.reduction_wall_s,
               "wall_s_per_simulated_ms": wall / (simulated * 1e3) if simulated > 0 else None,
               "resumed_from_s": t_start if found is not None else None,
               "checkpoint": f"{checkpoint.dir.name}/checkpoint.json", "checkpoints_written": checkpoint.written,
               "checkpoint_wall_s": checkpoint_wall,
               "drive_frequency_Hz": f_drive, "initial_state": cfg.initial_state,
               "steady": reached_steady if steady is not None else None,
               "reduction": {"ring_points": n_b, "contact_points": geo.n_points,
                             "contact_sampling": "interpolated" if case.reduction.contact_points else "nodal",
                             "interface_dofs": 3 * n_b, "modes": int(ring.mode_frequencies_Hz.size),
                             "size": n, "highest_mode_Hz": float(ring.mode_frequencies_Hz.max()),
                             "band_area_m2": ring.band_area_m2, "from_checkpoint": found is not None,
                             "enrichment_modes_Hz": ring.enrichment_frequencies_Hz.tolist(),
                             "stator_resonances_near_drive_Hz": ring.resonances_Hz(f_drive).tolist()},
               "motor": point, "time_series": h5_path.name,
               "outputs": [h5_path.name, state_path.name, *restart.checkpoint_files(out_dir, checkpoint)]}
    if comm.rank == 0:
        ring_csv = out_dir / "motor_ring.csv"
        write_csv(ring_csv, point.pop("_ring"))
        results["outputs"].append(ring_csv.name)
        path_csv = out_dir / "motor_contact_path.csv"
        write_csv(path_csv, point.pop("_path"))
        results["outputs"].append(path_csv.name)
        if case.output.plots:
            from app.motor.plots import operating_point_plots

            results["outputs"] += operating_point_plots(out_dir, ring_csv, path_csv, case.title)
    else:
        point.pop("_ring")
        point.pop("_path")
    log(f"transient (modal tier, motor): {periods} periods, {results['steps']} steps, {results['cutbacks']} cut-backs, "
        f"{wall:.1f} s wall ({checkpoint.written} checkpoints {checkpoint_wall:.2f} s); "
        f"speed {point['speed_rpm']:.2f} rpm, torque {point['friction_torque_N_m']:.4g} N m, "
        f"efficiency {100 * point['efficiency']:.2f} %, steady {results['steady']}")
    return results


def run_continued(case_path: str | Path, overrides: list[str], out_dir: str | Path,
                  warm_start: str | Path | None, comm=MPI.COMM_WORLD) -> dict:
    """One motor point continued from ``warm_start`` (an earlier run's ``motor_state.npz``; None: from the case's
    start), silently, into ``out_dir``: the benches' chained and settled points. Returns the transient results."""
    from app.runner import load_for_run

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return run(load_for_run(case_path, overrides), out, comm, lambda *_: None, warm_start=warm_start)


def motor_units(body: str, contact: str, electrodes: list[str]) -> dict[str, str]:
    units = {S.TIME: "s", S.STEP: "s", S.DRIVE: "V", S.body_position(body): "m", S.body_velocity(body): "m/s",
             S.body_angle(body): "rad", S.body_angular_velocity(body): "rad/s", S.contact_force(contact): "N",
             S.contact_closed(contact): "1", f"{contact}_torque_N_m": "N m", f"{contact}_normal_force_N": "N",
             f"{contact}_points_in_contact": "1", f"{contact}_area_in_contact_m2": "m^2",
             f"{contact}_drive_speed_m_per_s": "m/s",
             f"{contact}_dissipated_J": "J", "electrical_input_J": "J", "damping_dissipated_J": "J",
             "output_work_J": "J", "stored_energy_J": "J", "electrode_reaction_work_J": "J", "contact_work_J": "J"}
    units.update({S.electrode_voltage(e): "V" for e in electrodes})
    return units


def motor_block(columns, geo, body, contact, electrodes, amplitudes, phases, omega, cosine, z_ref) -> dict:
    t = columns[:, rk.C_TIME]
    rows = t.size
    block = {S.TIME: t, S.STEP: np.full(rows, t[1] - t[0] if rows > 1 else t[0])}
    for e, name in enumerate(electrodes):
        arg = omega * t + phases[e]
        block[S.electrode_voltage(name)] = amplitudes[e] * (np.cos(arg) if cosine else np.sin(arg))
    block[S.DRIVE] = block[S.electrode_voltage(electrodes[0])]
    position = np.zeros((rows, 3))
    position[:, 2] = z_ref + columns[:, rk.C_DZ]
    velocity = np.zeros((rows, 3))
    velocity[:, 2] = columns[:, rk.C_DZ_RATE]
    block[S.body_position(body.name)] = position
    block[S.body_velocity(body.name)] = velocity
    block[S.body_angle(body.name)] = columns[:, rk.C_ANGLE:rk.C_ANGLE + 1]
    block[S.body_angular_velocity(body.name)] = columns[:, rk.C_SPIN:rk.C_SPIN + 1]
    force = np.zeros((rows, 3))
    force[:, 2] = columns[:, rk.C_AXIAL]
    block[S.contact_force(contact)] = force
    block[S.contact_closed(contact)] = (columns[:, rk.C_ACTIVE] > 0).astype(float)
    block[f"{contact}_torque_N_m"] = columns[:, rk.C_TORQUE]
    block[f"{contact}_normal_force_N"] = columns[:, rk.C_NORMAL]
    block[f"{contact}_points_in_contact"] = columns[:, rk.C_ACTIVE]
    # the FE tier's name and meaning: the band area whose contact points are closed (points carry equal areas)
    block[f"{contact}_area_in_contact_m2"] = columns[:, rk.C_ACTIVE] * float(geo.area[0])
    block[f"{contact}_drive_speed_m_per_s"] = columns[:, rk.C_DRIVE_SPEED]
    block[f"{contact}_dissipated_J"] = columns[:, rk.C_E_FRIC]
    block["electrical_input_J"] = columns[:, rk.C_E_EL]
    block["damping_dissipated_J"] = columns[:, rk.C_E_DAMP]
    block["output_work_J"] = columns[:, rk.C_E_OUT]
    block["stored_energy_J"] = columns[:, rk.C_E_STORED]
    block["electrode_reaction_work_J"] = columns[:, rk.C_E_REACTION]
    block["contact_work_J"] = columns[:, rk.C_E_CONTACT]
    return block


def operating_point(history, geo: Geometry, case, spin_free: bool) -> dict:
    """The steady operating point over the last periods (the steady-state window): means, powers, efficiency,
    energy balance, contact states along the band, pressure round the ring, the contact point's path."""
    cols = np.concatenate([h[0] for h in history])
    states = np.concatenate([h[1] for h in history])
    fns = np.concatenate([h[2] for h in history])
    before = history[0][4]          # the row that ends the period before the window
    energy = {k: cols[-1, k] - before[k] for k in (rk.C_E_EL, rk.C_E_DAMP, rk.C_E_FRIC, rk.C_E_OUT, rk.C_E_STORED,
                                                   rk.C_E_REACTION, rk.C_E_CONTACT, rk.C_E_ROTOR, rk.C_E_PENALTY)}
    duration = cols[-1, rk.C_TIME] - before[rk.C_TIME]
    body = case.transient.bodies[0]
    rotation = body.rotations[0]
    speed = float(np.mean(cols[:, rk.C_SPIN]))
    load = rotation.torque_N_m - rotation.brake_N_m_s_per_rad * speed
    torque = float(np.mean(cols[:, rk.C_TORQUE]))
    p_el = energy[rk.C_E_EL] / duration
    p_out = energy[rk.C_E_OUT] / duration
    # friction loss: the work the stator does on the contact that neither the penalty stores nor the rotor takes
    # (the scheme's own discrete work); the trapezoidal sum of the slip power -f_t.s is reported beside it
    friction_J = energy[rk.C_E_CONTACT] - energy[rk.C_E_ROTOR] - energy[rk.C_E_PENALTY]
    p_fric = friction_J / duration
    p_fric_slip = energy[rk.C_E_FRIC] / duration
    p_damp = energy[rk.C_E_DAMP] / duration
    mech = torque * speed                   # friction torque times speed: the shaft power the contact delivers
    stored = energy[rk.C_E_STORED]
    balance = energy[rk.C_E_EL] - (energy[rk.C_E_DAMP] + friction_J + energy[rk.C_E_OUT] + stored)
    normal = float(np.mean(cols[:, rk.C_NORMAL]))
    counts = np.array([(states == s).mean() for s in (rk.SEPARATED, rk.STICK, rk.FORWARD_SLIP, rk.BACKWARD_SLIP)])
    drive_sign = np.sign(np.mean(cols[:, rk.C_DRIVE_SPEED])) or 1.0
    forward, backward = (counts[2], counts[3]) if drive_sign > 0 else (counts[3], counts[2])
    pressure = fns / geo.area[None, :]
    order = np.argsort(geo.angle_deg)
    ring_rows = {"angle_deg": geo.angle_deg[order], "mean_pressure_Pa": pressure.mean(axis=0)[order],
                 "last_pressure_Pa": pressure[-1][order],
                 "contact_fraction": (states != rk.SEPARATED).mean(axis=0)[order],
                 "stick_fraction": (states == rk.STICK).mean(axis=0)[order]}
    path = history[-1][3]
    alpha = math.radians(case.transient.contacts[0].half_angle_deg)
    friction = case.transient.contacts[0].friction
    mu_s = friction.mu_dynamic * friction.static_ratio if friction is not None else 0.0
    r_c = float(np.mean(geo.rho))
    preload = -float((body.applied_force_N or [0, 0, 0])[2])
    return {
        "speed_rad_per_s": speed, "speed_rpm": speed * 60.0 / (2 * math.pi),
        "speed_change_over_window": float(np.ptp([np.mean(h[0][:, rk.C_SPIN]) for h in history])),
        "load_torque_N_m": -load, "friction_torque_N_m": torque,
        "friction_torque_std_N_m": float(np.std([np.mean(h[0][:, rk.C_TORQUE]) for h in history])),
        "output_power_W": p_out if spin_free else mech, "shaft_power_W": mech,
        "electrical_power_W": p_el, "efficiency": (p_out if spin_free else mech) / p_el if p_el > 0 else 0.0,
        "friction_loss_W": p_fric, "friction_slip_power_W": p_fric_slip, "damping_loss_W": p_damp,
        "electrical_power_from_reactions_W": energy[rk.C_E_REACTION] / duration,
        "energy_balance_reactions_relative": (energy[rk.C_E_REACTION] - (energy[rk.C_E_EL] - balance))
        / energy[rk.C_E_REACTION] if energy[rk.C_E_REACTION] else 0.0,
        "energy_balance_relative": balance / energy[rk.C_E_EL] if energy[rk.C_E_EL] else 0.0,
        "stored_energy_change_J": stored, "window_s": duration,
        "normal_force_N": normal, "normal_force_closed_form_N": preload / math.sin(alpha),
        "axial_force_N": float(np.mean(cols[:, rk.C_AXIAL])),
        "coulomb_torque_bound_N_m": mu_s * preload / math.sin(alpha) * r_c, "contact_radius_m": r_c,
        "rotor_axial_offset_m": float(np.mean(cols[:, rk.C_DZ])),
        "rotor_axial_vibration_m": float(np.ptp(cols[:, rk.C_DZ])),
        "fractions": {"separation": float(counts[0]), "stick": float(counts[1]), "forward_slip": float(forward),
                      "backward_slip": float(backward)},
        "points_in_contact_mean": float(np.mean(cols[:, rk.C_ACTIVE])),
        "drive_speed_m_per_s": float(np.mean(cols[:, rk.C_DRIVE_SPEED])),
        "contact_point_amplitude_m": {"normal": float(np.ptp(path[:, 0]) / 2),
                                      "tangential": float(np.ptp(path[:, 1]) / 2),
                                      "meridional": float(np.ptp(path[:, 2]) / 2)},
        "_ring": ring_rows, "_path": {"time_s": history[-1][0][:, rk.C_TIME], "normal_m": path[:, 0],
                                      "tangential_m": path[:, 1], "meridional_m": path[:, 2]},
    }


def write_csv(path: Path, rows: dict) -> None:
    """Columns of equal length as CSV, a header of their names."""
    keys = list(rows)
    lines = [",".join(keys)]
    for i in range(len(rows[keys[0]])):
        lines.append(",".join(f"{rows[k][i]:.8g}" for k in keys))
    replace_file(path, ("\n".join(lines) + "\n").encode())      # whole or not at all: a killed run


def check_model(case, comm) -> None:
    """``validate``'s checks that need the mesh: the contact band exists and can carry ring_points nodes, no
    floating electrodes (without reducing anything)."""
    from app.fe.model import build_model, facet_group_tag

    file = case.source
    model = build_model(case, comm)
    if model.electrodes_of("floating"):
        raise CaseError(file, "electrodes", "floating electrodes are not supported by the transient analysis")
    contact = case.transient.contacts[0]
    tag = facet_group_tag(model.mesh_data.facet_names, contact.facets, file, "transient.contacts[0].facets")
    xyz, _ = _band_nodes(model, tag)
    if case.reduction.ring_points > xyz.shape[0]:
        raise CaseError(file, "reduction.ring_points", f"the band has only {xyz.shape[0]} nodes")


def table_rows(results: dict) -> list[tuple[str, str, str]]:
    """End-of-run lines of a motor operating point."""
    p = results["motor"]
    f = p["fractions"]
    return [("simulated time / periods", f"{results['simulated_time_s'] * 1e3:.4g} / {results['periods']}", "ms / -"),
            ("steps / cut-backs", f"{results['steps']} / {results['cutbacks']}", "-"),
            ("steady state reached", str(results["steady"]), "-"),
            ("wall time per simulated ms", "-" if results["wall_s_per_simulated_ms"] is None
             else f"{results['wall_s_per_simulated_ms']:.4g}", "s"),       # None: a finished run resumed
            ("rotor speed", f"{p['speed_rpm']:.4g} ({p['speed_rad_per_s']:.4g} rad/s)", "rpm"),
            ("load torque / friction torque",
             f"{p['load_torque_N_m'] * 1e3:.4g} / {p['friction_torque_N_m'] * 1e3:.4g}",
             "mN m"),
            ("Coulomb bound mu_s N r_c", f"{p['coulomb_torque_bound_N_m'] * 1e3:.4g}", "mN m"),
            ("normal force (P / sin alpha)", f"{p['normal_force_N']:.4g} ({p['normal_force_closed_form_N']:.4g})", "N"),
            ("output / electrical power",
             f"{p['output_power_W'] * 1e3:.4g} / {p['electrical_power_W'] * 1e3:.4g}", "mW"),
            ("efficiency", f"{100 * p['efficiency']:.3g}", "%"),
            ("friction / damping loss", f"{p['friction_loss_W'] * 1e3:.4g} / {p['damping_loss_W'] * 1e3:.4g}", "mW"),
            ("energy balance (relative)", f"{p['energy_balance_relative']:.2e}", "-"),
            ("separation / stick / fwd slip / bwd slip",
             f"{f['separation']:.3f} / {f['stick']:.3f} / {f['forward_slip']:.3f} / {f['backward_slip']:.3f}", "-")]
