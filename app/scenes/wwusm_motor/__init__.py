"""The travelling-wave ultrasonic motor (``scene = "wwusm-motor"``): a stator driving a rotor by friction.

Its operating point, computed from the time series of any tier that runs the case (FE or modal), so both report
it under the same keys (``statistics.motor``): over the steady window (the last ``steady_state.window_cycles``
drive periods), the rotor's speed, the friction torque and the load, the electrical input (from the driven
electrodes' voltages and charges), output and shaft power, efficiency, the losses (friction, structural
damping) and the energy balance, the normal and axial forces against the closed form, the rotor's axial
offset and vibration, the fractions of the contact that separate, stick and slip either way (from the
per-site tables), the contact point's path and the pressure round the ring (``motor_ring.csv``,
``motor_contact_path.csv`` and their plots), the speed against time with the window marked.

Why the drive sits where it does (docs/motor-rotor.md, "Diagnostics of the contact"): the contact in the wave's
frame, the pressure, contact, stick and forward / backward slip fractions and the slip speed's circumferential
(e1) and meridional (e2) parts against the wave's phase (0: the crest, positive ahead of it), per ring across the
band (``motor_wave_frame.csv`` and its plot, from the ``wave_frame`` table of app/contact/tables.py); in
``statistics.motor`` and the table, the contact's centre against the crest (``contact_centre_from_crest_deg``,
from the sites' first harmonics of pressure and normal displacement), the slip speeds' parts while slipping and
the meridional share of the friction power.

The case needs ``output.energies`` (charges and energies) and, for the ring and the fractions,
``output.contact_sites``; one rotor with one rotation and a surface contact on it.

In the lumped tier (``[lumped]`` with ``model = "friction_drive"``, app/lumped/friction_drive.py) there is no time
series: the tier solves for the steady operating point and already reports it in these keys
(``results.operating_point``); the scene takes it as ``statistics.motor`` and writes the speed-torque curves of
both branches (``motor_speed_torque.csv``, ``motor_speed_torque.png``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from app import series as S
from app.contact.tables import contact_centre_rad
from app.errors import CaseError
from app.scenes.registry import SceneReport, register

DEFAULT_WINDOW = 20


def _rotor(case):
    """(the rotor body section, its contact section) of a motor case."""
    cfg = case.transient
    if cfg.steady_state is not None:
        rotor = next(b for b in cfg.bodies if b.name == cfg.steady_state.body)
    else:
        rotor = next((b for b in cfg.bodies if b.rotations), None)
    contact = next((c for c in cfg.contacts if c.kind == "surface" and rotor is not None and c.body == rotor.name),
                   None)
    return rotor, contact


def _window(t: np.ndarray, period: float, cycles: int) -> np.ndarray:
    """Rows of the last ``cycles`` whole drive periods (the steady window)."""
    end = math.floor(t[-1] / period + 1e-9) * period
    start = max(end - cycles * period, 0.0)
    return (t > start * (1 + 1e-12)) & (t <= end * (1 + 1e-12))


def _integral(t, y):
    """Trapezoidal integral of y over t."""
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


class WedgeWaveMotor(SceneReport):
    name = "wwusm-motor"
    sweep_columns = ("statistics.motor.speed_rpm", "statistics.motor.output_power_W", "statistics.motor.efficiency",
                     "statistics.motor.friction_torque_N_m", "statistics.motor.normal_force_N")

    def check(self, case) -> None:
        file = case.source
        if case.tier == "lumped":
            if case.lumped.model != "friction_drive":
                raise CaseError(file, "lumped.model", "the motor's lumped model is 'friction_drive' (the stator's wave "
                                                      f"mode and the friction-drive law), not {case.lumped.model!r}")
            return
        if case.transient is None:
            raise CaseError(file, "transient", "the motor scene runs a transient in the fe or modal tier, or the "
                                               "lumped tier's friction_drive model")
        rotor, contact = _rotor(case)
        if rotor is None or len(rotor.rotations) < 1:
            raise CaseError(file, "transient.bodies", "the motor needs a rotor: a body with a rotation")
        if contact is None:
            raise CaseError(file, "transient.contacts",
                            f"the motor needs a surface contact on its rotor {rotor.name!r}")
        if not case.output.energies:
            raise CaseError(file, "output.energies", "the motor's powers and efficiency need the charges and "
                                                     "energies: set it to true")

    def steady_floors(self, case) -> tuple[float, float]:
        if case.transient is None:
            return 0.0, 0.0
        """A change below 2 % of the speed a 1 um tangential wave gives the rotor (free), or of the Coulomb
        bound mu_s N r_c (held): noise near standstill, not a drift."""
        rotor, contact = _rotor(case)
        omega = 2 * math.pi * case.transient.drive.frequency_Hz
        radius = contact.radius_m or 0.01
        speed_floor = 0.02 * omega * 1e-6 / radius
        preload = abs(float((rotor.applied_force_N or [0.0])[-1]))
        friction = contact.friction
        mu_s = friction.mu_dynamic * friction.static_ratio if friction is not None else 0.0
        sin_a = math.sin(math.radians(contact.half_angle_deg)) if contact.shape == "cone" else 1.0
        return speed_floor, 0.02 * mu_s * preload / sin_a * radius

    # ------------------------------------------------------------------ the operating point
    def statistics(self, data: dict, case, results: dict) -> dict:
        if case.tier == "lumped":       # a steady solve: the operating point in the motor's keys already
            point = results.get("operating_point")
            return {"motor": point} if point else {}
        cfg = case.transient
        rotor, contact = _rotor(case)
        t = data.get(S.TIME)
        period = 1.0 / cfg.drive.frequency_Hz
        if t is None or t.size < 2 or t[-1] < period:
            return {}
        cycles = cfg.steady_state.window_cycles if cfg.steady_state is not None else DEFAULT_WINDOW
        window = _window(t, period, cycles)
        first = int(np.argmax(window))
        rows = np.nonzero(window)[0]
        idx = np.r_[first - 1, rows] if first > 0 else rows       # the row that ends the period before the window
        tw = t[idx]
        duration = float(tw[-1] - tw[0])
        rotation = rotor.rotations[0]
        free = rotation.motion == "free"
        speed_all = data[S.body_angular_velocity(rotor.name)][:, 0]
        torque_all = data[S.contact_torque(contact.name)][:, 0]
        speed = _integral(tw, speed_all[idx]) / duration
        torque = _integral(tw, torque_all[idx]) / duration
        applied = rotation.torque_N_m - rotation.brake_N_m_s_per_rad * speed_all[idx]
        # electrical input: sum over the driven electrodes of the integral of V dQ
        electrodes = [n for n, e in case.electrodes.items() if e.kind == "voltage"]
        e_el = 0.0
        for name in electrodes:
            volts = data[S.electrode_voltage(name)] if S.electrode_voltage(name) in data else data[S.DRIVE]
            charge = data[S.electrode_charge(name)]
            v, q = volts[idx].reshape(-1), charge[idx].reshape(-1)
            e_el += float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(q)))
        p_el = e_el / duration
        if free:       # the output is the work against the load torque and the brake
            p_out = -_integral(tw, applied * speed_all[idx]) / duration
        else:          # a prescribed or held spin: the constraint takes the contact torque's work
            p_out = torque * speed
        dissipated = data[S.contact_dissipated(contact.name)][idx]
        friction_J = float(dissipated[-1] - dissipated[0])
        damping_J = float(data["damping_dissipated_J"][idx][-1] - data["damping_dissipated_J"][idx][0])
        stored = sum(data[k][idx] for k in ("kinetic_energy_J", "strain_energy_J", "rigid_kinetic_energy_J",
                                            "contact_energy_J"))
        force = np.asarray(rotor.applied_force_N or [0.0] * len(rotor.position_m), dtype=float)
        z = data[S.body_position(rotor.name)]
        gravity = np.asarray(cfg.loads.gravity_m_per_s2 or [0.0] * z.shape[1], dtype=float)
        load_work = float((force + rotor.mass_kg * gravity) @ (z[idx][-1] - z[idx][0]))
        stored_change = float(stored[-1] - stored[0]) - load_work
        balance = e_el - (damping_J + friction_J + p_out * duration + stored_change)
        normal = _integral(tw, data[S.contact_normal_force(contact.name)][idx]) / duration
        axis = {"x": 0, "y": 1, "z": 2, "plane": 1}[rotation.axis]        # the rotor translates along its axis
        axial = _integral(tw, data[S.contact_force(contact.name)][idx][:, axis]) / duration
        preload = -float(force[axis])
        sin_a = math.sin(math.radians(contact.half_angle_deg)) if contact.shape == "cone" else 1.0
        friction = contact.friction
        mu_s = friction.mu_dynamic * friction.static_ratio if friction is not None else 0.0
        mu_k = friction.mu_dynamic if friction is not None else 0.0
        offset = z[idx][:, axis] - rotor.position_m[axis]
        point = {
            "speed_rad_per_s": speed, "speed_rpm": speed * 60.0 / (2 * math.pi),
            "speed_change_over_window_rad_per_s": float(np.ptp(speed_all[idx])),
            "load_torque_N_m": 0.0 - float(np.mean(applied)), "friction_torque_N_m": torque,
            "output_power_W": p_out, "shaft_power_W": torque * speed, "electrical_power_W": p_el,
            "efficiency": p_out / p_el if p_el > 0 else 0.0,
            "friction_loss_W": friction_J / duration, "damping_loss_W": damping_J / duration,
            "stored_energy_change_J": stored_change,
            "energy_balance_relative": balance / e_el if e_el else 0.0,
            "window_s": duration, "window_periods": int(round(duration / period)),
            "normal_force_N": normal, "normal_force_closed_form_N": preload / sin_a,
            "axial_force_N": axial, "contact_radius_m": float(contact.radius_m or 0.0),
            "coulomb_torque_bound_N_m": mu_s * preload / sin_a * float(contact.radius_m or 0.0),
            "kinetic_friction_torque_N_m": mu_k * preload / sin_a * float(contact.radius_m or 0.0),
            "rotor_axial_offset_m": float(np.mean(offset)), "rotor_axial_vibration_m": float(np.ptp(offset)),
        }
        point.update(self._sites(data, contact.name, tw[0], tw[-1], free, speed, torque))
        probe = S.contact_probe(contact.name)
        if probe in data:
            last = (t > t[-1] - period * (1 + 1e-9))
            path = data[probe][last]
            point["contact_point_amplitude_m"] = {"normal": float(np.ptp(path[:, 0]) / 2),
                                                  "tangential": float(np.ptp(path[:, 1]) / 2),
                                                  "meridional": float(np.ptp(path[:, 2]) / 2)}
        return {"motor": point}

    @staticmethod
    def _sites(data, contact: str, start: float, end: float, free: bool, speed: float, torque: float) -> dict:
        """Fractions of the contact that separate, stick and slip forward or backward over the window, from the
        per-site tables (forward: the stator slipping ahead of the rotor in the direction the wave drives it)."""
        times = data.get(S.sites_table(contact, "time"))
        if times is None or not len(times):
            return {}
        rows = (times[:, 0] >= start * (1 - 1e-9)) & (times[:, 1] <= end * (1 + 1e-9))
        if not rows.any():
            rows = np.zeros(len(times), bool)
            rows[-1] = True
        closed = data[S.sites_table(contact, "closed")][rows].mean()
        stick = data[S.sites_table(contact, "stick")][rows].mean()
        positive = data[S.sites_table(contact, "slip_positive")][rows].mean()
        negative = data[S.sites_table(contact, "slip_negative")][rows].mean()
        drive = np.sign(speed) if free and speed else (np.sign(torque) or 1.0)
        forward, backward = (positive, negative) if drive > 0 else (negative, positive)
        n_sites = data[S.sites_table(contact, "closed")].shape[1]
        out = {"fractions": {"separation": float(1 - closed), "stick": float(stick), "forward_slip": float(forward),
                             "backward_slip": float(backward)},
               "points_in_contact_mean": float(closed * n_sites), "contact_points": int(n_sites),
               "forward_slip_direction_e1": float(drive)}
        out.update(WedgeWaveMotor._contact_diagnostics(data, contact, rows))
        return out

    @staticmethod
    def _contact_diagnostics(data, contact: str, rows: np.ndarray) -> dict:
        """Why the drive sits where it does (docs/motor-rotor.md, "Diagnostics of the contact"), from the per-site
        tables over the window's rows: the contact's centre against the wave's crest (the pressure-weighted mean
        wave phase from the sites' first harmonics, app/contact/tables.py), the slip speed's circumferential (e1)
        and meridional (e2) parts while slipping, and the meridional share of the friction power."""
        def table(key):
            return data[S.sites_table(contact, key)][rows]

        if S.sites_table(contact, "pressure_cos") not in data:      # a series written before these diagnostics
            return {}
        area = data[S.sites_table(contact, "geometry")][:, 3]
        centre = contact_centre_rad(area, table("pressure_cos"), table("pressure_sin"),
                                    table("normal_displacement_cos"), table("normal_displacement_sin"))
        slipping = float(area @ (table("slip_positive") + table("slip_negative")).mean(axis=0))
        power_e1 = float(area @ table("friction_power_e1").mean(axis=0))
        power_e2 = float(area @ table("friction_power_e2").mean(axis=0))

        def while_slipping(key):
            return float(area @ table(key).mean(axis=0)) / slipping if slipping > 0 else 0.0

        return {"contact_centre_from_crest_deg": math.degrees(centre) if math.isfinite(centre) else None,
                "slip_speed_circumferential_m_per_s": while_slipping("slip_speed_e1"),
                "slip_speed_meridional_m_per_s": while_slipping("slip_speed_e2"),
                "slip_speed_m_per_s": while_slipping("slip_speed"),
                "friction_power_circumferential_W": power_e1, "friction_power_meridional_W": power_e2,
                "meridional_slip_power_share": power_e2 / (power_e1 + power_e2) if power_e1 + power_e2 > 0 else 0.0}

    # ------------------------------------------------------------------ tables, CSVs, plots
    def table_rows(self, results: dict) -> list[tuple[str, str, str]]:
        p = (results.get("statistics") or {}).get("motor")
        if not p:
            return []
        rows = [("rotor speed", f"{p['speed_rpm']:.4g}", "rpm"),
                ("rotor speed", f"{p['speed_rad_per_s']:.4g}", "rad/s"),
                ("load torque", f"{p['load_torque_N_m'] * 1e3 + 0.0:.4g}", "mN m"),
                ("friction torque", f"{p['friction_torque_N_m'] * 1e3:.4g}", "mN m"),
                ("Coulomb bound mu_s N r_c", f"{p['coulomb_torque_bound_N_m'] * 1e3:.4g}", "mN m"),
                ("normal force N", f"{p['normal_force_N']:.4g}", "N"),
                ("normal force P / sin(alpha)", f"{p['normal_force_closed_form_N']:.4g}", "N"),
                ("output power", f"{p['output_power_W'] * 1e3:.4g}", "mW"),
                ("electrical power", f"{p['electrical_power_W'] * 1e3:.4g}", "mW"),
                ("efficiency", f"{100 * p['efficiency']:.3g}", "%"),
                ("friction loss", f"{p['friction_loss_W'] * 1e3:.4g}", "mW"),
                ("damping loss", f"{p['damping_loss_W'] * 1e3:.4g}", "mW"),
                ("energy balance (relative)", f"{p['energy_balance_relative']:.2e}", "1")]
        if "window_periods" in p:
            rows.append(("steady window", f"{p['window_periods']}", "periods"))
        if "wave_amplitude_m" in p:      # the lumped tier's steady solve
            rows += [("wave normal amplitude at the contact", f"{p['wave_amplitude_m'] * 1e6:.4g}", "um"),
                     ("contact half-angle theta_c", f"{p['contact_half_angle_rad']:.4g}", "rad"),
                     ("rotor speed / crest surface speed", f"{p['speed_over_surface_speed']:.5g}", "1")]
        f = p.get("fractions")
        if f:
            rows += [("contact separated", f"{100 * f['separation']:.3g}", "%"),
                     ("contact sticking", f"{100 * f['stick']:.3g}", "%"),
                     ("contact slipping forward", f"{100 * f['forward_slip']:.3g}", "%"),
                     ("contact slipping backward", f"{100 * f['backward_slip']:.3g}", "%")]
        if p.get("contact_centre_from_crest_deg") is not None:
            rows.append(("contact centre from the crest (+: ahead)", f"{p['contact_centre_from_crest_deg']:.3g}",
                         "deg of wave"))
        if "slip_speed_circumferential_m_per_s" in p:
            rows += [("slip speed circumferential (slipping)", f"{p['slip_speed_circumferential_m_per_s'] * 1e3:.4g}",
                      "mm/s"),
                     ("slip speed meridional (slipping)", f"{p['slip_speed_meridional_m_per_s'] * 1e3:.4g}", "mm/s"),
                     ("meridional share of the friction power", f"{100 * p['meridional_slip_power_share']:.3g}", "%")]
        return rows

    def outputs(self, results: dict, out_dir: Path, title: str, plots: bool = True) -> list[str]:
        from app.scenes.wwusm_motor.outputs import write_curves, write_outputs

        if results.get("curves") is not None:
            return write_curves(results, Path(out_dir), title, plots)
        return write_outputs(results, Path(out_dir), title, plots)


SCENE = register(WedgeWaveMotor())
