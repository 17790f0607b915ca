"""What a user reads at the end of a run, and again with ``piezodyn plot DIR``: the end-of-run table (one
unit per row) and the plots and CSVs of every result kind (frequency domain, every tier's time series, the
scene's own), from summary.json and the time series alone, without solving anything.

Top layer (beside the runner); the caller hands it the scene of a result (app/scenes/) for its rows and outputs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from app.errors import CaseError


def _number(value, fmt: str = ".4g") -> str:
    return "-" if value is None or (isinstance(value, float) and not math.isfinite(value)) else format(value, fmt)


def frequency_domain_rows(results: dict) -> list[tuple[str, str, str]]:
    rows = []
    if "mass_kg" in results:
        rows.append(("mass", f"{results['mass_kg'] * 1e3:.2f}", "g"))
    modal = results.get("modal")
    if modal:
        rows.append(("resonance f_r (modal, short circuit)", f"{modal['working_resonance_Hz']:.2f}", "Hz"))
        if "working_antiresonance_Hz" in modal:
            rows.append(("antiresonance f_a (modal, open circuit)", f"{modal['working_antiresonance_Hz']:.2f}", "Hz"))
            rows.append(("effective coupling k_eff", f"{modal['working_k_eff']:.4f}", "1"))
    harmonic = results.get("harmonic")
    if harmonic:
        peak = ("|Y| peak (harmonic)" if harmonic.get("admittance_peak_interior", True)
                else "|Y| largest at the sweep's end (no peak inside)")
        rows.append((peak, f"{harmonic['admittance_peak_Hz']:.2f}", "Hz"))
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
    return rows


def transient_rows(transient: dict | None) -> list[tuple[str, str, str]]:
    """End-of-run lines every transient tier shares: time, drive, cost, and per contact its impacts, largest
    force and rate; the foundation's mean force and power (one unit per row)."""
    if not transient:
        return []
    rows = [("simulated time", f"{transient['simulated_time_s'] * 1e3:.4g}", "ms")]
    if transient.get("drive_voltage_V") is not None:
        rows.append(("drive amplitude", f"{transient['drive_voltage_V']:.4g}", "V"))
    if transient.get("drive_frequency_Hz") is not None:
        rows.append(("drive frequency", f"{transient['drive_frequency_Hz']:.2f}", "Hz"))
    lock = transient.get("drive")
    if lock:        # a drive locked to the model's resonance (app/drive.py locked_case)
        rows.append(("model resonance (locked to)", f"{lock['resonance_Hz']:.2f}", "Hz"))
        rows.append(("detuning from it", f"{lock['detuning_Hz']:+.2f}", "Hz"))
    rows.append(("steps", f"{transient.get('steps', 0)}", "1"))
    rows.append(("cut-backs", f"{transient.get('cutbacks', 0)}", "1"))
    rows.append(("wall time per simulated ms", _number(transient.get("wall_s_per_simulated_ms")), "s"))
    steady = transient.get("steady_state")
    if steady:
        rule = f", {steady['rule']} rule" if steady.get("rule") else ""
        rows.append(("steady state reached", "yes" if steady["steady"] else "no",
                     f"after {steady['cycles']} periods{rule}"))
    if transient.get("warm_start"):
        rows.append(("warm start from", transient["warm_start"]["directory"], ""))
    stats = transient.get("statistics") or {}
    rates = stats.get("impact_rate_per_s", {})
    for name, contact in (transient.get("contacts") or {}).items():
        rows.append((f"{name}: impacts", f"{contact['impacts']}", "1"))
        rows.append((f"{name}: impact rate", f"{rates.get(name, 0.0):.4g}", "1/s"))
        rows.append((f"{name}: largest force", f"{contact['max_force_N']:.4g}", "N"))
    for key, value in stats.items():
        if key.endswith("_foundation") and isinstance(value, dict):
            name = key[: -len("_foundation")]
            rows.append((f"{name}: mean force on the foundation", f"{value['mean_force_N']:.4g}", "N"))
            rows.append((f"{name}: mean power into the foundation", f"{value['mean_power_W']:.4g}", "W"))
    return rows


def lumped_rows(lumped: dict | None) -> list[tuple[str, str, str]]:
    if not lumped:
        return []
    if "simulated_time_s" not in lumped:        # a steady solve (app.runner.STEADY_LUMPED_MODELS)
        rows = [("steady points solved", f"{lumped['points_solved']}", "1"),
                ("wall time per point", f"{lumped['wall_s_per_point'] * 1e3:.3g}", "ms")]
        if lumped.get("no_load_speed_rpm") is not None:
            rows.append(("no-load speed (upper branch)", f"{lumped['no_load_speed_rpm']:.4g}", "rpm"))
        if lumped.get("stall_torque_N_m") is not None:
            rows.append(("stall torque mu N r_c", f"{lumped['stall_torque_N_m'] * 1e3:.4g}", "mN m"))
        if not lumped.get("riding"):
            rows.append(("operating point on the crests", "none", "-"))
        return rows
    rows = [("simulated time", f"{lumped['simulated_time_s'] * 1e3:.4g}", "ms"),
            ("wall time per simulated ms", _number(lumped.get("wall_s_per_simulated_ms")), "s")]
    stats = lumped.get("statistics") or {}
    for name, rate in (stats.get("impact_rate_per_s") or {}).items():
        rows.append((f"{name}: impact rate", f"{rate:.4g}", "1/s"))
    rock = stats.get("stem_rock_foundation")
    if rock:
        rows.append(("stem_rock: mean force on the foundation", f"{rock['mean_force_N']:.4g}", "N"))
        rows.append(("stem_rock: mean power into the foundation", f"{rock['mean_power_W']:.4g}", "W"))
    return rows


def result_rows(results: dict, scene=None) -> list[tuple[str, str, str]]:
    """Every row of a run's end-of-run table: frequency domain, transient or lumped, the scene's."""
    rows = frequency_domain_rows(results)
    rows += field_peak_rows((results.get("harmonic") or {}).get("field_peaks"), "harmonic, cycle max")
    for key, common in (("transient", transient_rows), ("lumped", lumped_rows)):
        if results.get(key):
            rows += common(results[key])
            rows += field_peak_rows(results[key].get("field_peaks"), "transient, frames")
            if scene is not None:
                rows += scene.table_rows(results[key])
    return rows


# peak keys of app.fe.derived.region_peaks -> (table label, unit, scale)
FIELD_PEAK_ROWS = {"von_mises_Pa": ("peak von Mises", "MPa", 1e-6),
                   "max_principal_stress_Pa": ("peak max principal stress", "MPa", 1e-6),
                   "electric_field_V_per_m": ("peak |E|", "kV/mm", 1e-6)}


def field_peak_rows(peaks: dict | None, where: str) -> list[tuple[str, str, str]]:
    """One row per region and peak of the derived fields (``field_peaks`` of a harmonic or transient result)."""
    rows = []
    for region, values in (peaks or {}).items():
        for key, (label, unit, scale) in FIELD_PEAK_ROWS.items():
            if key in values:
                rows.append((f"{label}, {region} ({where})", f"{values[key] * scale:.4g}", unit))
    return rows


def print_table(rows: list[tuple[str, str, str]], log) -> None:
    if not rows:
        return
    width = max(len(r[0]) for r in rows)
    value_width = max(14, max(len(r[1]) for r in rows))
    log("-" * (width + value_width + 12))
    for label, value, unit in rows:
        log(f"{label:<{width}}  {value:>{value_width}} {unit}")
    log("-" * (width + value_width + 12))


def plot_spec_of_case(case: dict) -> dict:
    """What the time-series plots of a run show (``results["plot"]``, read again by ``piezodyn plot DIR``), from
    the case as the summary records it (also for a result written before summaries recorded the spec): the drive
    point if it is a named point, the bodies that move, every contact, a title saying what was run."""
    transient = case.get("transient") or {}
    point = (transient.get("drive") or {}).get("point")
    bodies = [b["name"] for b in transient.get("bodies", [])
              if not b.get("fixed") and (b.get("free_axes") is None or any(b["free_axes"]))]
    title = case.get("title") or Path(str(case.get("source", "case"))).stem
    return {"point": point if point in (case.get("points") or {}) else None, "bodies": bodies,
            "contacts": [c["name"] for c in transient.get("contacts", [])],
            "title": f"{title} ({case.get('tier', 'fe')} tier)"}


def read_summary(result_dir: Path) -> dict:
    """summary.json of a result directory, or a one-line CaseError saying why it cannot be used."""
    if not result_dir.exists():
        raise CaseError(str(result_dir), None, "no such directory")
    if not result_dir.is_dir():
        raise CaseError(str(result_dir), None, "is a file, not a result directory")
    path = result_dir / "summary.json"
    if not path.is_file():
        raise CaseError(str(result_dir), None, "no summary.json here: not a piezodyn result directory")
    try:
        summary = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise CaseError(str(path), None, "is not UTF-8 text (damaged)") from None
    except json.JSONDecodeError as exc:
        raise CaseError(str(path), None, f"is not valid JSON (truncated or damaged: {exc.msg})") from None
    except OSError as exc:
        raise CaseError(str(path), None, f"cannot be read ({exc.strerror})") from None
    if not isinstance(summary, dict) or not isinstance(summary.get("results"), dict):
        raise CaseError(str(path), "results", "missing: not a piezodyn summary")
    return summary


def replot(result_dir: str | Path, log, scenes: dict, write: bool = True) -> list[str]:
    """``piezodyn plot DIR``: the table, plots and CSVs of an existing result directory, from summary.json and
    the time series, without solving anything (every result kind: modal, harmonic, the transient tiers, the
    lumped tier, the scene's, looked up in ``scenes``; a sweep's directory: app.sweep.replot_sweep). A damaged
    or foreign directory is one CaseError naming the file."""
    from app.plots import frequency_domain_outputs, time_series_outputs
    from app.series import check_time_series

    result_dir = Path(result_dir)
    summary = read_summary(result_dir)
    results, case = summary["results"], summary.get("case") or {}
    name = case.get("scene")
    scene = scenes.get(name) if name is not None else None
    if name is not None and scene is None:
        raise CaseError(str(result_dir / "summary.json"), "case.scene", f"unknown scene {name!r}")
    for key in ("transient", "lumped"):
        tier = results.get(key)
        if isinstance(tier, dict) and tier.get("time_series"):
            check_time_series(result_dir / tier["time_series"])
    written = []
    if write:
        written += frequency_domain_outputs(result_dir, results, True, case.get("title", ""))
        for key in ("transient", "lumped"):
            tier = results.get(key)
            if not isinstance(tier, dict):
                continue
            if key == "transient" and not tier.get("plot"):
                tier = {**tier, "plot": plot_spec_of_case(case)}
            written += time_series_outputs(result_dir, tier)
            if scene is not None:
                title = (tier.get("plot") or {}).get("title", case.get("title", ""))
                written += scene.outputs(tier, result_dir, title)
    print_table(result_rows(results, scene), log)
    return written
