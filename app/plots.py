"""PNG plots (matplotlib, Agg backend)."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# Unit suffixes of piezodyn's names (summary.json keys, case keys) -> (shown unit, factor from SI).
# Lengths in mm, frequencies in kHz, masses in g, times in ms, as the terminal summaries show them.
UNIT_SUFFIXES = (
    ("_N_m", "mN m", 1e3),
    ("_m_per_s", "mm/s", 1e3),
    ("_N_s_per_m", "N s/m", 1.0),
    ("_N_per_m", "N/mm", 1e-3),
    ("_N_per_V", "N/V", 1.0),
    ("_m_per_V", "µm/V", 1e6),
    ("_m_per_s2", "m/s²", 1.0),
    ("_per_s", "1/s", 1.0),
    ("_N_s", "N s", 1.0),
    ("_Hz", "kHz", 1e-3),
    ("_kg", "g", 1e3),
    ("_deg", "deg", 1.0),
    ("_m", "mm", 1e3),
    ("_s", "ms", 1e3),
    ("_W", "W", 1.0),
    ("_N", "N", 1.0),
    ("_J", "J", 1.0),
    ("_V", "V", 1.0),
    ("_S", "S", 1.0),
    ("_F", "nF", 1e9),
)
# Path segments that only group keys; left out of labels.
_GROUPS = {"lumped", "transient", "statistics", "geometry", "parameters", "results"}


def quantity_label(name: str) -> tuple[str, float]:
    """A dotted piezodyn name -> (axis label with unit, factor to multiply SI values by):
    ``transient.statistics.transducer.max_rise_m`` -> ("transducer max rise [mm]", 1e3)."""
    words, unit, scale = [], None, 1.0
    for segment in name.split("."):
        if segment in _GROUPS:
            continue
        for suffix, shown, factor in UNIT_SUFFIXES:
            if segment.endswith(suffix) and len(segment) > len(suffix):
                segment = segment[: -len(suffix)]
                unit, scale = shown, factor
                break
        words.append(segment.replace("_", " "))
    text = " ".join(words).replace("k eff", "k_eff").replace("fe force", "FE force") or name
    return (f"{text} [{unit}]" if unit else text), scale


def write_harmonic_table(path: Path, harmonic: dict) -> None:
    """The harmonic sweep as CSV: frequency, admittance Y and impedance Z = 1/Y (magnitude, phase)."""
    f = np.asarray(harmonic["frequency_Hz"], dtype=float)
    mag = np.asarray(harmonic["admittance_magnitude_S"], dtype=float)
    phase = np.asarray(harmonic["admittance_phase_deg"], dtype=float)
    with open(path, "w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow(["frequency_Hz", "admittance_magnitude_S", "admittance_phase_deg",
                         "impedance_magnitude_ohm", "impedance_phase_deg"])
        for row in zip(f, mag, phase, 1.0 / mag, -phase):
            writer.writerow([repr(float(v)) for v in row])


def write_mode_table(path: Path, modal: dict) -> None:
    """The mode table as CSV: one row per short-circuit mode, its open-circuit partner and k_eff, and
    its orders (m, n, component, partner and split) when the case asks for mode identification. Modes are
    numbered from 1 (column ``mode``, and ``partner_mode``), as in the mode-shape XDMF and the log."""
    modes = modal.get("modes") or []
    keys: dict[str, None] = {}      # union of the modes' scalar keys, in first-seen order
    for mode in modes:
        keys.update({k: None for k, v in mode.items() if not isinstance(v, (list, dict)) and k != "mode"})
    columns = ["mode", *keys]
    with open(path, "w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow(columns + ["working"])
        for i, mode in enumerate(modes):
            values = [i + 1] + [mode.get(k, "") for k in columns[1:]]
            writer.writerow([repr(v) if isinstance(v, float) else ("" if v is None else v) for v in values]
                            + [int(i == modal.get("working_mode_index"))])


def _mark_fr_fa(ax, f_r: float | None, f_a: float | None, label: bool) -> None:
    """Dashed lines at the modal f_r and f_a; on the top axes their values in the legend."""
    for name, value, style in (("f_r", f_r, "--"), ("f_a", f_a, ":")):
        if value:
            ax.axvline(value / 1e3, color="dimgray", ls=style, lw=1.0,
                       label=f"{name} = {value / 1e3:.3f} kHz (modal)" if label else None)


def _circuit_curve(circuit: dict | None, f: np.ndarray):
    if not circuit or "clamped_capacitance_F" not in circuit:
        return None, None
    from app.circuit import bvd_admittance

    fine = np.linspace(f[0], f[-1], 2000)
    return fine, bvd_admittance(circuit, fine)


def _drive_of(harmonic: dict) -> dict:
    """{electrode: (amplitude V, phase deg)} of the sweep's drive (empty for an old summary)."""
    return {name: tuple(value) for name, value in (harmonic.get("drive_phasors_V_deg") or {}).items()}


def _what_is_plotted(harmonic: dict, what: str) -> tuple[str, str]:
    """(the FE curve's legend, the title's line): what the sweep's admittance is under its drive. One driven
    electrode (or several in phase): its I / V. Several phases: j omega (total driven charge) / voltage_V, not a
    driving-point admittance; each electrode driven alone is drawn beside it."""
    drive = _drive_of(harmonic)
    name = {"Y": "Electrical admittance", "Z": "Electrical impedance"}[what]
    if not drive:                                   # a summary from before the drive was recorded
        return "FE", f"{name} of the driven electrodes"
    names = ", ".join(drive)
    if len({round(p, 6) for _, p in drive.values()}) <= 1:
        return f"FE: {what} of {names}", f"{name} {what} = {'I/V' if what == 'Y' else 'V/I'} of electrode {names}"
    phases = ", ".join(f"{n} {a:.4g} V at {p:.0f} deg" for n, (a, p) in drive.items())
    return (f"FE: total current / reference V under the drive ({phases}); not a driving-point {what}",
            f"{name}: each driven electrode alone (others at 0 V); dashed: the drive's total")


def _frequency_plot(path: Path, f: np.ndarray, magnitude: np.ndarray, phase: np.ndarray, fine, fine_values,
                    f_r, f_a, what: str, unit: str, title: str, harmonic: dict | None = None,
                    alone: dict | None = None) -> None:
    fe_label, name = _what_is_plotted(harmonic or {}, what)
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 7))
    for electrode, (alone_magnitude, alone_phase) in (alone or {}).items():
        label = f"{what}_{electrode} = {'I/V' if what == 'Y' else 'V/I'}, {electrode} driven alone"
        ax1.semilogy(f / 1e3, alone_magnitude, "s-", ms=3, label=label)
        ax2.plot(f / 1e3, alone_phase, "s-", ms=3, label=label)
    style = "o--" if alone else "o-"
    ax1.semilogy(f / 1e3, magnitude, style, ms=3, label=fe_label)
    ax2.plot(f / 1e3, phase, style, ms=3, label=fe_label)
    if fine is not None:
        ax1.semilogy(fine / 1e3, np.abs(fine_values), "-", lw=1, label="1-DOF equivalent circuit")
        ax2.plot(fine / 1e3, np.degrees(np.angle(fine_values)), "-", lw=1, label="1-DOF equivalent circuit")
    _mark_fr_fa(ax1, f_r, f_a, label=True)
    _mark_fr_fa(ax2, f_r, f_a, label=False)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    ax1.set_ylabel(f"|{what}| [{unit}]")
    ax2.set_ylabel(f"phase({what}) [deg]")
    ax2.set_xlabel("frequency [kHz]")
    ax1.set_title(f"{title}\n{name}" if title else name, fontsize=9)
    # the legend below the panels: over a panel it would hide a curve's resonance loop whatever its corner
    handles, labels = ax1.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.035 * len(labels) + 0.01, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def admittance_plot(path: Path, harmonic: dict, f_r: float | None, f_a: float | None, circuit: dict | None = None,
                    title: str = ""):
    f = np.array(harmonic["frequency_Hz"])
    fine, y = _circuit_curve(circuit, f)
    _frequency_plot(path, f, np.array(harmonic["admittance_magnitude_S"]), np.array(harmonic["admittance_phase_deg"]),
                    fine, y, f_r, f_a, "Y", "S", title, harmonic, _alone(harmonic, impedance=False))


def _alone(harmonic: dict, impedance: bool) -> dict:
    """{electrode: (magnitude, phase)} of each driven electrode driven alone (app/harmonic.py), as Y or Z."""
    out = {}
    for name in _drive_of(harmonic):
        magnitude = harmonic.get(f"admittance_{name}_alone_magnitude_S")
        phase = harmonic.get(f"admittance_{name}_alone_phase_deg")
        if magnitude is not None and phase is not None:
            magnitude, phase = np.asarray(magnitude, dtype=float), np.asarray(phase, dtype=float)
            out[name] = (1.0 / magnitude, -phase) if impedance else (magnitude, phase)
    return out


def impedance_plot(path: Path, harmonic: dict, f_r: float | None, f_a: float | None, circuit: dict | None = None,
                   title: str = ""):
    """|Z| = 1/|Y| in ohm and phase(Z) = -phase(Y): the curve impedance analysers show."""
    f = np.array(harmonic["frequency_Hz"])
    fine, y = _circuit_curve(circuit, f)
    _frequency_plot(path, f, 1.0 / np.array(harmonic["admittance_magnitude_S"]),
                    -np.array(harmonic["admittance_phase_deg"]), fine, None if y is None else 1.0 / y,
                    f_r, f_a, "Z", "Ω", title, harmonic, _alone(harmonic, impedance=True))


def frequency_domain_outputs(out: Path, results: dict, plots: bool = True, title: str = "") -> list[str]:
    """Tables and plots of the modal and harmonic results (rank 0): modes.csv, harmonic.csv,
    admittance.png, impedance.png. Used by ``run`` and by ``piezodyn plot DIR``. Returns the file names."""
    out = Path(out)
    written = []
    modal = results.get("modal")
    f_r = modal.get("working_resonance_Hz") if modal else None
    f_a = modal.get("working_antiresonance_Hz") if modal else None
    if modal and modal.get("modes"):
        write_mode_table(out / "modes.csv", modal)
        written.append("modes.csv")
    harmonic = results.get("harmonic")
    if harmonic and harmonic.get("frequency_Hz"):
        write_harmonic_table(out / "harmonic.csv", harmonic)
        written.append("harmonic.csv")
        if plots:
            admittance_plot(out / "admittance.png", harmonic, f_r, f_a, results.get("circuit"), title)
            impedance_plot(out / "impedance.png", harmonic, f_r, f_a, results.get("circuit"), title)
            written += ["admittance.png", "impedance.png"]
    return written


MOTION_AXIS = "axial displacement [mm]"
FORCE_AXIS = "contact force [N]"
TIME_AXIS = "time [ms]"


def time_series_curves(data: dict[str, np.ndarray], point: str | None, bodies: list[str],
                       contacts: list[str]) -> dict[str, list[tuple[str, np.ndarray]]]:
    """The curves of the time-series plots of every tier, from a time series under the names of
    app/series.py: ``motion``: (label, mm) of the drive point's displacement and of each body's
    vertical rise from its start; ``force``: (label, N) of each contact's force magnitude."""
    from app import series as S

    motion = []
    if point and S.point_displacement(point) in data:
        motion.append((f"transducer {point}", data[S.point_displacement(point)] * 1e3))
    for body in bodies:
        if S.body_position(body) in data:
            z = data[S.body_position(body)][:, -1]
            motion.append((f"{body} (from its start)", (z - z[0]) * 1e3))
    force = [(contact, np.linalg.norm(data[S.contact_force(contact)], axis=1))
             for contact in contacts if S.contact_force(contact) in data]
    return {"motion": motion, "force": force}


def plot_time_series(h5_path: Path, out_dir: Path, point: str | None, bodies: list[str], contacts: list[str],
                     title: str = "") -> list[str]:
    """The time-series plots of every tier (:func:`time_series_curves`): the motion (Fig. 7/9/12-like)
    and the contact forces (Fig. 5-like: one panel per contact), both titled ``title``. Returns the
    file names written into ``out_dir``."""
    from app import series as S

    out_dir = Path(out_dir)
    data = S.read_time_series(h5_path)
    if S.TIME not in data:
        return []
    t_ms = data[S.TIME] * 1e3
    curves = time_series_curves(data, point, bodies, contacts)
    fig, ax = plt.subplots(figsize=(8, 4))
    for i, (label, values) in enumerate(curves["motion"]):
        ax.plot(t_ms, values, ":" if i == 0 and point else "-", lw=0.8, label=label)
    ax.set_xlabel(TIME_AXIS)
    ax.set_ylabel(MOTION_AXIS)
    ax.set_title(f"{title}: displacements" if title else "displacements")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_dir / S.MOTION_PLOT, dpi=120)
    plt.close(fig)
    written = [S.MOTION_PLOT]
    if curves["force"]:
        n = len(curves["force"])
        fig, axes = plt.subplots(n, 1, figsize=(8, 1.2 + 1.8 * n), sharex=True, squeeze=False)
        for ax, (label, values) in zip(axes[:, 0], curves["force"]):
            ax.plot(t_ms, values, lw=0.8)
            ax.set_ylabel(f"{label} [N]")
            ax.grid(alpha=0.3)
        axes[-1, 0].set_xlabel(TIME_AXIS)
        axes[0, 0].set_title(f"{title}: {FORCE_AXIS}" if title else FORCE_AXIS)
        fig.tight_layout()
        fig.savefig(out_dir / S.FORCE_PLOT, dpi=120)
        plt.close(fig)
        written.append(S.FORCE_PLOT)
    return written


def time_series_outputs(out_dir: Path, results: dict) -> list[str]:
    """The time-series plots of a tier's results (``results["plot"]`` says what to draw: drive point,
    bodies, contacts, title). The scene's own plots: app/report.py."""
    spec = results.get("plot")
    series = Path(out_dir) / results["time_series"] if results.get("time_series") else None
    if not spec or series is None or not series.is_file():
        return []
    return plot_time_series(series, out_dir, spec.get("point"), spec.get("bodies", []), spec.get("contacts", []),
                            spec.get("title", ""))
