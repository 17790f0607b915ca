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
from app.report import plot_spec_of_case, print_table, result_rows
from app.scenes import scene_of


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
    if resume and "transient" not in case.analyses and case.tier != "lumped":
        raise CaseError(str(case_path), "--resume", f"only a transient analysis or a lumped run can be resumed; "
                                                    f"this case runs {', '.join(case.analyses)}")
    if resume and case.tier == "lumped" and case.lumped.model in STEADY_LUMPED_MODELS:
        raise CaseError(str(case_path), "--resume", f"lumped model {case.lumped.model!r} is a steady solve: nothing "
                                                    "to resume (run it again)")
    return case


def check_scene(case: Case) -> None:
    """The case's ``scene`` names a registered scene (app/scenes/), and the scene's own input rules hold."""
    from app.scenes import SCENES

    if case.scene is None:
        return
    if case.scene not in SCENES:
        raise CaseError(case.source, "scene", f"unknown scene {case.scene!r} (scenes: {', '.join(SCENES)})")
    SCENES[case.scene].check(case)


def check_case(case: Case, comm: MPI.Comm = MPI.COMM_WORLD, log=None) -> None:
    """Every input check that ``run`` makes, including those that need the mesh, without solving:
    the FE model (groups, electrodes, points) and the transient model (drive point, contacts,
    loads). Collective."""
    if case.tier == "lumped" and case.lumped.model in STEADY_LUMPED_MODELS:
        _steady_lumped(case.lumped.model).check(case)
        return
    if case.tier == "lumped" or "transient" in case.analyses:
        engine_class(case.tier).check(case, comm, log or (lambda *a: None))
        if not _probes_frequency_domain(case):
            return
    # the FE model (a case that also runs a transient builds it a second time here: a rare combination)
    from app.fe.model import build_model

    check_frequency_domain(case, build_model(case, comm))


def _probes_frequency_domain(case: Case) -> bool:
    """Whether a frequency-domain analysis of ``case`` samples the mesh at points of its own."""
    return ("modal" in case.analyses and case.modal.identify is not None
            or "harmonic" in case.analyses and case.harmonic.wave is not None)


def check_frequency_domain(case: Case, model) -> None:
    """The frequency-domain analyses' checks that need the mesh, without solving: the sample points of
    modal.identify and harmonic.wave lie inside it. Collective."""
    if "modal" in case.analyses and case.modal.identify is not None:
        from app.modal import mode_identifier

        mode_identifier(model)
    if "harmonic" in case.analyses and case.harmonic.wave is not None:
        from app.harmonic import wave_circle

        wave_circle(model, case.harmonic.wave)


ENGINES = {"fe": "app.transient.engine:FEEngine", "modal": "app.reduced.engine:ModalEngine",
           "lumped": "app.lumped.engine:LumpedEngine"}


#: lumped models solved for their steady state rather than stepped through the run loop (module: solve, check)
STEADY_LUMPED_MODELS = {"friction_drive": "app.lumped.friction_drive"}


def _steady_lumped(model: str):
    from importlib import import_module

    return import_module(STEADY_LUMPED_MODELS[model])


def engine_class(tier: str):
    """The transient engine of a tier (app/loop/loop.py's protocol)."""
    from importlib import import_module

    module, _, name = ENGINES[tier].partition(":")
    return getattr(import_module(module), name)


def run_case(case_path: str | Path, overrides: list[str] | None = None, out_dir: str | Path | None = None,
             comm: MPI.Comm = MPI.COMM_WORLD, quiet: bool = False, resume: bool = False) -> dict:
    log = make_log(comm, quiet)
    timer = PhaseTimer()
    with timer.phase("validate"):
        case = load_for_run(case_path, overrides, resume)
    out = Path(out_dir) if out_dir else Path("results") / Path(case_path).stem
    flag = "--resume" if resume else "--out"
    prepare_output_dir(out, comm, flag, resume)
    from app.loop.loop import DirectoryLock

    # held for the whole run, before anything in the directory changes: a second run, or a --resume of a
    # directory a live run is writing, is refused with one line and leaves every file as it was
    lock = DirectoryLock(out, comm, flag)
    try:
        log(f"piezodyn {__version__}: {case.title or Path(case_path).name} -> {out}/ ({comm.size} MPI rank(s))")
        summary = {"case": to_dict(case), "versions": versions(), "mpi_size": comm.size, "results": {},
                   "outputs": []}
        with silenced(quiet):  # --quiet: no progress output either
            TIER_RUNNERS[case.tier](case, out, comm, log, timer, summary, resume)
        summary["wall_time_s"] = timer.seconds
        summary["outputs"].append("summary.json")
        if comm.rank == 0:
            write_json_atomic(out / "summary.json", summary)
    finally:
        lock.release()
    log(f"summary: {out / 'summary.json'}")
    return summary


def run_lumped(case: Case, out: Path, comm, log, timer: PhaseTimer, summary: dict, resume: bool) -> None:
    """The lumped tier through the one run loop (app/loop/loop.py, app/lumped/engine.py), then the scene's
    statistics and plots from the written series. ``lumped.output.write_time_series = false``: the series is
    removed at the end (the statistics are taken first) and no plots are drawn."""
    import dataclasses

    from app.loop.loop import run_transient
    from app.lumped.outputs import describe_series, plot_spec

    section = case.lumped
    if section.model in STEADY_LUMPED_MODELS:
        run_lumped_steady(case, out, comm, log, timer, summary)
        return
    cls = engine_class(case.tier)
    with timer.phase("lumped"):
        results = summary["results"]["lumped"] = run_transient(lambda found: cls(case, comm, log, found), case, out,
                                                               comm, log, resume)
        results["scene"] = case.scene
        results["plot"] = plot_spec(section.downforce_N, Path(case.source).stem)
        series = out / results["time_series"]
        if comm.rank == 0:
            describe_series(series)
        keep = section.output.write_time_series
        plots = keep and section.output.plots and case.output.plots
        add_scene_results(results, dataclasses.replace(case, output=dataclasses.replace(case.output, plots=plots)),
                          out, comm)
        if not keep:
            if comm.rank == 0:
                series.unlink(missing_ok=True)
            comm.barrier()
            results.pop("time_series")
            results["outputs"].remove(series.name)
    summary["outputs"] += results.pop("outputs", [])
    print_table(result_rows(summary["results"], scene_of(case)), log)


def run_lumped_steady(case: Case, out: Path, comm, log, timer: PhaseTimer, summary: dict) -> None:
    """A lumped model with a steady solve (``STEADY_LUMPED_MODELS``): its module's ``solve(section)`` on rank 0 (it
    takes milliseconds), the results to every rank, then the scene's statistics and outputs from them (there is no
    time series)."""
    with timer.phase("lumped"):
        results = _steady_lumped(case.lumped.model).solve(case.lumped) if comm.rank == 0 else None
        results = comm.bcast(results, root=0) if comm.size > 1 else results
        results["scene"] = case.scene
        summary["results"]["lumped"] = results
        add_scene_results(results, case, out, comm)
        log(f"lumped ({case.lumped.model}): {results['points_solved']} steady points in {results['wall_time_s']:.3g} s")
    summary["outputs"] += results.pop("outputs", [])
    print_table(result_rows(summary["results"], scene_of(case)), log)


def run_fe(case: Case, out: Path, comm, log, timer: PhaseTimer, summary: dict, resume: bool) -> None:
    from app.fe.model import build_model
    from app.fe.operators import add_damping, assemble_operators

    results = summary["results"]
    if case.tier == "modal" and list(case.analyses) == ["transient"]:
        # the modal tier's transient alone: its engine reduces the model, or takes it from the cache (no mesh)
        with timer.phase("transient"):
            results["transient"] = run_transient_analysis(case, out, comm, log, resume)
        summary["outputs"] += results["transient"].pop("outputs", [])
        if "regions" in results["transient"]:         # no FE model here: the reduced model's region table
            summary["regions"] = results["transient"]["regions"]
        print_table(result_rows(results, scene_of(case)), log)
        return
    with timer.phase("mesh"):
        model = build_model(case, comm)
    imap = model.W.dofmap.index_map
    cells = model.mesh.topology.index_map(model.mesh.topology.dim).size_global
    summary["dofs"] = {"total": imap.size_global, "cells": cells}
    results["mass_kg"] = model.total_mass_kg()
    summary["regions"] = {str(region.tag): region.name for region in model.regions}
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
                response_writer = None
                if case.output.fields:
                    def response_writer(model_, solver, frequency_Hz, scale):
                        return write_harmonic_response(model_, solver, frequency_Hz, scale, out, summary)
                harmonic = run_harmonic(model, ops, f_r, f_a, log, wave_writer, pair_centre_Hz(modal),
                                        response_writer)
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
        with timer.phase("transient"):
            results["transient"] = run_transient_analysis(case, out, comm, log, resume)
        summary["outputs"] += results["transient"].pop("outputs", [])
    print_table(result_rows(results, scene_of(case)), log)


def run_transient_analysis(case: Case, out: Path, comm, log, resume: bool) -> dict:
    """The transient analysis of ``case`` in its tier's engine, through the one run loop; then the scene's
    statistics and outputs (from the written series)."""
    from app.loop.loop import run_transient

    scene = scene_of(case)
    cls = engine_class(case.tier)
    floors = scene.steady_floors(case) if scene is not None else (0.0, 0.0)
    engines = []

    def make_engine(found):
        engines.append(cls(case, comm, log, found))
        return engines[-1]

    results = run_transient(make_engine, case, out, comm, log, resume, floors)
    case = engines[-1].case     # as the engine ran it: a drive locked to the resonance has its frequency resolved
    results["scene"] = case.scene
    results["plot"] = plot_spec_of_case(to_dict(case))
    add_scene_results(results, case, out, comm)
    return results


def add_scene_results(results: dict, case: Case, out: Path, comm) -> None:
    """The scene's statistics (from the time series written) into ``results["statistics"]``, and the plots and
    CSVs of the run (the tier's time-series plots, the scene's): rank 0 computes, every rank gets them."""
    from app.series import read_time_series

    scene = scene_of(case)
    written = []
    added = {}
    if comm.rank == 0:
        h5 = out / results["time_series"] if results.get("time_series") else None
        if scene is not None and h5 is not None and h5.is_file():
            added = scene.statistics(read_time_series(h5), case, results)
        elif scene is not None and h5 is None:       # a steady solve: the scene reads the tier's results
            added = scene.statistics({}, case, results)
    added = comm.bcast(added, root=0) if comm.size > 1 else added
    results.setdefault("statistics", {}).update(added)
    if comm.rank == 0:
        from app.plots import time_series_outputs

        if case.output.plots:
            written += time_series_outputs(out, results)
        if scene is not None:
            title = (results.get("plot") or {}).get("title", case.title)
            written += scene.outputs(results, out, title, case.output.plots)
    written = comm.bcast(written, root=0) if comm.size > 1 else written
    results["plots"] = written
    results.setdefault("outputs", []).extend(written)


TIER_RUNNERS = {"fe": run_fe, "modal": run_fe, "lumped": run_lumped}


def write_modes(model, modal, out: Path, summary: dict) -> None:
    from app.exports import ModeShapeExport
    from app.fe.derived import derived_for_model

    derived = derived_for_model(model, model.case.output.derived)
    for state, modes in (("short", modal.short), ("open", modal.open)):
        if not modes:
            continue
        export = ModeShapeExport(out / f"modes_{state}.xdmf", model, model.case.output.mode_shape_amplitude_m,
                                 derived)
        for mode in modes:
            export.write(mode.vector, mode.frequency_Hz)
        summary["outputs"] += export.close()


def write_harmonic_response(model, solver, frequency_Hz: float, scale: float, out: Path, summary: dict) -> dict:
    """The response at ``frequency_Hz`` (the solver's last solution times ``scale``) as harmonic_fields.xdmf;
    returns the peaks per region over the cycle."""
    from app.exports import HarmonicFieldExport
    from app.fe.derived import derived_for_model

    x_re, x_im = solver.full_solution()
    re, im = x_re.copy(), x_im.copy()
    re.scale(scale)
    im.scale(scale)
    derived = derived_for_model(model, model.case.output.derived)
    export = HarmonicFieldExport(out / "harmonic_fields.xdmf", model, derived)
    peaks = export.write_phasor(re, im, frequency_Hz)
    re.destroy()
    im.destroy()
    summary["outputs"] += export.close()
    return peaks


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
