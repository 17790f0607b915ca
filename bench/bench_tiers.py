"""Speed against error between the tiers of the drill scene: full transient FE (cases/usdc-fe.toml)
and the lumped model of the same scene (cases/usdc-lumped-fe-scene.toml), at 0/3/6/9 N downforce.

The FE runs are long (minutes per 200 ms), so they are read from their output directories (run
them first, e.g. ``piezodyn run cases/usdc-fe.toml --out /tmp/drill_3N --set
'transient.loads.fe_force_N=[0.0,-3.0]'``); the lumped runs are done here, in the same process.
Both tiers report the same statistics under the same keys (app/series.py, app/transient/impacts.py,
app/lumped/stats.py, app/scenes/percussion_drill.py), read by one function (``row``) for both; the
table gives each tier's value and the lumped tier's deviation from the FE tier. The motion is
chaotic, so the deviations are those of statistics over the window, not of trajectories.

    /work/main/.venv/bin/python bench/bench_tiers.py --fe-dir 0=/tmp/drill_0N --fe-dir 3=/tmp/drill_3N ...
        [--plot-dir DIR]

``--fe-dir`` may repeat a downforce: FE runs that differ only in round-off (e.g. two solver versions)
show the run-to-run spread of a 200 ms statistic of this chaotic motion, the yardstick for the
tiers' differences. ``--plot-dir`` also writes the FE runs as the drill paper's figures: ``fig9_displacements.png``
(tip, free mass and stem displacement, one panel per downforce) and ``fig5_rock_force.png``
(stem/rock contact force, one panel per downforce).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app import series as S  # noqa: E402
from app.case.schema import load_case  # noqa: E402
from app.lumped.driver import compute  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def row(results: dict) -> dict:
    """One table row from a tier's results (summary.json ``results.transient`` of an FE run, or the
    lumped tier's results): every tier reports under the same keys (app/series.py), so no mapping."""
    stats = results["statistics"]
    rates = stats["impact_rate_per_s"]
    rock = stats["stem_rock_foundation"]
    return {"wall_s_per_ms": results["wall_s_per_simulated_ms"], "simulated_ms": results["simulated_time_s"] * 1e3,
            "cutbacks": results["cutbacks"],
            "tip_ball_per_s": rates["tip_ball"], "ball_stem_per_s": rates["ball_stem"],
            "stem_rock_per_s": rates["stem_rock"],
            "rock_power_W": rock["mean_power_W"], "rock_force_N": rock["mean_force_N"],
            "rock_impulse_N_s": rock["impulse_per_impact_mean_N_s"],
            "max_rise_mm": stats["transducer"]["max_rise_m"] * 1e3,
            "flights_per_s": stats["transducer"]["flight_rate_per_s"]}


def fe_row(directory: Path) -> dict:
    return row(json.loads((directory / "summary.json").read_text())["results"]["transient"])


def lumped_row(force_N: float, duration_s: float) -> dict:
    case = load_case(ROOT / "cases" / "usdc-lumped-fe-scene.toml",
                     [f"lumped.downforce_N={force_N!r}", f"lumped.duration_s={duration_s!r}"])
    return row(compute(case.lumped)[0])


COLUMNS = [("wall_s_per_ms", "wall s / sim. ms", "{:.3g}"), ("tip_ball_per_s", "tip-ball impacts/s", "{:.0f}"),
           ("ball_stem_per_s", "ball-stem impacts/s", "{:.0f}"), ("stem_rock_per_s", "stem-rock impacts/s", "{:.0f}"),
           ("rock_power_W", "power into rock [W]", "{:.3f}"), ("rock_force_N", "mean rock force [N]", "{:.2f}"),
           ("rock_impulse_N_s", "impulse / rock impact [mN s]", "{:.2f}"),
           ("max_rise_mm", "max transducer rise [mm]", "{:.2f}"), ("flights_per_s", "flights/s", "{:.0f}")]


def plot_figures(fe_dirs: dict[float, Path], out: Path) -> list[Path]:
    import h5py
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    forces = sorted(fe_dirs)
    fig9, axes9 = plt.subplots(len(forces), 1, figsize=(8, 2.4 * len(forces)), sharex=True, squeeze=False)
    fig5, axes5 = plt.subplots(len(forces), 1, figsize=(8, 1.8 * len(forces)), sharex=True, squeeze=False)
    for row_index, force in enumerate(forces):
        with h5py.File(fe_dirs[force] / S.TIME_SERIES_FILE, "r") as f:
            t_ms = f[S.TIME][:] * 1e3
            ax = axes9[row_index, 0]
            ax.plot(t_ms, f[S.point_displacement("tip")][:] * 1e3, ":", lw=0.8, label="transducer tip")
            for body, style in (("ball", "-"), ("stem", "--")):
                z = f[S.body_position(body)][:, -1]
                ax.plot(t_ms, (z - z[0]) * 1e3, style, lw=0.8, label=f"{body} (from its start)")
            ax.set_ylabel("disp. [mm]")
            ax.set_title(f"{force:g} N downforce", fontsize=9)
            axes5[row_index, 0].plot(t_ms, np.linalg.norm(f[S.contact_force("stem_rock")][:], axis=1), lw=0.6)
            axes5[row_index, 0].set_ylabel("force [N]")
            axes5[row_index, 0].set_title(f"{force:g} N downforce", fontsize=9)
    axes9[0, 0].legend(fontsize=8, loc="upper right")
    axes9[-1, 0].set_xlabel("time [ms]")
    axes5[-1, 0].set_xlabel("time [ms]")
    paths = [out / "fig9_displacements.png", out / "fig5_rock_force.png"]
    for fig, path in zip((fig9, fig5), paths):
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return paths


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--fe-dir", action="append", default=[], help="FORCE=DIR of a finished FE run")
    parser.add_argument("--duration-s", type=float, default=0.2, help="lumped window (the FE runs' length)")
    parser.add_argument("--plot-dir", type=Path, help="write Fig. 9 / Fig. 5-like plots of the FE runs here")
    args = parser.parse_args()
    fe_dirs: dict[float, list[Path]] = {}
    for item in args.fe_dir:
        key, value = item.split("=", 1)
        fe_dirs.setdefault(float(key), []).append(Path(value))
    if args.plot_dir and fe_dirs:
        for path in plot_figures({k: v[0] for k, v in fe_dirs.items()}, args.plot_dir):
            print(f"wrote {path}")
    forces = sorted(fe_dirs) or [0.0, 3.0, 6.0, 9.0]
    print("| downforce | tier | " + " | ".join(c[1] for c in COLUMNS) + " |")
    print("|---|---|" + "---|" * len(COLUMNS))

    def cells_of(values):
        return [fmt.format(values[key] * (1e3 if key == "rock_impulse_N_s" else 1)) for key, _, fmt in COLUMNS]

    for force in forces:
        lumped = lumped_row(force, args.duration_s)
        fe_runs = [fe_row(d) for d in fe_dirs.get(force, [])]
        for fe in fe_runs:
            tier = f"FE ({fe['simulated_ms']:.0f} ms, {fe['cutbacks']} cut-backs)"
            print(f"| {force:g} N | {tier} | " + " | ".join(cells_of(fe)) + " |")
        print(f"| {force:g} N | lumped | " + " | ".join(cells_of(lumped)) + " |")
        if not fe_runs:
            continue
        mean = {key: float(np.mean([fe[key] for fe in fe_runs])) for key, _, _ in COLUMNS}
        cells = []
        for key, _, _ in COLUMNS:
            if key == "wall_s_per_ms":
                cells.append(f"{mean[key] / lumped[key]:.0f}x faster")
            else:
                cells.append(f"{(lumped[key] - mean[key]) / mean[key]:+.0%}" if mean[key] else "n/a")
        label = "lumped vs FE" + (f" (mean of {len(fe_runs)})" if len(fe_runs) > 1 else "")
        print(f"| {force:g} N | {label} | " + " | ".join(cells) + " |")
        if len(fe_runs) > 1:
            # The motion is chaotic: runs that differ only in round-off (solver version) give the
            # spread of a 200 ms statistic, the yardstick for the tiers' differences.
            cells = ["-"]
            for key, _, _ in COLUMNS[1:]:
                half_range = (max(fe[key] for fe in fe_runs) - min(fe[key] for fe in fe_runs)) / 2
                cells.append(f"±{half_range / abs(mean[key]):.0%}" if mean[key] else "n/a")
            print(f"| {force:g} N | FE run-to-run spread | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
