"""Drill-scene statistics with 95 % confidence intervals, per tier, from batch means.

The impact motion is chaotic, so tiers are compared by statistics, not trajectories. One long run
per tier and downforce is cut into ``--batches`` equal windows (after a ``--skip-ms`` start-up);
each statistic (impact rates per contact, mean rock force, power into the rock) is computed per
window with the same code as the run's own summary (app.transient.impacts.run_statistics); the
transducer rise is the window's mean drive-point displacement above its mean over the first drive
period of the run (a largest rise is not a batch statistic: it grows with the window). The 95 %
interval of each is mean +- t_{0.975, B-1} s / sqrt(B).
Batch means assume windows long against the motion's correlation time (here ~ a few ms against
100 ms windows).

Tiers: ``modal`` runs here (cases/usdc-fe.toml with tier = "modal"); ``fe`` reads finished FE-tier
runs (``--fe-dir FORCE=DIR``, e.g. from ``piezodyn run cases/usdc-fe.toml --set
transient.end_time_s=1.0 ...``), whose intervals are the yardstick for the modal tier.

    .venv/bin/python bench/bench_tier_statistics.py --seconds 1.0 --forces 0,3,6,9 [--fe-dir 9=DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats as sps

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app import series as S  # noqa: E402
from app.case.schema import load_case  # noqa: E402
from app.transient.impacts import run_statistics  # noqa: E402

CASE = ROOT / "cases" / "usdc-fe.toml"
KEYS = {
    "tip-ball impacts/s": lambda s: s["impact_rate_per_s"]["tip_ball"],
    "ball-stem impacts/s": lambda s: s["impact_rate_per_s"]["ball_stem"],
    "stem-rock impacts/s": lambda s: s["impact_rate_per_s"]["stem_rock"],
    "mean rock force [N]": lambda s: s["stem_rock_foundation"]["mean_force_N"],
    "power into rock [W]": lambda s: s["stem_rock_foundation"]["mean_power_W"],
}
RISE = "mean transducer rise [mm]"


def _force_set(force_N: float) -> str:
    return f"transient.loads.fe_force_N=[0.0,{-force_N!r}]"


def batch_statistics(h5_path: Path, force_N: float, batches: int, skip_s: float) -> dict[str, tuple]:
    """{statistic: (mean, half-width of the 95 % interval)} over equal windows of the run."""
    case = load_case(CASE, [_force_set(force_N)])
    cfg = case.transient
    data = S.read_time_series(h5_path)
    t = data[S.TIME]
    edges = np.linspace(skip_s, t[-1], batches + 1)
    values = {key: [] for key in [*KEYS, RISE]}
    tip = data[S.point_displacement(cfg.drive.point)]
    start = float(np.mean(tip[t <= t[0] + 1.0 / cfg.drive.frequency_Hz]))
    for lo, hi in zip(edges[:-1], edges[1:]):
        rows = (t > lo) & (t <= hi)
        window = {name: array[rows] for name, array in data.items()}
        s = run_statistics(window, cfg, case.scene)
        for key, get in KEYS.items():
            values[key].append(get(s))
        dt = window[S.STEP]
        mean_tip = float(np.sum(window[S.point_displacement(cfg.drive.point)] * dt) / np.sum(dt))
        values[RISE].append(1e3 * (mean_tip - start))
    t_crit = sps.t.ppf(0.975, batches - 1)
    return {key: (float(np.mean(v)), float(t_crit * np.std(v, ddof=1) / np.sqrt(batches))) for key, v in
            values.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time per run [s]")
    parser.add_argument("--forces", default="0,3,6,9", help="downforces [N]")
    parser.add_argument("--batches", type=int, default=10)
    parser.add_argument("--skip-ms", type=float, default=5.0, help="start-up left out [ms]")
    parser.add_argument("--fe-dir", action="append", default=[], metavar="FORCE=DIR", help="a finished FE-tier run")
    args = parser.parse_args()
    fe_dirs = {float(k): Path(v) for k, v in (item.split("=", 1) for item in args.fe_dir)}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for force in [float(f) for f in args.forces.split(",")]:
            out = Path(tmp) / f"modal_{force:g}N"
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "app", "run", str(CASE), "--out", str(out), "--quiet",
                            "--set", 'tier="modal"', "--set", f"transient.end_time_s={args.seconds}",
                            "--set", "output.fields=false", "--set", "output.plots=false",
                            "--set", _force_set(force)], check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
            wall = time.perf_counter() - start
            per_ms = json.loads((out / "summary.json").read_text())["results"]["transient"]["wall_s_per_simulated_ms"]
            rows.append((force, f"modal ({args.seconds:g} s, {wall:.0f} s wall, {per_ms:.3f} s/ms)",
                         batch_statistics(out / S.TIME_SERIES_FILE, force, args.batches, args.skip_ms * 1e-3)))
            if force in fe_dirs:
                summary = json.loads((fe_dirs[force] / "summary.json").read_text())["results"]["transient"]
                fe_h5 = fe_dirs[force] / summary["time_series"]
                rows.append((force, f"FE ({summary['simulated_time_s']:g} s)",
                             batch_statistics(fe_h5, force, args.batches, args.skip_ms * 1e-3)))
    print(f"# batch means, {args.batches} windows, 95 % intervals, {time.strftime('%Y-%m-%d')}")
    print("| downforce | tier | " + " | ".join([*KEYS, RISE]) + " |")
    print("|---|---|" + "---|" * (len(KEYS) + 1))
    for force, tier, values in rows:
        cells = [f"{m:.3g} ± {h:.2g}" for m, h in values.values()]
        print(f"| {force:g} N | {tier} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
