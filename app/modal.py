"""Modal analysis: SLEPc shift-invert around a target frequency for the short-circuit (driven
electrodes grounded: resonance f_r) and open-circuit (driven electrodes floating: antiresonance
f_a) states; effective coupling k_eff^2 = (f_a^2 - f_r^2) / f_a^2 from MAC-paired modes."""

from __future__ import annotations

import math
from dataclasses import dataclass

from petsc4py import PETSc

from app.errors import NumericalFailure
from app.fe.constraints import ConstraintSet
from app.fe.eigen import shift_invert_solver
from app.fe.model import FEModel
from app.fe.operators import Operators, electrical_state


@dataclass
class Mode:
    frequency_Hz: float
    vector: PETSc.Vec  # full u-phi numbering, mass-normalised: x^T M x = 1 [1/sqrt(kg)]


def solve_modes(ops: Operators, constraints: ConstraintSet, target_Hz: float, n_modes: int,
                rigid_cutoff_Hz: float, prefix: str) -> list[Mode]:
    """Eigenpairs K x = omega^2 M x nearest ``target_Hz`` (rigid-body modes below the cutoff dropped)."""
    comm = ops.K.getComm()
    K = constraints.reduce(ops.K)
    M = constraints.reduce(ops.M)
    constraints.apply(K, 1.0)
    constraints.apply(M, 0.0)
    eps = shift_invert_solver(comm, K, M, n_modes, target_Hz, prefix)
    eps.solve()
    modes = converged_modes(eps, ops.M, constraints, target_Hz, n_modes, rigid_cutoff_Hz, prefix)
    for obj in (eps, K, M):
        obj.destroy()
    return modes


def converged_modes(eps, M_full: PETSc.Mat, constraints: ConstraintSet, target_Hz: float, n_modes: int,
                    rigid_cutoff_Hz: float, prefix: str) -> list[Mode]:
    """The ``n_modes`` converged pairs of a solved ``eps`` nearest ``target_Hz`` (rigid-body modes below the cutoff
    dropped), expanded to the full numbering and mass-normalised with ``M_full``, ascending in frequency."""
    n_conv = eps.getConverged()
    if n_conv == 0:
        raise NumericalFailure(f"eigensolver ({prefix}) found no eigenpair near {target_Hz} Hz "
                               f"(tried Krylov-Schur shift-invert with MUMPS LU)")
    modes = []
    K, _ = eps.getOperators()
    y = K.createVecRight()
    Mx = M_full.createVecLeft()
    for i in range(n_conv):
        lam = eps.getEigenpair(i, y).real
        if lam <= (2 * math.pi * rigid_cutoff_Hz) ** 2:
            continue
        x = M_full.createVecRight()
        constraints.expand(y, x)
        M_full.mult(x, Mx)
        x.scale(1.0 / math.sqrt(abs(x.dot(Mx))))
        modes.append(Mode(math.sqrt(lam) / (2 * math.pi), x))
    for obj in (y, Mx):
        obj.destroy()
    # SLEPc may converge more pairs than asked for, depending on the partition: keep the n nearest
    modes.sort(key=lambda m: abs(m.frequency_Hz - target_Hz))
    for extra in modes[n_modes:]:
        extra.vector.destroy()
    modes = sorted(modes[:n_modes], key=lambda m: m.frequency_Hz)
    return modes


def mac(M: PETSc.Mat, a: PETSc.Vec, b: PETSc.Vec) -> float:
    """Mass-weighted modal assurance criterion of two mass-normalised modes."""
    Mb = M.createVecLeft()
    M.mult(b, Mb)
    value = a.dot(Mb) ** 2
    Mb.destroy()
    return value


@dataclass
class ModalResult:
    short: list[Mode]
    open: list[Mode]
    pairs: list[tuple[int, int | None, float | None]]  # (short index, open index, k_eff)
    working: int  # index into short
    orders: list | None = None  # app.modeid.ModeOrder per short mode, when the case asks
    contact_force: dict | None = None  # modal.contact_force's measures (contact_force())

    @property
    def working_mode(self) -> Mode:
        return self.short[self.working]

    def antiresonance_Hz(self) -> float | None:
        _, j, _ = self.pairs[self.working]
        return None if j is None else self.open[j].frequency_Hz


def resonances_near(model: FEModel, near_Hz: float, count: int) -> list[float]:
    """The FE model's ``count`` natural frequencies nearest ``near_Hz`` with its electrodes short-circuited (as a
    driven transient holds them) [Hz], ascending: the resonance a drive locked to it follows (app/drive.py
    locked_case). Assembles K and M and solves on its own (collective)."""
    from app.fe.operators import assemble_operators

    ops = assemble_operators(model)
    try:
        modes = solve_modes(ops, electrical_state(model, "short"), near_Hz, count, 0.0, prefix="drive_lock_")
    finally:
        ops.destroy()
    if len(modes) < count:
        raise NumericalFailure(f"drive lock: {len(modes)} of {count} natural frequencies found near {near_Hz:.0f} Hz")
    out = sorted(m.frequency_Hz for m in modes[:count])
    for mode in modes:
        mode.vector.destroy()
    return out


def run_modal(model: FEModel, ops: Operators) -> ModalResult:
    cfg = model.case.modal
    if cfg.cyclic is not None:
        from app.fe.cyclic import cyclic_modes

        modes = [Mode(f, x) for f, x in cyclic_modes(model, ops, cfg.cyclic, cfg.target_frequency_Hz, cfg.n_modes,
                                                     cfg.rigid_cutoff_Hz)]
        working = min(range(len(modes)), key=lambda i: abs(modes[i].frequency_Hz - cfg.target_frequency_Hz))
        return ModalResult(modes, [], [(i, None, None) for i in range(len(modes))], working)
    has_drive = bool(model.electrodes_of("voltage"))
    states = {"short": ["short"], "open": ["open"], "both": ["short", "open"]}[cfg.electrical]
    if not has_drive:
        states = ["short"]
    found = {}
    for state in states:
        found[state] = solve_modes(ops, electrical_state(model, state), cfg.target_frequency_Hz, cfg.n_modes,
                                   cfg.rigid_cutoff_Hz, prefix=f"modal_{state}_")
    short = found.get("short") or found.get("open")
    opened = found.get("open", []) if "short" in found else []
    pairs = []
    for i, mode in enumerate(short):
        best, best_mac = None, 0.0
        for j, other in enumerate(opened):
            value = mac(ops.M, mode.vector, other.vector)
            if value > best_mac:
                best, best_mac = j, value
        if best is not None and best_mac > 0.5:
            fa, fr = opened[best].frequency_Hz, mode.frequency_Hz
            k_eff = math.sqrt(max(fa * fa - fr * fr, 0.0)) / fa
            pairs.append((i, best, k_eff))
        else:
            pairs.append((i, None, None))
    if not short:
        raise NumericalFailure("no elastic mode found above the rigid-body cutoff; raise modal.n_modes")
    orders = identify_modes(model, short) if cfg.identify is not None else None
    candidates = range(len(short))
    if orders is not None and cfg.identify.working_order is not None:
        m, n = cfg.identify.working_order
        candidates = [i for i in candidates if (orders[i].m, orders[i].n) == (m, n)]
        if not candidates:
            found_orders = ", ".join(f"({o.m},{o.n})" for o in orders)
            raise NumericalFailure(f"no mode of order (m, n) = ({m}, {n}) among the modes found ({found_orders}); "
                                   f"raise modal.n_modes or move modal.target_frequency_Hz")
    if cfg.working_mode == "coupling" and any(pairs[i][2] for i in candidates):
        working = max(candidates, key=lambda i: pairs[i][2] or 0.0)
    else:
        working = min(candidates, key=lambda i: abs(short[i].frequency_Hz - cfg.target_frequency_Hz))
    result = ModalResult(short, opened, pairs, working, orders)
    if cfg.contact_force is not None:
        result.contact_force = contact_force(model, ops, result)
    return result


def contact_force(model: FEModel, ops: Operators, result: ModalResult) -> dict:
    """The working mode's (and its degenerate partner's) modal force referred to a contact circle.

    For a short-circuit mode x (mass-normalised) let W_x be the amplitude of order n of its normal
    displacement w = u . n round the circle (w = W_x cos n(theta - theta_0) for a pure order): the modal
    mass and stiffness referred to the contact normal are m_m = 1 / W_x^2, k_m = omega^2 m_m. A drive of
    phasors V_e on electrodes e pushes the mode's coordinate with the generalised force f = sum_e Q_e(x) V_e,
    Q_e(x) the charge the mode shape carries on electrode e with every electrode grounded (by reciprocity the
    work of the drive on the mode: forms.piezo). Referred to the contact, that is a force F = |f| / W_x, and
    at resonance the mode answers with the normal amplitude W = F / (2 zeta k_m), zeta = x^T C x / (2 omega)
    its damping ratio: F_m = 2 zeta k_m W. For the two modes of a travelling wave F_m is the root mean square
    of the pair's two forces (equal in a clean wave), and W the wave's amplitude. Per volt: over the largest
    drive amplitude. ``two_mode_wave``: the wave the pair alone makes at its centre frequency under the case's
    drive (its min/max: the travelling-wave ratio without the other modes' share). The preloads' normal force
    N = P / |n_z| against F_m says whether the wave can carry the rotor on its crests (N / F_m of order 1 or
    below; docs/motor-stator.md)."""
    import numpy as np

    from app.errors import CaseError
    from app.fe.operators import charge, indicator
    from app.harmonic import drive_phasors
    from app.modeid import PointSet, circle_points, cylindrical, harmonics, normal_component

    cfg = model.case.modal.contact_force
    file = model.case.source
    if model.kind == "fourier":
        raise CaseError(file, "modal.contact_force", "needs a 3d model (a Fourier model's electrodes cannot carry "
                                                     "a drive of order n)")
    phasors = drive_phasors(model, cfg.voltage_V)
    if not phasors:
        raise CaseError(file, "modal.contact_force", "needs an electrode of kind 'voltage' (the drive)")
    points, theta = circle_points(cfg.circle_radius_m, cfg.circle_height_m, cfg.n_points)
    probe = PointSet(model.mesh, points)
    if not probe.found.all():
        raise CaseError(file, "modal.contact_force.circle_radius_m", "the circle leaves the mesh")
    modes = [result.working]
    partner = result.orders[result.working].partner if result.orders is not None else None
    if partner is not None:
        modes.append(partner)
    f_ref = model.case.damping.reference_frequency_Hz or result.working_mode.frequency_Hz
    damping = model.damping(f_ref)
    C = None
    if damping is not None:
        from dolfinx import fem
        from dolfinx.fem.petsc import assemble_matrix

        C = assemble_matrix(fem.form(damping), bcs=[])
        C.assemble()
    chi = {name: indicator(model, [name]) for name in phasors}
    rows, shapes, forces, omegas, zetas = [], [], [], [], []
    for index in modes:
        mode = result.short[index]
        omega = 2 * math.pi * mode.frequency_Hz
        w = normal_component(cylindrical(probe(model.displacement(mode.vector)), theta), tuple(cfg.normal_rz))
        amplitude = 2 * abs(harmonics(w)[cfg.order])           # W_x [m per unit modal coordinate]
        zeta = 0.0
        if C is not None:
            Cx = C.createVecLeft()
            C.mult(mode.vector, Cx)
            zeta = Cx.dot(mode.vector) / (2 * omega)
            Cx.destroy()
        q = {name: charge(ops.K, mode.vector, vec) for name, vec in chi.items()}
        f = sum(q[name] * phasors[name] for name in phasors)
        shapes.append(w)
        forces.append(f)
        omegas.append(omega)
        zetas.append(zeta)
        rows.append({"mode": index + 1, "frequency_Hz": mode.frequency_Hz, "modal_mass_kg": 1 / amplitude**2,
                     "modal_stiffness_N_per_m": omega**2 / amplitude**2, "damping_ratio": zeta,
                     "modal_force_N": abs(f) / amplitude,
                     "electrode_force_factor_N_per_V": {name: abs(q[name]) / amplitude for name in q}})
    for vec in chi.values():
        vec.destroy()
    if C is not None:
        C.destroy()
    volts = max(abs(v) for v in phasors.values())
    # the wave of the pair alone at its centre: each mode's response f / (omega_j^2 - omega^2 + 2 i zeta_j omega_j
    # omega) times its normal displacement round the circle
    omega_c = float(np.mean(omegas))
    wave = sum(f / (om**2 - omega_c**2 + 2j * z * om * omega_c) * w
               for f, om, z, w in zip(forces, omegas, zetas, shapes))
    amplitude = np.abs(wave)
    force = math.sqrt(sum(r["modal_force_N"] ** 2 for r in rows) / len(rows))
    k_m = sum(r["modal_stiffness_N_per_m"] for r in rows) / len(rows)
    zeta = sum(r["damping_ratio"] for r in rows) / len(rows)
    n_z = abs(cfg.normal_rz[1]) / math.hypot(*cfg.normal_rz)
    out = {"order": cfg.order, "circle_radius_m": cfg.circle_radius_m, "circle_height_m": cfg.circle_height_m,
           "modes": rows, "drive_amplitude_V": volts, "modal_force_N": force,
           "modal_force_per_volt_N_per_V": force / volts, "modal_stiffness_N_per_m": k_m, "damping_ratio": zeta,
           "free_normal_amplitude_m": force / (2 * zeta * k_m) if zeta > 0 else None,
           "two_mode_wave": {"frequency_Hz": omega_c / (2 * math.pi),
                             "travelling_wave_ratio": float(amplitude.min() / amplitude.max()),
                             "normal_amplitude_mean_m": float(amplitude.mean())},
           "preloads": [{"axial_preload_N": p, "normal_force_N": p / n_z,
                         "normal_force_over_modal_force": p / n_z / force} for p in cfg.preloads_N]}
    return out


def mode_identifier(model: FEModel):
    """The modal.identify sampler (app.modeid.ModeIdentifier, or FourierModeIdentifier for a Fourier model);
    CaseError if its circle or generatrix leaves the mesh (so ``validate`` refuses it without solving:
    app.runner.check_case). Collective."""
    from app.errors import CaseError
    from app.modeid import FourierModeIdentifier, ModeIdentifier

    try:
        if model.kind == "fourier":
            return FourierModeIdentifier(model.mesh, model.case.modal.identify, model.circumferential_order)
        return ModeIdentifier(model.mesh, model.case.modal.identify)
    except ValueError as exc:
        raise CaseError(model.case.source, f"modal.identify.{exc}_radius_m",
                        "the identification points do not all lie inside the mesh") from None


def identify_modes(model: FEModel, modes: list[Mode]) -> list:
    """Circumferential and axial orders and degenerate partners (app.modeid) of ``modes``."""
    from app.modeid import pair_partners

    identifier = mode_identifier(model)
    orders = [identifier.order(model.displacement(mode.vector)) for mode in modes]
    if model.kind != "fourier":
        pair_partners([m.frequency_Hz for m in modes], orders)
    return orders


def mode_table(result: ModalResult) -> list[dict]:
    """One row per short-circuit mode: index, f, (m, n, component, partner split), k_eff, f_a."""
    rows = []
    for i, j, k_eff in result.pairs:
        row = {"index": i, "frequency_Hz": result.short[i].frequency_Hz}
        if result.orders is not None:
            o = result.orders[i]
            row.update({"m": o.m, "n": o.n, "component": o.component, "order_energy_fraction": o.purity,
                        "partner_index": o.partner, "partner_split_Hz": o.split_Hz})
        if j is not None:
            row.update({"antiresonance_Hz": result.open[j].frequency_Hz, "k_eff": k_eff})
        rows.append(row)
    return rows


def modal_summary(model: FEModel, result: ModalResult) -> dict:
    """Plain results for summary.json (units in key names)."""
    modes = []
    for i, j, k_eff in result.pairs:
        mode = result.short[i]
        entry = {"mode": i + 1, "resonance_Hz": mode.frequency_Hz}
        if j is not None:
            entry["antiresonance_Hz"] = result.open[j].frequency_Hz
            entry["k_eff"] = k_eff
        for name, value in model.point_values(mode.vector).items():
            entry[f"modal_mass_at_{name}_kg"] = (1.0 / value**2) if abs(value) > 0 else None
        modes.append(entry)
    if result.orders is not None:
        for entry, row in zip(modes, mode_table(result)):
            entry.update({k: row[k] for k in ("m", "n", "component", "order_energy_fraction", "partner_split_Hz")})
            entry["partner_mode"] = None if row["partner_index"] is None else row["partner_index"] + 1
    # modes are numbered from 1 (modes.csv, the mode-shape XDMF, the log); working_mode_index is the position in
    # the list `modes`, from 0
    out = {"modes": modes, "working_mode": result.working + 1, "working_mode_index": result.working,
           "working_resonance_Hz": result.working_mode.frequency_Hz}
    if result.orders is not None:
        o = result.orders[result.working]
        out.update({"working_m": o.m, "working_n": o.n, "working_partner_split_Hz": o.split_Hz})
        if o.split_Hz is not None:
            out["working_partner_split_relative"] = abs(o.split_Hz) / result.working_mode.frequency_Hz
    if result.contact_force is not None:
        out["contact_force"] = result.contact_force
    fa = result.antiresonance_Hz()
    if fa is not None:
        out["working_antiresonance_Hz"] = fa
        out["working_k_eff"] = result.pairs[result.working][2]
    if result.open and not any(p[1] is not None for p in result.pairs):
        out["open_circuit_Hz"] = [m.frequency_Hz for m in result.open]
    return out


def mode_table_lines(rows: list[dict], working: int) -> list[str]:
    """Terminal lines of the mode table (m, n, f, partner split); modes numbered from 1 as in modes.csv."""
    lines = ["  #   f [Hz]        m   n  comp   partner split [Hz]"]
    for row in rows:
        split = row.get("partner_split_Hz")
        lines.append(f"{'*' if row['index'] == working else ' '}{row['index'] + 1:>2d}  {row['frequency_Hz']:>11.2f}"
                     f"  {row.get('m') if row.get('m') is not None else '-':>2}  {row.get('n', '-'):>2}"
                     f"  {row.get('component', '-'):>5}  {'' if split is None else f'{split:+.2f}':>12}")
    return lines


def contact_force_rows(modal: dict | None) -> list[tuple[str, str, str]]:
    """End-of-run rows (label, value, unit) of modal.contact_force: F_m per volt, F_m at the drive, the
    predicted free amplitude, and N / F_m per preload."""
    cf = (modal or {}).get("contact_force")
    if not cf:
        return []
    rows = [(f"modal force F_m at the contact (n = {cf['order']})", f"{cf['modal_force_N']:.4g}", "N"),
            ("modal force per volt F_m / V", f"{cf['modal_force_per_volt_N_per_V'] * 1e3:.4g}", "mN/V"),
            ("modal stiffness k_m at the contact", f"{cf['modal_stiffness_N_per_m'] * 1e-6:.4g}", "N/um")]
    if cf["free_normal_amplitude_m"] is not None:
        rows.append(("free normal amplitude W = F_m / (2 zeta k_m)", f"{cf['free_normal_amplitude_m'] * 1e6:.4g}",
                     "um"))
    for p in cf["preloads"]:
        rows.append((f"N / F_m at preload {p['axial_preload_N']:.4g} N (N = {p['normal_force_N']:.4g} N)",
                     f"{p['normal_force_over_modal_force']:.3g}", "-"))
    return rows
