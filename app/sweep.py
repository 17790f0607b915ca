"""``piezodyn sweep CASE --param lumped.key=v1,v2 ... [--out DIR]``: a parameter grid of a lumped case.

Every grid point is the case with ``--set`` overrides and one value per ``--param``; all points are
validated (on every rank) before any runs, so a bad value or unknown name fails at once with a
CaseError. Points are dealt round-robin to MPI ranks; each rank runs its points serially
(``COMM_SELF``), writing ``DIR/point_NNNN/summary.json`` (+ time series and plots if the case asks
for them). Rank 0 shows a progress bar and writes ``DIR/sweep.csv`` (the table: parameters and
results, deterministic, independent of the number of ranks), ``DIR/sweep.json`` (the same plus wall
times) and one PNG per swept parameter.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import platform
import sys
import time
from pathlib import Path

from app.case.loader import apply_overrides, parse_override, read_toml
from app.case.validate import from_dict, to_dict
from app.errors import CaseError, NumericalFailure

TAG_PROGRESS = 11
TAG_ROWS = 12

# (column, path into results["statistics"] or results)
TABLE_COLUMNS = (
    ("impact_rate_tip_ball_per_s", ("statistics", "impact_rate_per_s", "tip_ball")),
    ("impact_rate_ball_stem_per_s", ("statistics", "impact_rate_per_s", "ball_stem")),
    ("impact_rate_stem_rock_per_s", ("statistics", "impact_rate_per_s", "stem_rock")),
    ("rock_impulse_per_impact_mean_N_s", ("statistics", "rock", "impulse_per_impact_mean_N_s")),
    ("rock_energy_per_impact_mean_J", ("statistics", "rock", "energy_per_impact_mean_J")),
    ("rock_mean_power_W", ("statistics", "rock", "mean_power_W")),
    ("rock_mean_force_N", ("statistics", "rock", "mean_force_N")),
    ("transducer_max_flight_height_m", ("statistics", "transducer", "max_flight_height_m")),
    ("flight_rate_per_s", ("statistics", "transducer", "flight_rate_per_s")),
    ("flight_duration_mean_s", ("statistics", "transducer", "flight_duration_mean_s")),
    ("free_mass_impact_rate_per_s", ("statistics", "free_mass", "impact_rate_per_s")),
    ("free_mass_rms_velocity_m_per_s", ("statistics", "free_mass", "rms_velocity_m_per_s")),
    ("electrical_input_power_W", None),
    ("energy_closure_relative", ("energy_ledger", "closure_relative")),
    ("contact_events", ("solver", "events")),
)
PLOT_COLUMNS = (
    "transducer_max_flight_height_m",
    "flight_rate_per_s",
    "free_mass_impact_rate_per_s",
    "rock_mean_power_W",
    "rock_impulse_per_impact_mean_N_s",
    "impact_rate_stem_rock_per_s",
)


def parse_param(text: str) -> tuple[str, list]:
    """``lumped.a.b=1,2,3`` -> ("lumped.a.b", [1, 2, 3]); each value is read as a TOML value."""
    if "=" not in text:
        raise CaseError("--param", text, "expected dotted.key=value1,value2,...")
    key, raw = text.split("=", 1)
    key = key.strip()
    values = []
    for item in raw.split(","):
        if not item.strip():
            raise CaseError("--param", key, f"empty value in {raw!r}")
        values.append(parse_override(f"{key}={item}")[1])
    if not key.startswith("lumped.") or len(key.split(".")) < 2:
        raise CaseError(
            "--param",
            key,
            "unknown sweep parameter: sweep parameters live under [lumped], "
            "e.g. lumped.downforce_N or lumped.free_mass.mass_kg",
        )
    return key, values


def build_points(
    case_path: str | Path, params: list[tuple[str, list]], sets: list[str] | None = None
) -> list[dict]:
    """Validate every grid point; returns [{index, values: {key: value}, section}] in grid order."""
    from app.lumped.schema import LumpedSection

    case_path = str(case_path)
    base = read_toml(case_path)
    if base.get("tier", "lumped") != "lumped":
        raise CaseError(
            case_path, "tier", f"sweep runs lumped cases; this case has tier = {base.get('tier')!r}"
        )
    keys = [k for k, _ in params]
    if len(set(keys)) != len(keys):
        raise CaseError("--param", keys[0], "a parameter is swept twice")
    points = []
    for index, combo in enumerate(itertools.product(*[v for _, v in params])):
        values = dict(zip(keys, combo))
        overrides = list(sets or []) + [f"{k}={_toml_value(v)}" for k, v in values.items()]
        raw = apply_overrides(base, overrides)
        if not isinstance(raw.get("lumped"), dict):
            raise CaseError(case_path, "lumped", "the case has no [lumped] table")
        section = from_dict(LumpedSection, raw["lumped"], case_path, "lumped")
        points.append({"index": index, "values": values, "overrides": overrides, "section": section})
    return points


def _toml_value(value) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value)


def _lookup(results: dict, path):
    node = results
    for part in path:
        node = node[part]
    return node


def table_row(point: dict, results: dict) -> dict:
    row = {"point": point["index"], **point["values"]}
    for column, path in TABLE_COLUMNS:
        if path is None:  # electrical input power
            ledger = results["energy_ledger"]
            row[column] = ledger["electrical_input_J"] / results["statistics"]["simulated_time_s"]
        else:
            row[column] = _lookup(results, path)
    return row


def _json_default(obj):
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _versions() -> dict:
    import numpy
    import scipy

    import app

    out = {
        "piezodyn": app.__version__,
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
    }
    try:
        import numba

        out["numba"] = numba.__version__
    except ImportError:  # pragma: no cover - numba is a hard dependency of the kernel
        pass
    return out


def run_point(case_path: str, point: dict, out_dir: Path) -> dict:
    """Run one grid point serially; writes point_dir/summary.json; returns the table row."""
    from app.lumped.driver import run

    point_dir = out_dir / f"point_{point['index']:04d}"
    wall0 = time.perf_counter()
    results = run(point["section"], point_dir, comm=None, log=lambda msg: None)
    wall = time.perf_counter() - wall0
    summary = {
        "case": case_path,
        "overrides": point["overrides"],
        "resolved_case": {"tier": "lumped", "lumped": to_dict(point["section"])},
        "versions": _versions(),
        "mpi_size": 1,
        "wall_s": {"total": wall},
        "results": results,
    }
    point_dir.mkdir(parents=True, exist_ok=True)
    (point_dir / "summary.json").write_text(json.dumps(summary, indent=1, default=_json_default))
    row = table_row(point, results)
    row["_wall_s"] = wall
    return row


def run_sweep(case_path, params, out_dir, sets=None, comm=None, progress=True) -> list[dict] | None:
    """Run the grid; returns the rows (sorted by point) on rank 0, None elsewhere."""
    case_path = str(case_path)
    out_dir = Path(out_dir)
    rank = comm.Get_rank() if comm is not None else 0
    size = comm.Get_size() if comm is not None else 1
    points = build_points(case_path, params, sets)  # every rank validates: errors surface everywhere
    mine = [pt for pt in points if pt["index"] % size == rank]
    bar = None
    if rank == 0 and progress:
        from tqdm import tqdm

        bar = tqdm(total=len(points), desc="sweep", unit="point", file=sys.stderr)
    rows = []
    done_elsewhere = 0
    failure = None
    for point in mine:
        try:
            rows.append(run_point(case_path, point, out_dir))
        except NumericalFailure as exc:  # keep the sweep going; report the point
            failure = failure or exc
            rows.append({"point": point["index"], **point["values"], "_failed": str(exc)})
        if rank == 0:
            if bar:
                bar.update(1)
            done_elsewhere += _drain_progress(comm, bar)
        elif comm is not None:
            comm.send(1, dest=0, tag=TAG_PROGRESS)
    if rank == 0 and comm is not None:
        expected = len(points) - len(mine)
        while done_elsewhere < expected:
            comm.recv(source=MPI_ANY_SOURCE(), tag=TAG_PROGRESS)
            done_elsewhere += 1
            if bar:
                bar.update(1)
    if bar:
        bar.close()
    if comm is not None and size > 1:
        gathered = comm.gather(rows, root=0)
        if rank != 0:
            return None
        rows = [r for part in gathered for r in part]
    rows.sort(key=lambda r: r["point"])
    write_table(rows, [k for k, _ in params], out_dir, case_path)
    return rows


def MPI_ANY_SOURCE():
    from mpi4py import MPI

    return MPI.ANY_SOURCE


def _drain_progress(comm, bar) -> int:
    if comm is None or comm.Get_size() == 1:
        return 0
    from mpi4py import MPI

    n = 0
    while comm.Iprobe(source=MPI.ANY_SOURCE, tag=TAG_PROGRESS):
        comm.recv(source=MPI.ANY_SOURCE, tag=TAG_PROGRESS)
        n += 1
        if bar:
            bar.update(1)
    return n


def write_table(rows: list[dict], keys: list[str], out_dir: Path, case_path: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    columns = ["point", *keys, *[c for c, _ in TABLE_COLUMNS]]
    with open(out_dir / "sweep.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_csv(row.get(c, "")) for c in columns])
    (out_dir / "sweep.json").write_text(
        json.dumps({"case": case_path, "parameters": keys, "rows": rows}, indent=1, default=_json_default)
    )
    ok = [r for r in rows if "_failed" not in r]
    if ok:
        write_sweep_plots(ok, keys, out_dir)


def _csv(value):
    if isinstance(value, float):
        return repr(value)
    return value


def write_sweep_plots(rows: list[dict], keys: list[str], out_dir: Path) -> list[str]:
    """One figure per swept parameter: metrics against it, one line per combination of the others."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    for key in keys:
        if not all(isinstance(r[key], (int, float)) and not isinstance(r[key], bool) for r in rows):
            continue
        others = [k for k in keys if k != key]
        groups: dict = {}
        for r in rows:
            groups.setdefault(tuple(r[k] for k in others), []).append(r)
        ncols = 3
        nrows = math.ceil(len(PLOT_COLUMNS) / ncols)
        fig, axes = plt.subplots(nrows, ncols, figsize=(4 * ncols, 3 * nrows), squeeze=False)
        for ax, column in zip(axes.flat, PLOT_COLUMNS):
            for label, group in groups.items():
                group = sorted(group, key=lambda r: r[key])
                name = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(others, label)) or None
                ax.plot([r[key] for r in group], [r[column] for r in group], "o-", label=name)
            ax.set_xlabel(key.removeprefix("lumped."))
            ax.set_title(column, fontsize=9)
            ax.grid(alpha=0.3)
        if others:
            axes.flat[0].legend(fontsize=7)
        fig.tight_layout()
        name = f"sweep_{key.removeprefix('lumped.').replace('.', '_')}.png"
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="piezodyn sweep", description=__doc__.split("\n\n")[0])
    parser.add_argument("case", help="lumped case file (tier = 'lumped')")
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=V1,V2,...",
        help="swept parameter, e.g. lumped.downforce_N=0,3,6,9 (repeat for a grid)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="fixed override applied to every point",
    )
    parser.add_argument("--out", default=None, help="output directory (default: sweep-<case name>)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    comm = None
    try:
        from mpi4py import MPI

        comm = MPI.COMM_WORLD
    except ImportError:  # pragma: no cover - mpi4py is installed on the project's machines
        comm = None
    rank = comm.Get_rank() if comm is not None else 0
    try:
        if not args.param:
            raise CaseError("--param", None, "give at least one --param KEY=V1,V2,...")
        params = [parse_param(text) for text in args.param]
        from app.runner import prepare_output_dir

        out_dir = prepare_output_dir(args.out or f"sweep-{Path(args.case).stem}", comm, "--out")
        rows = run_sweep(args.case, params, out_dir, args.set, comm, progress=not args.no_progress)
    except CaseError as exc:
        if rank == 0:
            print(exc.line(), file=sys.stderr)
        return 2
    if rank == 0:
        failed = [r for r in rows if "_failed" in r]
        print(f"sweep: {len(rows)} points -> {out_dir / 'sweep.csv'}", file=sys.stderr)
        if failed:
            for r in failed:
                print(f"sweep: point {r['point']} failed: {r['_failed']}", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
