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

Tiers: ``modal`` (cases/usdc-fe.toml with tier = "modal") and ``lumped`` (its lumped model,
cases/usdc-lumped-fe-scene.toml) run here; ``fe`` reads finished FE-tier runs (``--fe-dir
FORCE=DIR``, repeatable, also several per force, e.g. from ``piezodyn run cases/usdc-fe.toml --set
transient.end_time_s=1.0 ...``), whose intervals are the yardstick: every modal and lumped
statistic is flagged "in" or "OUT" of the FE interval at its force (its mean inside FE mean +-
half-width of the longest FE run), and the lumped ones outside are listed under the table.
``--keep-dir DIR`` keeps the run directories (DIR/modal1s_9N, DIR/lumped1s_9N, ...) and reuses
finished ones, so the table can be made again when the FE runs finish without re-running the rest.

    .venv/bin/python bench/bench_tier_statistics.py --seconds 1.0 --forces 0,3,6,9 --keep-dir DIR \
        [--fe-dir 0=DIR0 --fe-dir 9=DIR9 ...]
    # against the FE intervals published in BENCHMARKS.md (the FE runs' directories not at hand):
    .venv/bin/python bench/bench_tier_statistics.py --seconds 1.0 --forces 0,9 --tiers modal \
        --fe-published BENCHMARKS.md
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app import series as S  # noqa: E402
from app.case.schema import load_case  # noqa: E402
from app.intervals import half_width_95  # noqa: E402
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
        s = run_statistics(window, cfg)
        for key, get in KEYS.items():
            values[key].append(get(s))
        dt = window[S.STEP]
        mean_tip = float(np.sum(window[S.point_displacement(cfg.drive.point)] * dt) / np.sum(dt))
        values[RISE].append(1e3 * (mean_tip - start))
    return {key: (float(np.mean(v)), half_width_95(v)) for key, v in values.items()}


LUMPED_CASE = ROOT / "cases" / "usdc-lumped-fe-scene.toml"


def lumped_batch_statistics(force_N: float, seconds: float, batches: int, skip_s: float) -> dict[str, tuple]:
    """As :func:`batch_statistics` for the lumped tier, from its exact event table instead of samples
    (its time series is 1D and sampled every 10 us, too coarse for microsecond contacts): impacts
    are the closing events in a window, the rock force the impulse of the stem-rock contacts ending
    in it, the power into the rock the window's increment of the rock work (ledger + layer energy,
    app.lumped.stats) from runs ending at the window edges (the run is deterministic: a shorter run
    is the longer one's prefix, checked on the event count), the rise the window's mean transducer
    coordinate above its mean over the first drive period."""
    from app.lumped import kernel as K
    from app.lumped.driver import compute
    from app.lumped.model import ID3
    from app.lumped.outputs import BODIES
    from app.lumped.parameters import CONTACT_NAMES

    def simulate(duration_s):
        case = load_case(LUMPED_CASE, [f"lumped.downforce_N={force_N!r}", f"lumped.duration_s={duration_s!r}"])
        return compute(case.lumped)[1], case

    def rock_work(result) -> float:
        k = result.parameters.contacts[2].stiffness_N_per_m
        return result.ledger_J["stem_rock"] + 0.5 * k * (result.final_y[ID3] ** 2 - result.initial_y[ID3] ** 2)

    full, case = simulate(seconds)
    ev = full.events
    closing = ev[:, K.EV_CLOSING] == 1.0
    edges = np.linspace(skip_s, seconds, batches + 1)
    work = []
    for edge in edges:
        prefix = full if edge >= seconds else simulate(float(edge))[0]
        if prefix.events.shape[0] != int(np.sum(ev[:, K.EV_TIME] <= edge)) and prefix is not full:
            raise RuntimeError(f"lumped run to {edge} s is not the prefix of the {seconds} s run")
        work.append(rock_work(prefix))
    t = full.samples_t_s
    z = full.samples_y[:, BODIES["transducer"][0]]
    start = float(np.mean(z[t <= t[0] + 1.0 / case.lumped.drive.frequency_Hz]))
    names = {name: i for i, name in enumerate(CONTACT_NAMES)}
    values = {key: [] for key in [*KEYS, RISE]}
    for j, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        inside = (ev[:, K.EV_TIME] > lo) & (ev[:, K.EV_TIME] <= hi)
        width = hi - lo
        for contact in ("tip_ball", "ball_stem", "stem_rock"):
            values[f"{contact.replace('_', '-')} impacts/s"].append(
                np.sum(inside & closing & (ev[:, K.EV_CONTACT] == names[contact])) / width)
        rock_ends = inside & ~closing & (ev[:, K.EV_CONTACT] == names["stem_rock"])
        values["mean rock force [N]"].append(float(np.sum(ev[rock_ends, K.EV_IMPULSE])) / width)
        values["power into rock [W]"].append((work[j + 1] - work[j]) / width)
        rows = (t > lo) & (t <= hi)
        values[RISE].append(1e3 * (float(np.mean(z[rows])) - start))
    return {key: (float(np.mean(v)), half_width_95(v)) for key, v in values.items()}


def _run(tier: str, force: float, seconds: float, out: Path) -> float:
    """Run one tier into ``out`` unless a finished run is there; -> wall s per simulated ms."""
    summary = out / "summary.json"
    if not summary.exists():
        if tier == "modal":
            settings = ['tier="modal"', f"transient.end_time_s={seconds}", "output.fields=false",
                        "output.plots=false", "transient.checkpoint_interval_steps=0", _force_set(force)]
            case = CASE
        else:
            settings = [f"lumped.duration_s={seconds!r}", f"lumped.downforce_N={force!r}", "lumped.output.plots=false"]
            case = LUMPED_CASE
        command = [sys.executable, "-m", "app", "run", str(case), "--out", str(out), "--quiet"]
        for item in settings:
            command += ["--set", item]
        subprocess.run(command, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    results = json.loads(summary.read_text())["results"]
    results = results.get("transient", results.get("lumped", results))
    return results["wall_s_per_simulated_ms"]


def _verdict(value: tuple, reference: tuple | None) -> str:
    """" in" when the mean lies in the FE interval; " OUT" otherwise, " OUT (overlap)" when the two
    intervals still overlap: two runs of the same chaotic process put one mean outside the other's
    95 % interval about one time in six (the difference has twice the variance), so an OUT with
    overlapping intervals is weak evidence of a difference."""
    if reference is None:
        return ""
    difference = abs(value[0] - reference[0])
    if difference <= reference[1]:
        return " in"
    return " OUT (overlap)" if difference <= reference[1] + value[1] else " OUT"


PUBLISHED_SECTION = "## Drill-scene statistics with 95 % intervals: FE, modal and lumped tiers (issue 9)"


def published_fe_rows(path: Path) -> dict[float, tuple[str, dict[str, tuple]]]:
    """The FE tier's rows of the issue-9 table in BENCHMARKS.md (``| 9 N | FE (1 s, fe1s_9N) | 1.34e+03 ± 96 |
    ...``): force -> (label, {statistic: (mean, half-width)}), the longest FE run per force. For a table against
    the published FE intervals when the FE runs' directories are not at hand (a 1 s FE run costs hours)."""
    out: dict[float, tuple[str, dict, float]] = {}
    text = path.read_text()
    section = text[text.index(PUBLISHED_SECTION):]
    section = section[:section.find("\n## ", 1)]
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 2 + len(KEYS) + 1 or not cells[1].startswith("FE (") or not cells[0].endswith(" N"):
            continue
        force, seconds = float(cells[0][:-2]), float(cells[1][4:].split(" s")[0])
        values = {}
        for key, cell in zip([*KEYS, RISE], cells[2:]):
            mean, half = cell.split("±")
            values[key] = (float(mean), float(half))
        if force not in out or seconds > out[force][2]:
            out[force] = (f"{cells[1]}, published", values, seconds)
    return {force: (label, values) for force, (label, values, _) in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="simulated time per run [s]")
    parser.add_argument("--forces", default="0,3,6,9", help="downforces [N]")
    parser.add_argument("--tiers", default="modal,lumped", help="tiers run here (modal, lumped)")
    parser.add_argument("--batches", type=int, default=10)
    parser.add_argument("--skip-ms", type=float, default=5.0, help="start-up left out [ms]")
    parser.add_argument("--fe-dir", action="append", default=[], metavar="FORCE=DIR",
                        help="a finished FE-tier run (repeatable, several per force allowed)")
    parser.add_argument("--fe-published", type=Path, default=None, metavar="BENCHMARKS.md",
                        help="the FE rows of the issue-9 table there as the yardstick (where no --fe-dir is given)")
    parser.add_argument("--keep-dir", type=Path, default=None,
                        help="keep (and reuse) the run directories here: <tier><seconds>s_<force>N")
    args = parser.parse_args()
    fe_dirs: dict[float, list[Path]] = {}
    for item in args.fe_dir:
        force, directory = item.split("=", 1)
        fe_dirs.setdefault(float(force), []).append(Path(directory))
    tiers = [t for t in args.tiers.split(",") if t]
    skip = args.skip_ms * 1e-3
    rows = []
    outside: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        base = args.keep_dir if args.keep_dir is not None else Path(tmp)
        base.mkdir(parents=True, exist_ok=True)
        for force in [float(f) for f in args.forces.split(",")]:
            reference, reference_s = None, 0.0
            if args.fe_published is not None and not fe_dirs.get(force):
                published = published_fe_rows(args.fe_published).get(force)
                if published is not None:
                    rows.append((force, published[0], published[1], None))
                    reference = published[1]
            for directory in fe_dirs.get(force, []):
                summary = json.loads((directory / "summary.json").read_text())["results"]["transient"]
                values = batch_statistics(directory / summary["time_series"], force, args.batches, skip)
                seconds = summary["simulated_time_s"]
                rows.append((force, f"FE ({seconds:g} s, {directory.name})", values, None))
                if seconds > reference_s:       # the longest FE run is the yardstick
                    reference, reference_s = values, seconds
            for tier in tiers:
                out = base / f"{tier}{args.seconds:g}s_{force:g}N"
                start = time.perf_counter()
                per_ms = _run(tier, force, args.seconds, out)
                wall = time.perf_counter() - start
                values = (batch_statistics(out / S.TIME_SERIES_FILE, force, args.batches, skip) if tier == "modal"
                          else lumped_batch_statistics(force, args.seconds, args.batches, skip))
                rows.append((force, f"{tier} ({args.seconds:g} s, {per_ms:.3g} s/ms)", values, reference))
                if tier == "lumped" and reference is not None:
                    outside += [f"{force:g} N: lumped {key} = {values[key][0]:.3g} outside the FE interval "
                                f"{reference[key][0]:.3g} ± {reference[key][1]:.2g}"
                                for key in values if _verdict(values[key], reference[key]).startswith(" OUT")]
                print(f"# {tier} {force:g} N: {wall:.0f} s wall here", file=sys.stderr, flush=True)
    print(f"# batch means, {args.batches} windows after {args.skip_ms:g} ms, 95 % intervals (t, B-1 dof), "
          f"{time.strftime('%Y-%m-%d')}; in/OUT: mean inside the FE interval of the longest FE run at that force")
    print("| downforce | tier | " + " | ".join([*KEYS, RISE]) + " |")
    print("|---|---|" + "---|" * (len(KEYS) + 1))
    for force, tier, values, reference in rows:
        cells = [f"{m:.3g} ± {h:.2g}" + _verdict((m, h), reference[key] if reference else None)
                 for key, (m, h) in values.items()]
        print(f"| {force:g} N | {tier} | " + " | ".join(cells) + " |")
    with_fe = {f"{f:g} N" for f, tier, *_ in rows if tier.startswith("FE")}
    without = sorted({f"{f:g} N" for f, *_ in rows} - with_fe)
    if without:
        print(f"\nNo FE run given at {', '.join(without)}: no in/OUT flags there.")
    if outside:
        print("\nLumped tier outside the FE interval (its mean outside the FE 95 % interval):\n"
              + "\n".join(f"- {line}" for line in outside))


if __name__ == "__main__":
    main()
