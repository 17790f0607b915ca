"""piezodyn sweep: a grid of runs of one case, any key, any tier, in parallel over MPI ranks.

Every grid point is the case with the ``--set`` overrides and one value per ``--param``: exactly what
``piezodyn run CASE --set ...`` would run. All points are validated (on every rank) before any runs, so
a bad value or unknown key fails at once with one line. Points are dealt round-robin to the MPI ranks;
each rank runs its points on ``COMM_SELF`` into ``DIR/point_NNNN/`` (summary.json and the outputs the
case asks for, as ``run`` writes them). Rank 0 reports progress, gathers the rows and writes
``DIR/sweep.csv`` (swept values and every scalar result, named by their path in summary.json's
``results``; independent of the number of ranks), ``DIR/sweep.json`` (the same plus wall time, rank and
overrides per point) and one PNG per swept parameter.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import sys
import time
import traceback
from pathlib import Path

from app.case.loader import parse_override
from app.errors import CaseError, NumericalFailure
from app.files import write_json_atomic

TAG_PROGRESS = 11

# Headline results plotted against a swept parameter (the CSV holds every scalar); the first present are used:
# the scene's own (app/scenes/, below the analysis that ran: "transient." or "lumped."), then these.
PLOT_COLUMNS = (
    "modal.working_resonance_Hz",
    "modal.working_antiresonance_Hz",
    "modal.working_k_eff",
    "harmonic.admittance_peak_Hz",
    "harmonic.voltage_for_target_amplitude_V",
    "circuit.mechanical_quality_factor",
)
MAX_PLOTS = 6
# Results that describe the run, not the physics: kept in the CSV, never plotted.
_BOOKKEEPING = ("checkpoints_written", "field_outputs")


def split_values(raw: str) -> list[str]:
    """Split ``v1,v2,...`` at top-level commas: ``[0,0],[0,-3]`` -> ``["[0,0]", "[0,-3]"]``."""
    items, depth, quote, current = [], 0, None, []
    for ch in raw:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append("".join(current))
            current = []
            continue
        current.append(ch)
    items.append("".join(current))
    return items


def parse_param(text: str) -> tuple[str, list]:
    """``a.b.c=v1,v2,...`` -> ("a.b.c", [v1, v2, ...]); each value is read as a TOML value (a list is
    one value: ``transient.loads.fe_force_N=[0,0],[0,-3]``). The key is checked against the case's
    schema when the points are built."""
    if "=" not in text:
        raise CaseError("--param", text, "expected dotted.key=value1,value2,...")
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise CaseError("--param", text, "expected dotted.key=value1,value2,...")
    values = []
    for item in split_values(raw):
        if not item.strip():
            raise CaseError("--param", key, f"empty value in {raw!r}")
        values.append(parse_override(f"{key}={item}")[1])
    return key, values


def toml_value(value) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return repr(value)


def build_points(case_path: str | Path, params: list[tuple[str, list]], sets: list[str] | None = None) -> list[dict]:
    """Validate every grid point (the whole case schema, as ``validate`` does before building a mesh);
    returns [{index, values: {key: value}, overrides, case}] in grid order."""
    from app.runner import load_for_run

    keys = [k for k, _ in params]
    if len(set(keys)) != len(keys):
        raise CaseError("--param", keys[0], "a parameter is swept twice")
    points = []
    for index, combo in enumerate(itertools.product(*[v for _, v in params])):
        values = dict(zip(keys, combo))
        overrides = list(sets or []) + [f"{k}={toml_value(v)}" for k, v in values.items()]
        try:
            case = load_for_run(case_path, overrides)
        except CaseError as exc:
            raise _swept(exc, values) from None
        _check_geometry_parameters(case)
        points.append({"index": index, "values": values, "overrides": overrides, "case": case})
    return points


def _swept(exc: CaseError, values: dict) -> CaseError:
    """``exc`` saying which --param value it comes from, when its key is a swept key or lies in or above
    one (a swept key that makes a section the case's tier does not read is named by that section)."""
    key = str(exc.key or "")
    for name, value in values.items():
        if key and (name == key or name.startswith((key + ".", key + "[")) or key.startswith((name + ".", name + "["))):
            return CaseError(exc.file, exc.key, f"{exc.message} (from --param {name}={toml_value(value)})")
    return exc


def _check_geometry_parameters(case) -> None:
    """The mesh builder's parameters are checked when the mesh is built; check them here, without meshing,
    so a misspelt ``geometry.parameters`` key fails before any point runs."""
    geometry = getattr(case, "geometry", None)
    if case.tier != "fe" or geometry is None or geometry.builder is None:
        return
    from app.case.validate import from_dict
    from geometry.builders import BUILDERS

    params_cls, _ = BUILDERS[geometry.builder]
    from_dict(params_cls, geometry.parameters, case.source, "geometry.parameters")


def scalar_results(results: dict, prefix: str = "") -> dict:
    """Every numeric scalar in ``results`` by its dotted path (lists, strings and None left out, and wall and CPU
    times: those are in each point's summary.json, and the table must not depend on the machine)."""
    out = {}
    for key, value in results.items():
        name = f"{prefix}{key}"
        if "wall" in key or "cpu" in key:
            continue
        if isinstance(value, dict):
            out.update(scalar_results(value, name + "."))
        elif isinstance(value, bool):
            out[name] = int(value)
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            out[name] = value
        elif type(value).__module__ == "numpy" and getattr(value, "ndim", 1) == 0:
            out[name] = value.item()
    return out


def run_point(case_path: str, point: dict, out_dir: Path) -> dict:
    """Run one grid point on COMM_SELF as ``piezodyn run`` would; returns its table row."""
    from mpi4py import MPI

    from app.progress import silenced
    from app.runner import run_case

    point_dir = out_dir / f"point_{point['index']:04d}"
    wall0 = time.perf_counter()
    with silenced():
        summary = run_case(case_path, point["overrides"], point_dir, comm=MPI.COMM_SELF, quiet=True)
    row = {"point": point["index"], **point["values"], **scalar_results(summary["results"])}
    row["_wall_s"] = time.perf_counter() - wall0
    return row


def _run_mine(case_path, mine, out_dir, rank, on_done) -> list[dict]:
    rows = []
    for point in mine:
        base = {"point": point["index"], **point["values"], "_rank": rank, "_overrides": point["overrides"]}
        try:
            row = {**run_point(case_path, point, out_dir), "_rank": rank, "_overrides": point["overrides"]}
        except CaseError as exc:
            row = {**base, "_failed": exc.line(), "_exit": 2}
        except NumericalFailure as exc:  # keep the sweep going; report the point
            row = {**base, "_failed": f"numerical failure: {exc}", "_exit": 1}
        except Exception as exc:  # a bug: say where, keep the other ranks from waiting forever
            traceback.print_exc(file=sys.stderr)
            row = {**base, "_failed": f"{type(exc).__name__}: {exc}", "_exit": 1}
        rows.append(row)
        on_done()
    return rows


def run_sweep(case_path, params, out_dir, sets=None, comm=None, progress=True) -> list[dict] | None:
    """Run the grid; returns the rows (sorted by point) on rank 0, None elsewhere."""
    from app.progress import Progress

    case_path = str(case_path)
    out_dir = Path(out_dir)
    rank = comm.Get_rank() if comm is not None else 0
    size = comm.Get_size() if comm is not None else 1
    points = build_points(case_path, params, sets)  # every rank validates: errors surface everywhere
    mine = [pt for pt in points if pt["index"] % size == rank]
    bar = Progress(len(points), "sweep", "points", enabled=progress, rank=rank, value_format="{:.0f}")

    done = [0]  # points finished on any rank, as rank 0 knows

    def on_done():
        if rank == 0:
            finished = 1 + _drain_progress(comm)
            done[0] += finished
            bar.update(finished)
        else:
            comm.send(1, dest=0, tag=TAG_PROGRESS)

    rows = _run_mine(case_path, mine, out_dir, rank, on_done)
    if rank == 0 and size > 1:
        from mpi4py import MPI

        while done[0] < len(points):
            comm.recv(source=MPI.ANY_SOURCE, tag=TAG_PROGRESS)
            done[0] += 1
            bar.update(1)
    bar.close()
    if size > 1:
        gathered = comm.gather(rows, root=0)
        if rank != 0:
            return None
        rows = [r for part in gathered for r in part]
    rows.sort(key=lambda r: r["point"])
    title = (points[0]["case"].title if points else "") or Path(case_path).name
    headline = scene_columns(points[0]["case"]) if points else []
    axes = scene_axes(points[0]["case"], [k for k, _ in params]) if points else {}
    write_table(rows, [k for k, _ in params], out_dir, case_path, title, headline, axes)
    if progress:                  # the table as the terminal shows it (not with --quiet)
        for line in table_lines(rows, [k for k, _ in params], headline, axes):
            print(line, flush=True)
    return rows


def _drain_progress(comm) -> int:
    """Progress messages from the other ranks that have arrived (never blocks)."""
    if comm is None or comm.Get_size() == 1:
        return 0
    from mpi4py import MPI

    n = 0
    while comm.Iprobe(source=MPI.ANY_SOURCE, tag=TAG_PROGRESS):
        comm.recv(source=MPI.ANY_SOURCE, tag=TAG_PROGRESS)
        n += 1
    return n


def table_columns(rows: list[dict], keys: list[str]) -> list[str]:
    columns = ["point", *keys]
    for row in rows:
        for name in row:
            if name not in columns and not name.startswith("_"):
                columns.append(name)
    return columns


def write_table(rows: list[dict], keys: list[str], out_dir: Path, case_path: str, title: str = "",
                headline: list[str] | None = None, axes: dict | None = None) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    columns = table_columns(rows, keys)
    with open(out_dir / "sweep.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_csv(row.get(c, "")) for c in columns])
    write_json_atomic(out_dir / "sweep.json", {"case": case_path, "title": title, "parameters": keys,
                                               "columns": columns, "headline": headline or [],
                                               "axes": axes or {}, "rows": rows},
                      indent=1)
    ok = [r for r in rows if "_failed" not in r]
    if ok:
        write_sweep_plots(ok, keys, out_dir, title, headline, axes)


def _csv(value):
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return json.dumps(value)
    return value


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _axis(rows: list[dict], key: str, axis=None):
    """(x values, x label) for a swept key: by the scene's ``axis`` (label, component, sign) when it gives one
    (:func:`scene_axes`), else a number with its unit, or a vector by the one component that varies."""
    from app.plots import quantity_label

    values = [r[key] for r in rows]
    if axis is not None:
        label, component, sign = axis
        try:
            # + 0.0: a zero force reads 0, not -0
            return [sign * (v if component is None else v[component]) + 0.0 for v in values], label
        except (TypeError, IndexError, KeyError):
            pass
    if all(_is_number(v) for v in values):
        text, scale = quantity_label(key)
        return [v * scale for v in values], text
    if all(isinstance(v, list) and v and all(_is_number(c) for c in v) for v in values):
        varying = [i for i in range(len(values[0])) if len({v[i] for v in values}) > 1]
        if len(varying) == 1 and all(len(v) == len(values[0]) for v in values):
            i = varying[0]
            text, scale = quantity_label(key)
            name, _, unit = text.partition(" [")
            return [v[i] * scale for v in values], f"{name}, component {i}" + (f" [{unit}" if unit else "")
    return None, None


def _legend(key: str, value) -> str:
    """``lumped.free_mass.mass_kg``, 0.002 -> "free mass mass = 2 g" (units as on the axes)."""
    from app.plots import quantity_label

    text, scale = quantity_label(key)
    name, _, unit = text.partition(" [")
    if _is_number(value):
        return f"{name} = {value * scale:g}" + (f" {unit[:-1]}" if unit else "")
    return f"{name} = {value}"


def scene_columns(case) -> list[str]:
    """The headline result paths of the case's scene (app/scenes/), below the analysis that reports them."""
    from app.scenes import scene_of

    scene = scene_of(case)
    if scene is None:
        return []
    analysis = "lumped" if case.tier == "lumped" else "transient"
    return [f"{analysis}.{column}" for column in scene.sweep_columns]


def scene_axes(case, keys: list[str]) -> dict:
    """{swept key: [label, component, sign]} for the keys the case's scene plots its own way
    (``Scene.sweep_axis``); kept in sweep.json, so ``piezodyn plot`` draws the same axes."""
    from app.scenes import scene_of

    scene = scene_of(case)
    hook = getattr(scene, "sweep_axis", None)
    axes = {}
    for key in keys:
        axis = hook(key) if hook is not None else None
        if axis is not None:
            axes[key] = list(axis)
    return axes


def interval_column(column: str) -> str | None:
    """The column holding the half-width of a statistic's 95 % interval (``X.statistics.interval_95.Y`` for
    ``X.statistics.Y``: a scene's batch means), None for a column that is not a statistic."""
    head, sep, tail = column.partition(".statistics.")
    return f"{head}.statistics.interval_95.{tail}" if sep and not tail.startswith("interval_95.") else None


def plot_columns(rows: list[dict], headline: list[str] | None = None) -> list[str]:
    """The results a sweep plots: the scene's headlines, then the generic ones, those present at every point and
    not zero at all (an all-zero panel says nothing), at most MAX_PLOTS."""
    present = [c for c in [*(headline or []), *PLOT_COLUMNS] if all(_is_number(r.get(c)) for r in rows)
               and any(r[c] != 0 for r in rows)]
    if not present:  # a tier without headlines: its first scalar results
        present = [c for c in table_columns(rows, []) if c != "point" and not c.endswith(_BOOKKEEPING)
                   and ".interval_95." not in c and all(_is_number(r.get(c)) for r in rows)
                   and any(r[c] != 0 for r in rows)]
    return present[:MAX_PLOTS]


def write_sweep_plots(rows: list[dict], keys: list[str], out_dir: Path, title: str = "",
                      headline: list[str] | None = None, axes: dict | None = None) -> list[str]:
    """One PNG per swept parameter (:func:`sweep_figures`); returns the file names."""
    import matplotlib.pyplot as plt

    files = []
    for name, fig in sweep_figures(rows, keys, title, headline, axes):
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


def sweep_figures(rows: list[dict], keys: list[str], title: str = "", headline: list[str] | None = None,
                  axes: dict | None = None):
    """(file name, figure) per swept parameter: headline results against it (x increasing to the right, as the
    scene names the quantity: :func:`scene_axes`), one line per combination of the others, error bars where
    the results carry 95 % intervals (:func:`interval_column`), no all-zero panel; labels and units as the
    rest of piezodyn shows them (mm, kHz, g)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from app.plots import quantity_label

    columns = plot_columns(rows, headline)
    for key in keys:
        x_all, x_label = _axis(rows, key, (axes or {}).get(key))
        if x_all is None or not columns:
            continue
        x_of = dict(zip((r["point"] for r in rows), x_all))
        others = [k for k in keys if k != key]
        groups: dict = {}
        for r in rows:
            groups.setdefault(tuple(json.dumps(r[k]) for k in others), []).append(r)
        ncols = min(3, len(columns))
        nrows = math.ceil(len(columns) / ncols)
        fig, panels = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 3.2 * nrows), squeeze=False)
        with_bars = False
        for ax, column in zip(panels.flat, columns):
            y_label, y_scale = quantity_label(column)
            bars = interval_column(column)
            for label, group in groups.items():
                group = sorted(group, key=lambda r: x_of[r["point"]])
                name = ", ".join(_legend(k, json.loads(v)) for k, v in zip(others, label)) or None
                x = [x_of[r["point"]] for r in group]
                y = [r[column] * y_scale for r in group]
                if bars is not None and all(_is_number(r.get(bars)) for r in group):
                    ax.errorbar(x, y, yerr=[r[bars] * y_scale for r in group], fmt="o-", capsize=3, label=name)
                    with_bars = True
                else:
                    ax.plot(x, y, "o-", label=name)
            ax.set_xlabel(x_label)
            ax.set_ylabel(y_label, fontsize=8)
            ax.grid(alpha=0.3)
        for ax in list(panels.flat)[len(columns):]:
            ax.set_visible(False)
        if others:
            panels.flat[0].legend(fontsize=7, loc="best")
        what = f"results against {x_label}" + (" (bars: 95 % batch-means intervals)" if with_bars else "")
        fig.suptitle(f"{title}\n{what}" if title else what, fontsize=10)
        fig.tight_layout()
        yield f"sweep_{key.replace('.', '_')}.png", fig


def table_lines(rows: list[dict], keys: list[str], headline: list[str] | None = None,
                axes: dict | None = None) -> list[str]:
    """The sweep as a terminal table: each point's swept values (as the scene names them: :func:`scene_axes`)
    and its headline results with units, a statistic with its 95 % interval as "mean ± half-width"."""
    from app.plots import quantity_label

    columns = plot_columns([r for r in rows if "_failed" not in r], headline) if rows else []
    heads, cells = ["point"], [[str(r["point"])] for r in rows]
    own = set()
    for key in keys:
        x, label = _axis(rows, key, (axes or {}).get(key)) if (axes or {}).get(key) else (None, None)
        if x is None:
            continue
        own.add(key)
        heads.append(label)
        for cell, value in zip(cells, x):
            cell.append(f"{value:.5g}")
    for key in [k for k in keys if k not in own] + columns:
        label, scale = quantity_label(key)
        heads.append(label)
        bars = interval_column(key)
        for cell, r in zip(cells, rows):
            value = r.get(key)
            if _is_number(value) and bars is not None and _is_number(r.get(bars)):
                cell.append(f"{value * scale:.4g} ± {r[bars] * scale:.2g}")
            elif _is_number(value):
                cell.append(f"{value * scale:.5g}")
            elif isinstance(value, list):
                cell.append("[" + ", ".join(f"{v * scale:.4g}" if _is_number(v) else str(v) for v in value) + "]")
            else:
                cell.append("failed" if "_failed" in r else str(value if value is not None else "-"))
    widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h) for i, h in enumerate(heads)]
    line = "  ".join(h.rjust(w) for h, w in zip(heads, widths))
    return [line, "-" * len(line)] + ["  ".join(c.rjust(w) for c, w in zip(cell, widths)) for cell in cells]


EPILOG = """\
examples:
  piezodyn sweep cases/usdc-lumped.toml --param lumped.downforce_N=0,3,6,9
  piezodyn sweep cases/usdc-fe.toml --param transient.loads.fe_force_N=[0,0],[0,-3],[0,-6],[0,-9]
  piezodyn sweep cases/usdc-transducer.toml --param geometry.parameters.tip_length_m=0.046,0.048,0.050
  mpirun -n 4 piezodyn sweep CASE --param KEY=V1,V2 --param KEY2=W1,W2   (a 4-point grid, one per rank)

Each point runs as 'piezodyn run CASE --set ...' would, into OUT/point_NNNN/. OUT/sweep.csv has the
swept values and every scalar result (named by its path in summary.json), OUT/sweep.json the same with
wall times, OUT/sweep_<key>.png the headline results against each swept key.
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="piezodyn sweep", formatter_class=argparse.RawDescriptionHelpFormatter, epilog=EPILOG,
        description="Run a case over a grid of parameter values (any case key, any tier), in parallel "
                    "over MPI ranks.")
    parser.add_argument("case", help="case file (any tier)")
    parser.add_argument("--param", action="append", default=[], metavar="KEY=V1,V2,...",
                        help="swept case key and its values (TOML values; repeat for a grid)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a case key at every point (as for 'run')")
    parser.add_argument("--out", default=None, help="output directory (default results/sweep-<case name>)")
    parser.add_argument("--quiet", action="store_true", help="no progress and no messages")
    parser.add_argument("--no-progress", action="store_true", help=argparse.SUPPRESS)  # the old spelling
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    rank = comm.Get_rank()
    out_dir = Path(args.out or Path("results") / f"sweep-{Path(args.case).stem}")
    try:
        if not args.param:
            raise CaseError("--param", None, "give at least one --param KEY=V1,V2,...")
        params = [parse_param(text) for text in args.param]
        from app.runner import prepare_output_dir

        out_dir = prepare_output_dir(out_dir, comm, "--out")
        rows = run_sweep(args.case, params, out_dir, args.set, comm,
                         progress=not (args.quiet or args.no_progress))
    except CaseError as exc:
        if rank == 0:
            print(f"piezodyn: error: {exc.line()}", file=sys.stderr, flush=True)
        return 2
    code = 0
    if rank == 0:
        failed = [r for r in rows if "_failed" in r]
        if not args.quiet:
            print(f"sweep: {len(rows)} points -> {out_dir / 'sweep.csv'}", flush=True)
        for r in failed:
            print(f"piezodyn: sweep point {r['point']} failed: {r['_failed']}", file=sys.stderr, flush=True)
        code = max((r["_exit"] for r in failed), default=0)
    return comm.bcast(code, root=0)


if __name__ == "__main__":
    sys.exit(main())


def replot_sweep(result_dir: Path, log, write: bool = True) -> list[str]:
    """``piezodyn plot`` on a sweep's directory: its plots from sweep.json and its table again."""
    path = result_dir / "sweep.json"
    try:
        sweep = json.loads(path.read_bytes().decode("utf-8"))
        rows, keys = sweep["rows"], sweep["parameters"]
        headline = sweep.get("headline") or []
        axes = sweep.get("axes") or {}
        title = sweep.get("title", "")
        if not isinstance(rows, list) or not all(isinstance(r, dict) and "point" in r for r in rows):
            raise KeyError("rows")
    except UnicodeDecodeError:
        raise CaseError(str(path), None, "is not UTF-8 text (damaged)") from None
    except json.JSONDecodeError as exc:
        raise CaseError(str(path), None, f"is not valid JSON (truncated or damaged: {exc.msg})") from None
    except (KeyError, TypeError) as exc:
        raise CaseError(str(path), str(exc).strip("'"), "missing: not a piezodyn sweep") from None
    ok = [r for r in rows if "_failed" not in r]
    written = write_sweep_plots(ok, keys, result_dir, title, headline, axes) if write and ok else []
    for line in table_lines(rows, keys, headline, axes):
        log(line)
    return written
