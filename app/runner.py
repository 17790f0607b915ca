"""Runs one case: validation, then the analyses it lists, then summary.json.

Phases (each timed): mesh, assemble, modal, harmonic, circuit, lumped / transient, export.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

from mpi4py import MPI

from app import __version__
from app.case.schema import Case, load_case
from app.case.validate import to_dict
from app.errors import CaseError
from app.files import write_json_atomic
from app.mpi_log import PhaseTimer, make_log
from app.progress import silenced


def versions() -> dict:
    import dolfinx
    import petsc4py
    import slepc4py

    return {"piezodyn": __version__, "dolfinx": dolfinx.__version__, "petsc4py": petsc4py.__version__,
            "slepc4py": slepc4py.__version__, "python": platform.python_version()}


def prepare_output_dir(path: str | Path, comm, flag: str = "--out", resume: bool = False) -> Path:
    """Check (and unless ``resume``, create) an output directory on rank 0 and share the verdict,
    so every rank raises the same CaseError (no rank waits for one that failed): an existing file,
    a path under a file, a directory that cannot be created or written."""
    path = Path(path)
    why = None
    if comm is None or comm.rank == 0:
        why = _output_dir_problem(path, resume)
    if comm is not None and comm.size > 1:
        why = comm.bcast(why, root=0)
    if why:
        raise CaseError(flag, str(path), why)
    return path


def _output_dir_problem(path: Path, resume: bool) -> str | None:
    if path.exists() and not path.is_dir():
        return "is an existing file, not a directory"
    if resume:
        return None if path.is_dir() else "no such directory (nothing to resume)"
    try:
        path.mkdir(parents=True, exist_ok=True)
    except NotADirectoryError:
        return "cannot be created: a parent is a file, not a directory"
    except OSError as exc:
        return f"cannot be created ({exc.strerror or exc})"
    if not os.access(path, os.W_OK | os.X_OK):
        return "is not writable"
    return None


def load_for_run(case_path: str | Path, overrides: list[str] | None, resume: bool = False) -> Case:
    """Load and check a case for ``run`` (and ``validate``): the schema, and the CLI rules."""
    case = load_case(case_path, overrides)
    check_scene(case)
    if resume and "transient" not in case.analyses:
        raise CaseError(str(case_path), "--resume", f"only a transient analysis can be resumed; this case runs "
                                                    f"{', '.join(case.analyses)}")
    return case


def check_scene(case: Case) -> None:
    """The case's ``scene`` names a registered scene (app/scenes/)."""
    from app.scenes import SCENES

    if case.scene is not None and case.scene not in SCENES:
        raise CaseError(case.source, "scene", f"unknown scene {case.scene!r} (scenes: {', '.join(SCENES)})")


def check_case(case: Case, comm: MPI.Comm = MPI.COMM_WORLD, log=None) -> None:
    """Every input check that ``run`` makes, including those that need the mesh, without solving:
    the FE model (groups, electrodes, points) and the transient model (drive point, contacts,
    loads). Collective."""
    if case.tier not in ("fe", "modal"):
        return
    if case.tier == "modal" and "transient" in case.analyses:
        from app.reduced import motor

        if motor.is_motor_case(case):       # the motor's reduced stator: its band and electrodes
            motor.check_model(case, comm)
            return
    if "transient" in case.analyses:        # the modal tier builds the same model before reducing it
        from app.transient.driver import build

        tm = build(case, comm, log or (lambda *a: None))
        tm.system.destroy()
    else:
        from app.fe.model import build_model

        build_model(case, comm)


def run_case(case_path: str | Path, overrides: list[str] | None = None, out_dir: str | Path | None = None,
             comm: MPI.Comm = MPI.COMM_WORLD, quiet: bool = False, resume: bool = False) -> dict:
    log = make_log(comm, quiet)
    timer = PhaseTimer()
    with timer.phase("validate"):
        case = load_for_run(case_path, overrides, resume)
    out = Path(out_dir) if out_dir else Path("results") / Path(case_path).stem
    prepare_output_dir(out, comm, "--resume" if resume else "--out", resume)
    log(f"piezodyn {__version__}: {case.title or Path(case_path).name} -> {out}/ ({comm.size} MPI rank(s))")
    summary = {"case": to_dict(case), "versions": versions(), "mpi_size": comm.size, "results": {},
               "outputs": []}
    with silenced(quiet):  # --quiet: no progress output either
        TIER_RUNNERS[case.tier](case, out, comm, log, timer, summary, resume)
    summary["wall_time_s"] = timer.seconds
    summary["outputs"].append("summary.json")
    if comm.rank == 0:
        write_json_atomic(out / "summary.json", summary)
    log(f"summary: {out / 'summary.json'}")
    return summary


def run_lumped(case: Case, out: Path, comm, log, timer: PhaseTimer, summary: dict, resume: bool) -> None:
    from app.lumped import driver

    with timer.phase("lumped"):
        summary["results"]["lumped"] = driver.run(case.lumped, out, comm, log, Path(case.source).stem)
    summary["outputs"] += summary["results"]["lumped"].pop("outputs", [])


def run_fe(case: Case, out: Path, comm, log, timer: PhaseTimer, summary: dict, resume: bool) -> None:
    from app.fe.model import build_model
    from app.fe.operators import add_damping, assemble_operators

    results = summary["results"]
    if case.tier == "modal" and list(case.analyses) == ["transient"]:
        from app.reduced import motor

        if motor.is_motor_case(case):       # its reduced stator may come from the cache: no mesh needed
            with timer.phase("transient"):
                results["transient"] = motor.run(case, out, comm, log, resume=resume)
            summary["outputs"] += results["transient"].pop("outputs", [])
            print_table(results, log)
            return
    with timer.phase("mesh"):
        model = build_model(case, comm)
    imap = model.W.dofmap.index_map
    cells = model.mesh.topology.index_map(model.mesh.topology.dim).size_global
    summary["dofs"] = {"total": imap.size_global, "cells": cells}
    results["mass_kg"] = model.total_mass_kg()
    log(f"mesh: {cells} cells, {imap.size_global} DOFs, mass {results['mass_kg'] * 1e3:.2f} g")
    modal = harmonic = None
    f_r = f_a = None
    frequency_domain = {"modal", "harmonic", "circuit"} & set(case.analyses)
    if frequency_domain:
        with timer.phase("assemble"):
            ops = assemble_operators(model)
    if "modal" in case.analyses:
        from app.modal import modal_summary, mode_table, mode_table_lines, run_modal

        with timer.phase("modal"):
            modal = run_modal(model, ops)
            results["modal"] = modal_summary(model, modal)
        rows = mode_table(modal)
        if modal.orders is not None:
            for line in mode_table_lines(rows, modal.working):
                log(line)
        f_r, f_a = modal.working_mode.frequency_Hz, modal.antiresonance_Hz()
        log(f"modal: working mode f_r = {f_r:.2f} Hz" + (f", f_a = {f_a:.2f} Hz, k_eff = "
                                                          f"{results['modal']['working_k_eff']:.4f}" if f_a else ""))
        if f_a is None and modal.open:
            log("modal: warning: the working mode has no open-circuit partner in the window; "
                "raise modal.n_modes or move modal.target_frequency_Hz between f_r and f_a")
        if case.output.fields:
            with timer.phase("export"):
                write_modes(model, modal, out, summary)
    damping_f = case.damping.reference_frequency_Hz or f_r or (case.modal.target_frequency_Hz if case.modal else None)
    if damping_f is None and case.harmonic is not None and case.harmonic.f_start_Hz is not None:
        damping_f = 0.5 * (case.harmonic.f_start_Hz + case.harmonic.f_stop_Hz)
    if "harmonic" in case.analyses or "circuit" in case.analyses:
        from app.harmonic import harmonic_summary, run_harmonic, wave_lines

        with timer.phase("assemble"):
            add_damping(ops, model, damping_f)
        if "harmonic" in case.analyses:
            with timer.phase("harmonic"):
                wave_writer = None
                if case.output.fields and case.harmonic.wave and case.harmonic.wave.animation_frames:
                    def wave_writer(model_, solver, frequency_Hz):
                        write_wave(model_, solver, frequency_Hz, case.harmonic.wave.animation_frames, out, summary)
                harmonic = run_harmonic(model, ops, f_r, f_a, log, wave_writer, pair_centre_Hz(modal))
                results["harmonic"] = harmonic_summary(harmonic)
                for line in wave_lines(results["harmonic"].get("travelling_wave")):
                    log(line)
        if "circuit" in case.analyses:
            from app.circuit import equivalent_circuit

            with timer.phase("circuit"):
                results["circuit"] = equivalent_circuit(model, ops, modal, harmonic, case.circuit.point)
    if frequency_domain:
        ops.destroy()
        if comm.rank == 0:  # modes.csv, harmonic.csv, admittance.png, impedance.png
            from app.plots import frequency_domain_outputs

            with timer.phase("export"):
                summary["outputs"] += frequency_domain_outputs(out, results, case.output.plots, case.title)
    if "transient" in case.analyses:
        if case.tier == "modal":
            from app.reduced import driver as transient_driver
            from app.reduced import motor

            if motor.is_motor_case(case):
                transient_driver = motor
        else:
            from app.transient import driver as transient_driver

        with timer.phase("transient"):
            results["transient"] = transient_driver.run(case, out, comm, log, resume=resume)
        summary["outputs"] += results["transient"].pop("outputs", [])
    print_table(results, log)


TIER_RUNNERS = {"fe": run_fe, "modal": run_fe, "lumped": run_lumped}


def write_modes(model, modal, out: Path, summary: dict) -> None:
    from app.exports import ModeShapeExport

    for state, modes in (("short", modal.short), ("open", modal.open)):
        if not modes:
            continue
        export = ModeShapeExport(out / f"modes_{state}.xdmf", model)
        for mode in modes:
            export.write(mode.vector, mode.frequency_Hz)
        summary["outputs"] += export.close()


def pair_centre_Hz(modal) -> float | None:
    """Centre of the working mode and its degenerate partner: a two-phase drive runs between them."""
    if modal is None or modal.orders is None or modal.orders[modal.working].partner is None:
        return None
    return 0.5 * (modal.working_mode.frequency_Hz + modal.short[modal.orders[modal.working].partner].frequency_Hz)


def write_wave(model, solver, frequency_Hz: float, frames: int, out: Path, summary: dict) -> None:
    """The steady wave u(t) = Re(x exp(i omega t)) over one period as an XDMF series ('time' in s)."""
    import math

    from app.exports import WaveExport

    x_re, x_im = solver.full_solution()
    x_t = x_re.duplicate()
    period = 1.0 / frequency_Hz
    export = WaveExport(out / "travelling_wave.xdmf", model)
    for k in range(frames):
        phase = 2 * math.pi * k / frames
        x_t.array_w[:] = math.cos(phase) * x_re.array_r - math.sin(phase) * x_im.array_r
        export.write(x_t, k * period / frames)
    x_t.destroy()
    summary["outputs"] += export.close()


def transient_rows(transient: dict | None) -> list[tuple[str, str, str]]:
    """End-of-run lines of a transient run (FE and modal tiers): drive, cost, and per contact its
    impacts, largest force and rate; the foundation's mean force and power; the transducer's rise."""
    if not transient:
        return []
    if transient.get("motor"):
        from app.reduced.motor import table_rows

        return table_rows(transient)
    wall_per_ms = transient["wall_s_per_simulated_ms"]     # None: a finished run resumed (no step taken)
    rows = [("simulated time", f"{transient['simulated_time_s'] * 1e3:.4g}", "ms"),
            ("drive amplitude", f"{transient['drive_voltage_V']:.4g}", "V"),
            ("steps / cut-backs", f"{transient['steps']} / {transient['cutbacks']}", "-"),
            ("wall time per simulated ms", "-" if wall_per_ms is None else f"{wall_per_ms:.4g}", "s")]
    stats = transient.get("statistics") or {}
    rates = stats.get("impact_rate_per_s", {})
    for name, contact in (transient.get("contacts") or {}).items():
        rows.append((f"{name}: impacts (rate)", f"{contact['impacts']} ({rates.get(name, 0.0):.4g} /s)", "-"))
        rows.append((f"{name}: largest force", f"{contact['max_force_N']:.4g}", "N"))
    for key, value in stats.items():
        if key.endswith("_foundation") and isinstance(value, dict):
            name = key[: -len("_foundation")]
            rows.append((f"{name}: mean force on the foundation", f"{value['mean_force_N']:.4g}", "N"))
            rows.append((f"{name}: mean power into the foundation", f"{value['mean_power_W']:.4g}", "W"))
    if transient.get("scene"):
        from app.scenes import scene_report

        rows += scene_report(transient["scene"]).table_rows(stats)
    return rows


def print_table(results: dict, log) -> None:
    rows = []
    if "mass_kg" in results:
        rows.append(("mass", f"{results['mass_kg'] * 1e3:.2f}", "g"))
    modal = results.get("modal")
    if modal:
        rows.append(("resonance f_r (modal, short circuit)", f"{modal['working_resonance_Hz']:.2f}", "Hz"))
        if "working_antiresonance_Hz" in modal:
            rows.append(("antiresonance f_a (modal, open circuit)", f"{modal['working_antiresonance_Hz']:.2f}", "Hz"))
            rows.append(("effective coupling k_eff", f"{modal['working_k_eff']:.4f}", "-"))
    harmonic = results.get("harmonic")
    if harmonic:
        rows.append(("|Y| peak (harmonic)", f"{harmonic['admittance_peak_Hz']:.2f}", "Hz"))
        if harmonic.get("admittance_trough_Hz"):
            rows.append(("|Y| trough (harmonic)", f"{harmonic['admittance_trough_Hz']:.2f}", "Hz"))
        if "voltage_for_target_amplitude_V" in harmonic:
            rows.append(("voltage for target amplitude", f"{harmonic['voltage_for_target_amplitude_V']:.2f}", "V"))
    circuit = results.get("circuit")
    if circuit:
        for key, label, scale, unit in (("modal_mass_kg", "equivalent mass m_m", 1e3, "g"),
                                        ("modal_stiffness_N_per_m", "equivalent stiffness k_m", 1e-6, "N/um"),
                                        ("modal_damping_N_s_per_m", "equivalent damping c_m", 1.0, "N s/m"),
                                        ("force_factor_N_per_V", "force factor alpha", 1.0, "N/V"),
                                        ("clamped_capacitance_F", "clamped capacitance C_p", 1e9, "nF")):
            if key in circuit:
                rows.append((label, f"{circuit[key] * scale:.4g}", unit))
    rows += transient_rows(results.get("transient"))
    if not rows:
        return
    width = max(len(r[0]) for r in rows)
    log("-" * (width + 24))
    for label, value, unit in rows:
        log(f"{label:<{width}}  {value:>14} {unit}")
    log("-" * (width + 24))
