"""The modal tier's engine for the run loop (app/loop/loop.py): the case's reduced model (app/reduced/model.py,
cached), its rigid bodies and interactions as the compiled loop's records (app/reduced/loop_kernel.py), the
rows under the output convention of every tier (app/series.py), so the FE tier and this one report alike.

The drive (electrode amplitudes, a target tip amplitude, the harmonic start) follows the one rule of
app/drive.py; the rigid bodies, contacts, base motions, seating and the steady-state stop are the case's keys
as the FE tier reads them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app import series as S
from app.contact.records import AXES, bodies_record, contact_records, sites_record
from app.contact.tables import SiteTables, site_groups
from app.drive import electrode_amplitudes
from app.errors import CaseError, NumericalFailure
from app.killpoint import kill_point
from app.loop.checkpoint import Found, read_on_root, write_engine_file
from app.reduced import kernel as lk
from app.reduced.coordinates import FREE_MODES, PHYSICAL, RECORD_KEY, free_modes, in_free_modes
from app.reduced.model import ReducedModel, load_or_build

MODEL_FILE = "reduced-model.npz"
ROWS_PER_CALL = 4096
#: field frames the kernel buffers in a call, and frame times it is given at once (app/reduced/kernel.py Frames)
FRAMES_PER_CALL = 256
FRAME_TIMES_PER_CALL = 256


class ModalEngine:
    """The modal tier as an :class:`app.loop.loop.Engine`."""

    tier = "modal"

    def __init__(self, case, comm, log, found: Found | None = None):
        from app.blas import limit_blas_threads

        limit_blas_threads()     # the kernel's small products: threads cost more than they give (BENCHMARKS.md)
        self.case, self.comm, self.log = case, comm, log
        self.cfg = cfg = case.transient
        self.end_time_s = cfg.end_time_s
        self.checkpoint_interval_steps = cfg.checkpoint_interval_steps
        start = time.perf_counter()
        self._warm = None
        self._period_factor = None     # period_state's factor of M_FF, formed at its first call
        if found is None and cfg.start_from is not None:
            # read before the model is built or loaded, and before a fresh run clears its directory (which may be
            # the one it starts from): a bad directory costs nothing
            from app.loop.checkpoint import read_warm_start

            warm = read_warm_start(case, comm, self.tier)
            files = warm.record.get("files") or {}
            path = warm.pointer.parent / str(files.get("reduced_model", MODEL_FILE))
            self._warm = (warm, read_on_root(path, comm, ReducedModel.load, "a reduced model"))
        if found is not None:
            path = found.pointer.parent / str((found.record.get("files") or {}).get("reduced_model", MODEL_FILE))
            self.model: ReducedModel = read_on_root(path, comm, ReducedModel.load, "a reduced model")
            self.from_cache = None
            log(f"modal tier: reduced model from the checkpoint {path}")
        else:
            self.model, self.from_cache = load_or_build(case, comm, log)
        self.drive_lock = None
        if cfg.drive.lock == "resonance":
            # the reduced structure's own resonance (with enrichment: the FE stator's pair exactly); the case as run
            # has the resolved frequency, the basis keeps the nominal one (app/drive.py locked_case)
            from app.drive import drive_lock_line, locked_case

            found_Hz = self.model.resonances_Hz(cfg.drive.frequency_Hz, cfg.drive.lock_modes)
            self.case, self.drive_lock = locked_case(case, found_Hz)
            self.cfg = cfg = self.case.transient
            log(drive_lock_line(self.drive_lock))
        self.surgery = None
        if found is None:           # a checkpoint's model is the one its run used, surgery included
            self._surgery()
        # the run's coordinates: the model's free coordinates in its own modes where its site rows are few
        # (app/reduced/coordinates.py); the model as built (and operated on) stays for the checkpoint's file, the
        # warm-start checks and the field output
        self.built_model = self.model
        self.free_modes = free_modes(self.model, self.model.free_coordinates, comm)
        if self.free_modes is not None:
            self.model = in_free_modes(self.model, self.free_modes)
        self.setup_wall_s = time.perf_counter() - start
        # electrodes driven A cos(wt + phase) after a harmonic start, A sin from rest; a warm start keeps its
        # source run's, a resumed run its checkpoint's
        self.cosine_drive = cfg.initial_state == "harmonic"
        self.warm_start: dict | None = None
        self._records()

    def _surgery(self) -> None:
        """``reduction.surgery`` and ``site_motion`` (app/reduced/surgery.py) on the built model, at the drive as run
        (after the lock); the free wave at the cone contacts' sites logged and reported (what ``wave_scale`` scales)."""
        red, cfg, case = self.case.reduction, self.cfg, self.case
        if red.surgery == "none" and red.site_motion == "full":
            return
        from app.drive import electrode_amplitudes
        from app.reduced import surgery as sg

        model = self.model
        frequency = cfg.drive.frequency_Hz
        scale_V, weights, phases = electrode_amplitudes(case, list(model.inputs[:model.n_electrodes]))
        bodies = {b.name: b for b in cfg.bodies}
        contact_site = np.asarray(model.site_contact)
        chosen, frames, angles, travelling = [], [], [], []
        for k, c in enumerate(cfg.contacts):
            if c.kind == "surface" and c.shape == "cone":
                sites = np.flatnonzero(contact_site == k)
                points = np.asarray(model.site_points)[sites]
                chosen.append(sites)
                frames.append(sg.cone_frames(points, bodies[c.body].position_m, c.axis, math.radians(c.half_angle_deg)))
                angles.append(sg.cone_angles(points, bodies[c.body].position_m, c.axis))
                travelling.append((sites, frames[-1], angles[-1]))
        chosen = np.concatenate(chosen) if chosen else np.zeros(0, np.int64)
        frames = np.concatenate(frames) if frames else np.zeros((0, 3, 3))
        record = {"surgery": red.surgery, "site_motion": red.site_motion, "wave_scale": red.wave_scale}
        if chosen.size and model.n_electrodes:
            wave = sg.site_wave(model, frequency, scale_V * weights, phases, chosen, frames)
            record["free_site_wave_m"] = wave
            self.log(f"surgery: the free wave at the cone sites, {scale_V:g} V: normal "
                     f"{wave['normal_m'] * 1e6:.4g} um, circumferential {wave['circumferential_m'] * 1e6:.4g} um, "
                     f"meridional {wave['meridional_m'] * 1e6:.4g} um (the reduced model as built)")
        if red.surgery in ("modal_pair", "rigid_wave", "travelling_wave"):
            model = sg.modal_pair(model, frequency)
        if red.surgery == "rigid_wave":
            model = sg.rigid_wave(model, frequency, weights, phases, red.wave_scale)
        if red.surgery == "travelling_wave":         # one cone contact (app/case/options.py)
            model = sg.rigid_wave(model, frequency, weights, phases, red.wave_scale, travelling=travelling[0])
        if red.site_motion == "planar":
            model = sg.planar_sites(model, chosen, frames)
        if chosen.size and model.n_electrodes:
            # the wave the surgery leaves at the sites, free (no contact): a rigid wave's is the one prescribed
            record["site_wave_m"] = sg.site_wave(model, frequency, scale_V * weights, phases, chosen, frames)
        self.log(f"surgery: {red.surgery}, sites {red.site_motion}" + (f", wave x {red.wave_scale:g}"
                                                                      if red.surgery.endswith("_wave") else "")
                 + f": {model.size} coordinates")
        self.model, self.surgery = model, record

    @classmethod
    def check(cls, case, comm, log) -> None:
        """``validate``: the checks that need the mesh (facet groups, node points, the interface), without
        reducing anything."""
        from app.fe.model import build_model
        from app.reduced.model import contact_site_sets

        if case.transient.start_from is not None:       # the directory and its checkpoint; the model's fit at run
            from app.loop.checkpoint import read_warm_start

            read_warm_start(case, comm, cls.tier)
        model = build_model(case, comm)
        if model.electrodes_of("floating"):
            raise CaseError(case.source, "electrodes",
                            "floating electrodes are not supported by the transient analysis")
        contact_site_sets(case, model)

    # ---------------------------------------------------------------- the kernel's records
    def _records(self) -> None:
        case, cfg, model = self.case, self.cfg, self.model
        file = case.source
        gdim = model.gdim
        inputs, free = model.input_coordinates, model.free_coordinates
        gravity = np.asarray(cfg.loads.gravity_m_per_s2 or [0.0] * gdim, dtype=float)
        force = np.asarray(cfg.loads.fe_force_N or [0.0] * gdim, dtype=float)
        for key, value in (("gravity_m_per_s2", gravity), ("fe_force_N", force)):
            if value.size != gdim:
                raise CaseError(file, f"transient.loads.{key}", f"needs {gdim} components")
        acceleration = gravity + force / model.mass_kg
        load = acceleration @ model.translation_loads
        self.structure = lk.Structure(model.K, model.M, model.C, load, free, inputs)
        s = cfg.scheme.scheme()
        self.scheme = lk.Scheme(s.beta, s.gamma, s.alpha_m, s.alpha_f)
        st = cfg.steps
        self.control = lk.Control(st.open_s, st.closed_s, st.change_s, st.min_s, 2.0)
        self.bodies_record, self.body_slices = bodies_record(case, gdim, gravity)
        self.contacts_record, self.links_record = contact_records(case)
        self.sites_record = sites_record(case, model.site_points, model.site_weight, model.site_contact,
                                         model.site_rows,
                                         self.contacts_record, self.bodies_record)
        self.electrodes = list(model.inputs[:model.n_electrodes])
        self.scale_V, amplitudes, phases = electrode_amplitudes(case, self.electrodes)
        self.inputs_record = self._inputs(amplitudes, phases, 1.0)
        self.sample_rows = np.vstack([model.sample_rows, model.charge_rows]) if model.n_electrodes else \
            model.sample_rows
        self.cache = lk.make_cache(free.size, model.site_rows.shape[0])

    def _inputs(self, amplitudes, phases, scale):
        """The prescribed coordinates' time functions: electrodes (amplitude [V], phase), then each base motion's
        four patterns (its amplitudes W, U and the ramp)."""
        cfg, model = self.cfg, self.model
        kinds, amps, ph, ramps = [], [], [], []
        omega = 2 * math.pi * cfg.drive.frequency_Hz
        for e in range(model.n_electrodes):
            kinds.append(lk.ELECTRODE)
            amps.append(amplitudes[e] * scale)
            ph.append(phases[e])
            ramps.append(0.0)
        motions = {m.name: m for m in cfg.base_motions}
        for name in model.inputs[model.n_electrodes:]:
            motion_name, pattern = name.split(":")
            m = motions[motion_name]
            frequency = m.frequency_Hz or cfg.drive.frequency_Hz
            if abs(2 * math.pi * frequency - omega) > 1e-9 * omega:
                raise CaseError(self.case.source, "transient.base_motions.frequency_Hz",
                                "the modal tier drives base motions at the drive frequency")
            W, U = m.normal_amplitude_m, m.tangential_amplitude_m
            # u = cos wt (W cos kx n + U sin kx e) + sin wt (W sin kx n - U cos kx e), ramped
            kind, amplitude = {"n_cos": (lk.PATTERN_COS, W), "n_sin": (lk.PATTERN_SIN, W),
                               "e_sin": (lk.PATTERN_COS, U), "e_cos": (lk.PATTERN_SIN, -U)}[pattern]
            kinds.append(kind)
            amps.append(amplitude)
            ph.append(0.0)
            ramps.append(m.ramp_periods / frequency)
        return lk.Inputs(np.array(kinds, np.int64), np.array(amps, float), np.array(ph, float),
                         np.array(ramps, float), omega, self.cosine_drive)

    # ---------------------------------------------------------------- start / restore
    def _allocate(self) -> None:
        model = self.model
        n, m = model.size, self.bodies_record.mass.size
        n_c, n_l = self.contacts_record.kind.size, self.links_record.lower.size
        cap = ROWS_PER_CALL
        self._out = (np.zeros(cap), np.zeros(cap), np.zeros((cap, self.sample_rows.shape[0])),
                     np.zeros((cap, self.structure.inputs.size)), np.zeros((cap, m)), np.zeros((cap, m)),
                     np.zeros((cap, n_c + n_l, 3)), np.zeros((cap, n_c, 3)), np.zeros((cap, n_c)),
                     np.zeros((cap, n_c)), np.zeros((cap, n_c + n_l), np.bool_), np.zeros((cap, n_c + n_l)),
                     np.zeros((cap, 5)), np.zeros((cap, n_c, 3)), np.zeros((cap, n_c)))
        ns = self.sites_record.contact.size
        sampled = [(name, self.sites_record.contact == k) for k, name in enumerate(self._kernel_contact_names())
                   if self.contacts_record.kind[k] == lk.SURFACE]
        self.tables = SiteTables(sampled, ns, self.cfg.output_interval_s,
                                 site_groups(self.case, np.asarray(self.model.site_contact)))
        self.q, self.v, self.a = np.zeros(n), np.zeros(n), np.zeros(n)
        self.z, self.zd, self.zdd = np.zeros(m), np.zeros(m), np.zeros(m)
        self.istate = np.zeros(lk.N_ISTATE, np.int64)
        self.fstate = np.zeros(lk.N_FSTATE)
        self.fstate[lk.F_CAP] = np.inf
        self.sums = lk.Sums(np.zeros(n_c + n_l), np.full(n_c + n_l, np.nan), np.zeros(2))   # power: none yet
        self.site_force = np.zeros((ns, 3))
        self.frames = lk.no_frames(n, m)     # the field frames the kernel takes (field_export), none by default
        self._frame_series = None
        self._taken: list[tuple[float, np.ndarray, np.ndarray]] = []

    def _harmonic(self, scale: float) -> np.ndarray:
        """Complex steady-state coordinates for the electrodes' phasors (amplitude ``scale`` x weight,
        their phases), the other inputs held (a base motion starts from rest)."""
        model = self.model
        omega = self.inputs_record.omega
        D = model.K - omega**2 * model.M + 1j * omega * model.C
        P, F = self.structure.inputs, self.structure.free
        x = np.zeros(model.size, dtype=complex)
        for e in range(model.n_electrodes):
            x[P[e]] = scale * self._weights[e] * np.exp(1j * self._phases[e])
        x[F] = np.linalg.solve(D[np.ix_(F, F)], -D[np.ix_(F, P)] @ x[P])
        return x

    def start(self) -> None:
        cfg, model = self.cfg, self.model
        self._allocate()
        self.scale_V, self._weights, self._phases = electrode_amplitudes(self.case, self.electrodes)
        if cfg.drive.tip_amplitude_m is not None or cfg.initial_state == "harmonic":
            if not model.n_electrodes:
                key = "drive.tip_amplitude_m" if cfg.drive.tip_amplitude_m is not None else "initial_state"
                raise CaseError(self.case.source, f"transient.{key}",
                                "needs an electrode of kind 'voltage' (a harmonic solve)")
        if cfg.drive.tip_amplitude_m is not None:
            from app.drive import target_voltage

            point = model.sample_names.index(cfg.drive.point)
            per_volt = abs(model.sample_rows[point] @ self._harmonic(1.0))
            self.scale_V = target_voltage(cfg.drive.tip_amplitude_m, per_volt)
        if cfg.start_from is not None:
            self._warm_start()
            return
        self.inputs_record = self._inputs(self._weights, self._phases, self.scale_V)
        P, F = self.structure.inputs, self.structure.free
        q, v, a = self.q, self.v, self.a
        omega = self.inputs_record.omega
        if cfg.initial_state == "harmonic":
            x = self._harmonic(self.scale_V)
            q[:], v[:], a[:] = x.real, -omega * x.imag, -omega**2 * x.real
            if self.surgery is not None and self.surgery["surgery"] in ("rigid_wave", "travelling_wave"):
                self._scheme_steady_inputs(x)
            kill_point("harmonic_start")
        else:                    # from rest: the free coordinates cancel the moving inputs' modes
            values = np.zeros(P.size)
            lk.input_values(0.0, self.inputs_record, values)
            q[P] = values
            h = 1e-7 / omega
            plus, minus = np.zeros(P.size), np.zeros(P.size)
            lk.input_values(h, self.inputs_record, plus)
            lk.input_values(-h, self.inputs_record, minus)
            v[P] = (plus - minus) / (2 * h)
            a[P] = (plus - 2 * values + minus) / (h * h)
            MFF = model.M[np.ix_(F, F)]
            q[F] = -np.linalg.solve(MFF, model.M[np.ix_(F, P)] @ q[P])
            v[F] = -np.linalg.solve(MFF, model.M[np.ix_(F, P)] @ v[P])
        rhs = self.structure.load - model.K @ q - model.C @ v - model.M[:, P] @ a[P]
        a[F] = np.linalg.solve(model.M[np.ix_(F, F)], rhs[F])
        self._bodies_at_rest()
        self._seat()
        if self.case.output.contact_sites:
            self.tables.geometry(self.model.site_points, self.model.site_weight)
        self._started()

    def _scheme_steady_inputs(self, x: np.ndarray) -> None:
        """A prescribed wave's harmonic start (``reduction.surgery`` 'rigid_wave', 'travelling_wave'): the inputs'
        rate and acceleration on the time scheme's own steady state at the closed-contact step, not the continuous
        one. The kernel advances a prescribed coordinate's rate and acceleration by Newmark's update from its
        values (app/reduced/kernel.py), so for q_n = Re(Q z^n), z = exp(i w dt), the rate and acceleration phasors
        are V = g_v Q, A = g_a Q (A = (z - 1) Q / (dt^2 [((1 - gamma) + gamma z) / (z - 1) + 1/2 - beta + beta z]),
        V = dt ((1 - gamma) + gamma z) A / (z - 1)); started from the continuous ones instead, the difference
        (for the trapezoidal rule |g_v| = (2 / dt) tan(w dt / 2), 0.2 % above w at 40 steps per period) rides on
        the prescribed rates as an undamped step-to-step alternation of that size, which the contact sites would
        feel as slip. The prescribed crest speed is then |g_v| U_t (bench/bench_motor_chain.py compares with it)."""
        from forms.newmark import harmonic_rate_gains

        P = self.structure.inputs
        g_v, g_a = harmonic_rate_gains(self.inputs_record.omega, self.cfg.steps.closed_s, self.scheme.beta,
                                       self.scheme.gamma)
        self.v[P] = (g_v * x[P]).real
        self.a[P] = (g_a * x[P]).real

    def _warm_start(self) -> None:
        """``transient.start_from``: the structure's and the bodies' state at the end of an earlier run of the same
        reduced model, the clock moved back by whole drive periods (the electrodes' phase unchanged, the drive's
        sine or cosine kept from that run), the counters and energy sums from zero. A held rotation takes this
        case's rate."""
        from app.loop.checkpoint import warm_start_directory

        cfg, model, file, key = self.cfg, self.model, self.case.source, "transient.start_from"
        found, other = self._warm
        directory = warm_start_directory(self.case)
        built = self.built_model
        if other.size != built.size or not (np.allclose(other.K, built.K, rtol=1e-10, atol=1e-10 * abs(built.K).max())
                                            and np.allclose(other.M, built.M, rtol=1e-10,
                                                            atol=1e-10 * abs(built.M).max())):
            raise CaseError(file, key, f"the run in {directory} has another reduced model ({other.size} coordinates, "
                                       f"this case {model.size}, or other matrices): a warm start needs the same "
                                       "stator, mesh and reduction")
        data = found.arrays
        for name in ("q", "v", "a", "z", "zd", "zdd", "fstate", "site_force"):
            if name not in data:
                raise CaseError(file, key, f"{found.pointer}: {name!r} missing in the checkpoint's state")
            if np.shape(data[name]) != np.shape(getattr(self, name)) and name != "fstate":
                raise CaseError(file, key, f"the run in {directory} has another layout ({name}: "
                                           f"{np.shape(data[name])}, this case {np.shape(getattr(self, name))}): "
                                           "a warm start needs the same bodies and contact sites")
        for name in ("q", "v", "a", "z", "zd", "zdd", "site_force"):
            getattr(self, name)[:] = data[name]
        self._coordinates_of(found)
        held = ~self.bodies_record.free
        self.zd[held] = self.bodies_record.rate[held]
        self.zdd[held] = 0.0
        period = 1.0 / cfg.drive.frequency_Hz
        t0 = float(data["fstate"][lk.F_TIME])
        source_Hz = float(found.engine.get("drive_frequency_Hz", cfg.drive.frequency_Hz))
        if source_Hz == cfg.drive.frequency_Hz:
            self.fstate[lk.F_TIME] = max(t0 - math.floor(t0 / period + 1e-9) * period, 0.0)
        else:
            # another drive frequency (a frequency sweep): start where this drive's phase equals the source
            # drive's phase at t0, as a swept generator keeps its phase continuous (a jump in phase would kick
            # the stator like a step in the drive)
            cycles = t0 * source_Hz
            self.fstate[lk.F_TIME] = max(cycles - math.floor(cycles + 1e-9), 0.0) * period
        self.fstate[lk.F_CAP] = float(data["fstate"][lk.F_CAP])
        source_initial = ((found.record.get("case") or {}).get("transient") or {}).get("initial_state", "rest")
        self.cosine_drive = source_initial == "harmonic"
        self.inputs_record = self._inputs(self._weights, self._phases, self.scale_V)
        self.warm_start = {"directory": str(directory), "source_time_s": t0, "start_time_s": self.t,
                           "source_frequency_Hz": source_Hz, "frequency_Hz": cfg.drive.frequency_Hz,
                           "source_steps": int(data["istate"][lk.I_STEPS]) if "istate" in data else None}
        self.log(f"modal tier: warm start from {found.pointer} (its t = {t0 * 1e3:.6g} ms, here t = "
                 f"{self.t * 1e3:.6g} ms)")
        if self.case.output.contact_sites:
            self.tables.geometry(self.model.site_points, self.model.site_weight)
        self._started()

    def _bodies_at_rest(self) -> None:
        b = self.bodies_record
        cfg = self.cfg
        gdim = b.gdim
        for body in cfg.bodies:
            sl = self.body_slices[body.name]
            self.z[sl.start:sl.start + gdim] = body.position_m
            self.zd[sl.start:sl.start + gdim] = body.velocity_m_per_s or [0.0] * gdim
            for r, rot in enumerate(body.rotations):
                j = sl.start + gdim + r
                self.z[j] = rot.angle_rad
                self.zd[j] = rot.rate_rad_per_s if rot.motion != "fixed" else 0.0
        held = ~b.free
        self.zd[held] = b.rate[held]
        loaded = b.free & (b.mass > 0)
        self.zdd[:] = 0.0
        self.zdd[loaded] = (b.load[loaded] - b.brake[loaded] * self.zd[loaded]) / b.mass[loaded]

    def _site_gaps(self, z: np.ndarray) -> np.ndarray:
        """Every site's gap [m] at the current structure state and body coordinates ``z`` (rates zero)."""
        sites, gdim = self.sites_record, self.model.gdim
        work = lk.site_work(self.bodies_record.mass.size)
        y = np.zeros(3)
        zero = np.zeros(3)
        out = np.zeros(sites.contact.size)
        rows = sites.rows @ self.q
        for i in range(out.size):
            y[:gdim] = rows[i * gdim:(i + 1) * gdim]
            out[i] = lk.site_force(i, y, zero, z, np.zeros_like(z), sites, self.contacts_record, self.bodies_record,
                                   1.0, 1.0, False, work)[1]
        return out

    def _seat(self) -> None:
        """Bodies with ``seat_on`` move along their one free translation axis until the smallest gap of that
        contact's sites is zero (bisection on it: monotone in the distance)."""
        cfg = self.cfg
        kernel_index = {c.name: k for k, c in enumerate(c for c in cfg.contacts if c.kind != "point")}
        for body in cfg.bodies:
            if body.seat_on is None:
                continue
            k = kernel_index[body.seat_on]
            mine = self.sites_record.contact == k
            axis = (body.free_axes or [True] * len(body.position_m)).index(True)
            j = self.body_slices[body.name].start + axis

            def smallest(s, j=j, mine=mine):
                z = self.z.copy()
                z[j] += s
                return float(self._site_gaps(z)[mine].min())

            g0 = smallest(0.0)
            step = max(abs(g0), 1e-9)
            # the gap grows one way along the axis: find it, bracket the root, bisect
            direction = 1.0 if smallest(step) > g0 else -1.0
            lo, hi = 0.0, direction * step
            while (smallest(hi) < 0.0) == (g0 < 0.0) and abs(hi) < 1.0:
                lo, hi = hi, 2.0 * hi
            if g0 > 0.0:      # start above: move against the growth direction
                lo, hi = 0.0, -direction * step
                while smallest(hi) > 0.0 and abs(hi) < 1.0:
                    lo, hi = hi, 2.0 * hi
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                if (smallest(mid) > 0.0) == (smallest(lo) > 0.0):
                    lo = mid
                else:
                    hi = mid
                if abs(hi - lo) <= 1e-15 * max(1.0, abs(hi)):
                    break
            distance = hi if smallest(hi) >= 0.0 else lo
            self.z[j] += distance
            self.log(f"modal tier: body {body.name!r} seated on {body.seat_on!r}: moved {distance * 1e6:.6g} um along "
                     f"axis {axis}")

    def restore(self, found: Found) -> None:
        self._allocate()
        data = found.arrays
        for key in ("q", "v", "a", "z", "zd", "zdd", "istate", "fstate"):
            if key not in data:
                raise CaseError(str(found.pointer), key, "missing in the checkpoint's state")
            getattr(self, key)[:] = data[key]
        for name in ("dissipated", "power", "damping"):
            getattr(self.sums, name)[:] = data[f"sums_{name}"]
        if "site_force" in data:       # a checkpoint of an older version: its next step starts from no force
            self.site_force[:] = data["site_force"]
        self._coordinates_of(found)
        self.tables.restore(data, found.engine)
        self.scale_V = float(found.engine["drive_voltage_V"])
        self.cosine_drive = bool(found.engine.get("cosine_drive", self.cfg.initial_state == "harmonic"))
        self.warm_start = found.engine.get("warm_start")
        _, self._weights, self._phases = electrode_amplitudes(self.case, self.electrodes)
        self.inputs_record = self._inputs(self._weights, self._phases, self.scale_V)
        self._started()

    def _coordinates_of(self, found: Found) -> None:
        """q, v, a just read from a checkpoint whose record says which coordinates they are in (the model's own
        before the free modes, app/reduced/coordinates.py): converted to this run's. The same model always makes
        the same choice, so a conversion happens only for a checkpoint written before the free modes."""
        saved_in_modes = found.engine.get(RECORD_KEY, PHYSICAL) == FREE_MODES
        if self.free_modes is None and saved_in_modes:
            raise CaseError(str(found.pointer), f"engine.{RECORD_KEY}",
                            "the state is in the free modes of a model this run keeps in its own coordinates")
        if self.free_modes is not None and not saved_in_modes:
            for name in ("q", "v", "a"):
                getattr(self, name)[:] = self.free_modes.to_modes(getattr(self, name))

    def physical(self, q: np.ndarray) -> np.ndarray:
        """The model's own coordinates (as built) of the run's coordinates ``q`` ((n,) or (n, columns))."""
        return q if self.free_modes is None else self.free_modes.to_physical(q)

    def _started(self) -> None:
        cfg = self.cfg
        start = "warm" if self.warm_start is not None else cfg.initial_state
        self.log(f"modal tier: {start} start, drive {self.scale_V:.4g} V at {cfg.drive.frequency_Hz:.2f} "
                 f"Hz, {len(cfg.bodies)} rigid bodies, {len(cfg.contacts)} contacts, {self.model.size} coordinates, "
                 f"{self.sites_record.contact.size} contact sites, {cfg.end_time_s * 1e3:.4g} ms")
        # load (or compile) the kernel on a call that takes no step: set-up, not time-loop cost
        mark = time.perf_counter()
        saved = (self.fstate.copy(), self.istate.copy())
        out = lk.Outputs(*(arr[:1] for arr in self._out), *self._site_outputs())
        lk.run(self.t, self._state(), self._model(), self.cache, out, self.case.output.energies,
               lk.no_frames(self.q.size, self.z.size))
        self.fstate[:], self.istate[:] = saved
        self.compile_wall_s = time.perf_counter() - mark
        self._loop_wall = 0.0

    def _site_outputs(self) -> tuple:
        """The per-site diagnostics' accumulators the kernel adds to (app/contact/tables.py)."""
        tables = self.tables
        return tables.sums, tables.bins, tables.groups, tables.phase

    def _state(self) -> lk.State:
        return lk.State(self.q, self.v, self.a, self.z, self.zd, self.zdd, self.istate, self.fstate, self.sums,
                        self.site_force)

    def _model(self) -> lk.Model:
        return lk.Model(self.structure, self.inputs_record, self.scheme, self.control, self.bodies_record,
                        self.sites_record, self.contacts_record, self.links_record, self.sample_rows)

    @property
    def t(self) -> float:
        return float(self.fstate[lk.F_TIME])

    @property
    def steps(self) -> int:
        return int(self.istate[lk.I_STEPS])

    # ---------------------------------------------------------------- stepping
    def _kernel_contact_names(self) -> list[str]:
        return [c.name for c in self.cfg.contacts if c.kind != "point"]

    def columns(self) -> dict[str, str]:
        cfg, model, case = self.cfg, self.model, self.case
        units = {S.TIME: "s", S.STEP: "s", S.DRIVE: "V"}
        for name in case.points:
            units[S.point_displacement(name)] = "m"
        if model.n_electrodes > 1:
            for name in self.electrodes:
                units[S.electrode_voltage(name)] = "V"
        if case.output.energies:
            for name in self.electrodes:
                units[S.electrode_charge(name)] = "C"
            units.update(S.ENERGY_COLUMNS)
        for b in cfg.bodies:
            units.update(S.body_columns(b.name))
            if b.rotations:
                axes = ", ".join(r.axis for r in b.rotations)
                units[S.body_angle(b.name)] = f"rad ({axes})"
                units[S.body_angular_velocity(b.name)] = f"rad/s ({axes})"
        bodies = {b.name: b for b in cfg.bodies}
        for c in cfg.contacts:
            units.update(S.contact_columns(c.name))
            units[S.contact_dissipated(c.name)] = "J (damping and friction, since t = 0)"
            if c.kind == "surface" and bodies[c.body].rotations:
                units[S.contact_torque(c.name)] = "N m (on the rigid body, about its rotation axes)"
                units[S.contact_normal_force(c.name)] = "N"
                units[S.contact_area(c.name)] = "m^2"
            if c.kind == "surface" and case.output.contact_sites:
                units[S.contact_probe(c.name)] = "m (n, e1, e2)"
            if c.kind == "surface" and case.output.contact_pressure:
                units[S.contact_peak_pressure(c.name)] = "Pa"
        return units

    def advance(self, t_end: float, max_steps: int, stop_at_s: float) -> dict[str, np.ndarray]:
        blocks = []
        taken = 0
        sites_on = self.case.output.contact_sites
        start = time.perf_counter()
        if self._frame_series is not None:
            # the field frames from the series' next frame time on (the loop has taken every earlier one)
            self._frame_times(self._frame_series.next_s if not self._taken else
                              self._frame_series.schedule.next_after(self._taken[-1][0]))
        while self.t < t_end * (1 - 1e-12) and taken < max_steps:
            cap = int(min(ROWS_PER_CALL, max_steps - taken))
            out = lk.Outputs(*(arr[:cap] for arr in self._out), *self._site_outputs())
            stop = min(stop_at_s, self.tables.next_s * (1 - 1e-12)) if sites_on else stop_at_s
            self.fstate[lk.F_STOP] = stop
            code, rows = lk.run(t_end, self._state(), self._model(), self.cache, out, self.case.output.energies,
                                self.frames)
            if rows:
                blocks.append(self._block(out, rows))
            taken += rows
            if self.frames.slots[1]:
                self._take_frames_out()
            if code == lk.STEP_FAILED:
                raise NumericalFailure(f"modal tier: a step failed at t = {self.t:.6e} s after "
                                       f"{self.istate[lk.I_CUTBACKS]} cut-backs (dt below min_s = "
                                       f"{self.control.min_s:.3e} s)")
            if sites_on and self.tables.due(self.t):
                self.tables.row(self.t)
            if code == lk.DONE or (code == lk.STOPPED and self.t >= stop_at_s):
                break
        self._loop_wall += time.perf_counter() - start
        if not blocks:
            return {}
        return {k: np.concatenate([b[k] for b in blocks]) for k in blocks[0]}

    def _frame_times(self, from_s: float) -> None:
        """Give the kernel the field frame times from ``from_s`` (a frame time) on."""
        schedule = self._frame_series.schedule
        times = schedule.upcoming(from_s, FRAME_TIMES_PER_CALL) if math.isfinite(from_s) else np.zeros(0)
        self.frames = self.frames._replace(times=np.ascontiguousarray(times, dtype=float))
        self.frames.slots[0] = 0

    def _take_frames_out(self) -> None:
        """Move the frames the kernel took out of its buffers; give it further frame times when it took its
        last."""
        f = self.frames
        for i in range(int(f.slots[1])):
            self._taken.append((float(f.t[i]), self.physical(f.q[i].copy()), f.z[i].copy()))
        f.slots[1] = 0
        if f.slots[0] >= f.times.size and f.times.size:
            self._frame_times(self._frame_series.schedule.next_after(self._taken[-1][0]))

    def taken_frames(self) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """The field frames (t [s], coordinates q, body coordinates z) the kernel took since the last call
        (FieldSeriesExport.engine_frames)."""
        taken, self._taken = self._taken, []
        return taken

    def _block(self, out, rows: int) -> dict[str, np.ndarray]:
        cfg, model, case = self.cfg, self.model, self.case
        gdim = model.gdim
        block = {S.TIME: out.time[:rows].copy(), S.STEP: out.dt[:rows].copy(),
                 S.DRIVE: out.inputs[:rows, 0].copy() if model.n_electrodes else np.zeros(rows)}
        for i, name in enumerate(case.points):
            block[S.point_displacement(name)] = out.samples[:rows, i].copy()
        if model.n_electrodes > 1:
            for e, name in enumerate(self.electrodes):
                block[S.electrode_voltage(name)] = out.inputs[:rows, e].copy()
        if case.output.energies:
            n_points = len(case.points)
            for e, name in enumerate(self.electrodes):
                block[S.electrode_charge(name)] = out.samples[:rows, n_points + e].copy()
            for k, name in enumerate(S.ENERGY_COLUMNS):
                block[name] = out.energy[:rows, k].copy()
        for b in cfg.bodies:
            sl = self.body_slices[b.name]
            block[S.body_position(b.name)] = out.z[:rows, sl.start:sl.start + gdim].copy()
            block[S.body_velocity(b.name)] = out.zd[:rows, sl.start:sl.start + gdim].copy()
            if b.rotations:
                block[S.body_angle(b.name)] = out.z[:rows, sl.start + gdim:sl.stop].copy()
                block[S.body_angular_velocity(b.name)] = out.zd[:rows, sl.start + gdim:sl.stop].copy()
        bodies = {b.name: b for b in cfg.bodies}
        k = 0
        n_c = self.contacts_record.kind.size
        l = 0
        for c in cfg.contacts:
            j = k if c.kind != "point" else n_c + l
            block[S.contact_force(c.name)] = out.force[:rows, j, :gdim].copy()
            block[S.contact_closed(c.name)] = out.closed[:rows, j].astype(float)
            block[S.contact_dissipated(c.name)] = out.dissipated[:rows, j].copy()
            if c.kind == "surface" and bodies[c.body].rotations:
                axes = np.array([AXES[r.axis] for r in bodies[c.body].rotations])
                block[S.contact_torque(c.name)] = out.torque[:rows, k] @ axes.T
                block[S.contact_normal_force(c.name)] = out.normal[:rows, k].copy()
                block[S.contact_area(c.name)] = out.area[:rows, k].copy()
            if c.kind == "surface" and case.output.contact_sites:
                block[S.contact_probe(c.name)] = out.probe[:rows, k].copy()
            if c.kind == "surface" and case.output.contact_pressure:
                block[S.contact_peak_pressure(c.name)] = out.peak[:rows, k].copy()
            if c.kind == "point":
                l += 1
            else:
                k += 1
        return block

    def take_tables(self) -> dict:
        return self.tables.take()

    def period_state(self) -> np.ndarray:
        """The structure's state as the steady-state watch compares it from one period end to the next
        (``[transient.steady_state] rule = "orbit"``, app/loop/steady.py): its free coordinates, scaled so the
        vector's squared Euclidean norm is w^2 q_F^T M_FF q_F + v_F^T M_FF v_F [J] (w the drive's
        angular frequency): twice the kinetic energy of a harmonic motion at w through this state, so the
        norm of a steady harmonic state does not depend on the phase it is sampled at. M_FF, not K_FF: the mass
        block is positive definite also for a structure with rigid-body freedom. The bodies' state is left out (the
        rotor's speed is the watched quantity; its angle grows)."""
        F = self.structure.free
        if self._period_factor is None:
            # M_FF = L L^T: ||L^T x||^2 = x^T M_FF x
            self._period_factor = np.linalg.cholesky(self.model.M[np.ix_(F, F)]).T
        omega = 2 * math.pi * self.cfg.drive.frequency_Hz
        return np.concatenate([omega * (self._period_factor @ self.q[F]), self._period_factor @ self.v[F]])

    # ---------------------------------------------------------------- checkpoints, fields, results
    def snapshot(self) -> tuple[dict | None, dict]:
        site_arrays, site_record = self.tables.snapshot()
        arrays = {"q": self.q, "v": self.v, "a": self.a, "z": self.z, "zd": self.zd, "zdd": self.zdd,
                  "istate": self.istate, "fstate": self.fstate, "sums_dissipated": self.sums.dissipated,
                  "sums_power": self.sums.power, "sums_damping": self.sums.damping, "site_force": self.site_force,
                  **site_arrays}
        record = {"drive_voltage_V": self.scale_V, "drive_frequency_Hz": self.cfg.drive.frequency_Hz,
                  "cosine_drive": self.cosine_drive, "warm_start": self.warm_start,
                  RECORD_KEY: FREE_MODES if self.free_modes is not None else PHYSICAL, **site_record}
        return (arrays if self.comm.rank == 0 else None), record

    def checkpoint_files(self, out_dir: Path) -> dict[str, str]:
        return {"reduced_model": write_engine_file(out_dir, self.comm, MODEL_FILE, self.built_model.save)}

    def field_export(self, out_dir: Path, resume_from_s: float | None):
        if not self.case.output.fields:
            return None
        if not self.built_model.vertex_basis.size and self.comm.rank == 0:
            raise CaseError(self.case.source, "output.fields", "the reduced model holds no vertex basis")
        from app.transient.body_shapes import BodyMeshes
        from app.transient.fields import FieldSeriesExport, frame_schedule

        case, slices = self.case, dict(self.body_slices)
        # the field bases are on the model's own coordinates: the frames are mapped back to them (self.physical)
        vertex = ReducedVertexFields(self.built_model, self.comm, self.case.output.derived)
        vertex.prepare()
        series = FieldSeriesExport(Path(out_dir) / "transient_fields.xdmf", vertex,
                                   lambda: self.physical(self.q), frame_schedule(self.case),
                                   bodies=lambda size: BodyMeshes(case.transient, case.geometry.model, slices, size),
                                   resume_from_s=resume_from_s,
                                   sites=self._site_cloud() if case.output.contact_pressure else None)
        if series.engine_can_take:
            # the kernel takes the frames at its steps (the loop's rule, app/reduced/kernel.py Frames): no stop of
            # the compiled loop per frame (BENCHMARKS.md, "Field output of a modal run")
            n, m = self.q.size, self.z.size
            self.frames = lk.Frames(np.zeros(0), series.due_s, series.after_s, np.zeros(2, np.int64),
                                    np.zeros(FRAMES_PER_CALL), np.zeros((FRAMES_PER_CALL, n)),
                                    np.zeros((FRAMES_PER_CALL, m)))
            self._frame_series = series
            series.engine_frames = self.taken_frames
        return series

    def _site_cloud(self):
        """``output.contact_pressure``: the surface contacts' sites as the field series' point cloud companion
        (app.transient.fields.ContactSiteCloud), their pressure the law's at the current (end-of-step) state."""
        from app.transient.fields import ContactSiteCloud

        sites, model = self.sites_record, self.model
        names = self._kernel_contact_names()
        chosen = np.flatnonzero(self.contacts_record.kind[sites.contact] == lk.SURFACE)
        return ContactSiteCloud(points=np.asarray(model.site_points)[chosen], area_m2=sites.weight[chosen],
                                contact=sites.contact[chosen], names=names,
                                state=lambda: self._site_pressures(chosen) if self.comm.rank == 0 else None)

    def _site_pressures(self, chosen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The displacement [m] (n, 3) and the normal contact pressure [Pa] (n,) of the sites ``chosen`` at the
        current state: the kernel's law (app.contact.law.site_force) at the end-of-step coordinates and rates, as
        the FE tier's ContactPressureProbe takes its state (with Newmark the state the step's equilibrium used;
        with generalized-alpha the step used its mid-point)."""
        sites, gdim = self.sites_record, self.model.gdim
        y = (sites.rows @ self.q).reshape(-1, gdim)
        rate = (sites.rows @ self.v).reshape(-1, gdim)
        work = lk.site_work(self.bodies_record.mass.size)
        displacement = np.zeros((chosen.size, 3))
        pressure = np.zeros(chosen.size)
        y3, rate3 = np.zeros(3), np.zeros(3)
        for j, i in enumerate(chosen):
            y3[:gdim], rate3[:gdim] = y[i], rate[i]
            fn = lk.site_force(int(i), y3, rate3, self.z, self.zd, sites, self.contacts_record, self.bodies_record,
                               1.0, 1.0, False, work)[0]
            pressure[j] = fn / sites.weight[i]
            displacement[j, :gdim] = y[i]
        return displacement, pressure

    def body_positions(self) -> np.ndarray:
        return self.z

    def results(self) -> dict:
        model, cfg = self.model, self.cfg
        out = {"newton_iterations": int(self.istate[lk.I_NEWTON]), "attempts": int(self.istate[lk.I_ATTEMPTS]),
               "cutbacks": int(self.istate[lk.I_CUTBACKS]), "event_refinements": int(self.istate[lk.I_REFINEMENTS]),
               "drive_voltage_V": self.scale_V, "drive_frequency_Hz": cfg.drive.frequency_Hz,
               "initial_state": cfg.initial_state, "warm_start": self.warm_start,
               "stepping_wall_time_s": self._loop_wall,
               **({"drive": self.drive_lock} if self.drive_lock is not None else {}),
               **({"surgery": self.surgery} if self.surgery is not None else {}),
               "reduction": {"interface_dofs": model.n_interface, "electrodes": list(self.electrodes),
                             "inputs": list(model.inputs),
                             "modes": int(model.mode_frequencies_Hz.size), "size": model.size,
                             "highest_mode_Hz": float(model.mode_frequencies_Hz.max(initial=0.0)),
                             "enrichment_modes_Hz": model.enrichment_frequencies_Hz.tolist(),
                             "resonances_near_drive_Hz": model.resonances_Hz(cfg.drive.frequency_Hz).tolist(),
                             "contact_sites": int(self.sites_record.contact.size),
                             "free_modes": self.free_modes is not None,
                             "band_area_m2": np.asarray(model.band_area_m2, float).tolist(),
                             "fe_dofs": model.fe_dofs, "build_wall_s": model.reduction_wall_s,
                             "from_cache": self.from_cache, "from_checkpoint": self.from_cache is None,
                             "setup_wall_s": self.setup_wall_s,
                             "kernel_load_wall_s": self.compile_wall_s}}
        self.log(f"modal tier: {self.steps} steps, {out['newton_iterations']} Newton iterations, "
                 f"{out['cutbacks']} cut-backs, {self._loop_wall:.2f} s in the compiled loop")
        return out

    def statistics(self, h5_path: Path) -> tuple[dict, dict]:
        from app.transient.impacts import statistics_from_file

        return statistics_from_file(h5_path, self.case)

    def close(self) -> None:
        pass


class ReducedVertexFields:
    """The field output's vertex values from the reduced model's vertex basis (app/exports.py VertexFields'
    interface): displacement [m] and potential [V] at the mesh vertices = V q, on rank 0; ``expand`` forms a
    batch of frames at once (app/transient/fields.py writes the modal tier's frames through it).

    Every field is linear in q, so each basis vector's fields are laid out once, transposed (coordinates x
    values: a batch's product is frames x values, each frame's values contiguous): the vertex values, and of
    the region-wise averaged derived values (app.fe.derived.RegionAveraging) only the columns the derived fields
    and the peaks need (app.fe.derived.raw_columns; 9 of 18 for the default fields), component by component,
    their (region, vertex) pairs ordered by region so each region's peaks read a slice. Components that are
    zero for every basis vector (a model of revolution's u_theta, the potential of its metal parts, its shears
    yz and xy, its E_theta: a third of the product) are not formed; the expansion writes zeros for them and its
    invariants (von Mises, principal stresses: app.fe.derived.principal_of_parts, |E|) take them as 0.0."""

    def __init__(self, model: ReducedModel, comm, derived=()):
        self.comm = comm
        self.model = model
        # derived fields by expansion (app.fe.derived), when the model carries their basis
        self.derived = tuple(derived) if model.derived_basis.size else ()
        self.regions = [_RegionRow(int(tag), name, piezo == "1")
                        for tag, name, piezo in (row.split("|") for row in model.region_table)]
        self.region_names = {r.tag: r.name for r in self.regions}
        self.mesh_arrays = {"geometry": model.mesh_geometry, "topology": model.mesh_topology,
                            "region": model.mesh_region}
        self.topology_type = model.mesh_topology_type
        self.n_nodes = model.mesh_geometry.shape[0]
        self.n_cells = model.mesh_topology.shape[0]
        self.averaging = None
        if self.derived and comm.rank == 0:
            from app.fe.derived import RegionAveraging

            self.averaging = RegionAveraging(model.mesh_topology, model.mesh_region, self.n_nodes,
                                             [r.tag for r in self.regions if r.piezoelectric])
        self._vertex_T = None         # the per-basis-vector layouts (rank 0): at the first expand

    def _layouts(self) -> None:
        from app.fe.derived import RAW_COLUMNS, raw_columns

        model = self.model
        # components zero at every vertex for every basis vector (a model of revolution's u_theta) are not formed:
        # the product covers the others and the expansion puts zeros
        rows = np.flatnonzero(np.any(model.vertex_basis != 0, axis=1))
        self._vertex_rows = None if rows.size == model.vertex_basis.shape[0] else rows
        self._vertex_T = np.ascontiguousarray(model.vertex_basis[rows].T)
        if not self.derived:
            return
        indices, self._columns = raw_columns(self.derived, any(r.piezoelectric for r in self.regions))
        a = self.averaging
        order = np.argsort(a.pair_region, kind="stable")          # the pairs by region
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        self._pair_region = a.pair_region[order]
        self._vertex_pair = rank[a.vertex_pair]
        basis = model.derived_basis.reshape(a.size, RAW_COLUMNS, -1)[order[:, None], indices[None, :]]
        # component by component (each component of a frame contiguous over the pairs), without the components
        # zero everywhere (a plane or axisymmetric model's out-of-plane shears and E): None in _formed_of
        basis = basis.transpose(1, 0, 2)
        formed = [j for j in range(basis.shape[0]) if np.any(basis[j])]
        self._formed_of = [formed.index(j) if j in formed else None for j in range(basis.shape[0])]
        self._derived_T = np.ascontiguousarray(basis[formed].reshape(-1, basis.shape[-1]).T)

    def prepare(self) -> None:
        """Lay out the per-basis-vector fields now (set-up) instead of at the first batch (rank 0)."""
        if self.comm.rank == 0 and self._vertex_T is None:
            self._layouts()

    def sample(self, q: np.ndarray):
        if self.comm.rank != 0:
            return None
        values = self.model.vertex_basis @ q
        n = self.n_nodes
        return values[:3 * n].reshape(n, 3), values[3 * n:]

    def expand(self, q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, dict, dict | None]]:
        """The frames of the coordinates ``q`` (size, frames) on rank 0: [(displacement (n, 3) [m], potential (n,)
        [V], derived vertex fields, peaks per region or None)], one per column. One product of the vertex basis
        (and of the derived basis) with all the columns: the basis is read once per batch, not once per frame;
        the invariants (von Mises, principal stresses, |E|) of all the frames at once, component by component."""
        from app.fe.derived import fields_of, frame_region_peaks, principal_of_parts, von_mises_of_parts

        if self._vertex_T is None:
            self._layouts()
        q = np.asarray(q, dtype=float).reshape(self.model.vertex_basis.shape[1], -1)
        n, frames = self.n_nodes, q.shape[1]
        q = np.ascontiguousarray(q.T)                 # (frames, coordinates)
        values = q @ self._vertex_T                   # (frames, 3 n + n): displacement, then potential
        if self._vertex_rows is not None:
            values, formed = np.zeros((frames, 4 * n)), values
            values[:, self._vertex_rows] = formed
        fields: list[dict] = [{} for _ in range(frames)]
        peaks: list = [None] * frames
        if self.derived:
            # every frame's region-wise averaged values, component by component ((frames, pairs) each, 0.0 for
            # one zero everywhere); the invariants at every pair, then at the vertices and the peaks per region
            n_pairs = self._pair_region.size
            formed = (q @ self._derived_T).reshape(frames, -1, n_pairs)
            parts = [0.0 if j is None else formed[:, j] for j in self._formed_of]
            columns = self._columns
            stress = parts[columns["stress"]]
            piezoelectric = any(r.piezoelectric for r in self.regions)
            known = {"von_mises_Pa": von_mises_of_parts(stress)}
            principal = None
            if piezoelectric or "principal_stress" in self.derived:
                principal = principal_of_parts(stress)
                known["max_principal_stress_Pa"] = principal[0]
            if piezoelectric:
                E = parts[columns["electric_field"]]
                known["electric_field_V_per_m"] = np.sqrt(E[0] * E[0] + E[1] * E[1] + E[2] * E[2])
            at_vertices = fields_of(self.derived, lambda name: self._at_vertices(parts[columns[name]], frames),
                                    lambda: known["von_mises_Pa"][:, self._vertex_pair],
                                    lambda: self._at_vertices(principal, frames))
            fields = [{key: v[k] for key, v in at_vertices.items()} for k in range(frames)]
            peaks = frame_region_peaks(None, self._pair_region, self.regions, known=known)
        return [(values[k, :3 * n].reshape(n, 3), values[k, 3 * n:], fields[k], peaks[k]) for k in range(frames)]

    def _at_vertices(self, components, frames: int) -> np.ndarray:
        """(frames, vertices, components) of (frames, pairs) components (0.0: zero everywhere) at the pairs."""
        out = np.zeros((frames, self.n_nodes, len(components)))
        for i, c in enumerate(components):
            if np.ndim(c):
                out[:, :, i] = c[:, self._vertex_pair]
        return out

    def derived_frame(self, q: np.ndarray):
        """(derived vertex fields, peaks per region) of the frame (rank 0; (None, None) elsewhere): the basis's
        region-wise averaged vertex values combined with q, as the FE tier's (app.exports.VertexFields)."""
        from app.fe.derived import RAW_COLUMNS, node_fields, region_peaks

        if self.comm.rank != 0:
            return None, None
        pairs = (self.model.derived_basis @ q).reshape(self.averaging.size, RAW_COLUMNS)
        return (node_fields(self.averaging.at_vertices(pairs), self.derived),
                region_peaks(pairs, self.averaging.pair_region, self.regions))


@dataclass(frozen=True)
class _RegionRow:
    """A region as app.fe.derived.region_peaks reads it: tag, name, and ``e`` not None when piezoelectric."""

    tag: int
    name: str
    piezoelectric: bool

    @property
    def e(self):
        return True if self.piezoelectric else None

