"""Command line: ``piezodyn run|validate|sweep|cases|plot``. Input errors exit 2 with one line; unrecoverable
numerical failures exit 1 saying what was tried."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from app import __version__


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad command line as one CaseError line (exit 2, rank 0 only)."""

    def error(self, message):
        from app.errors import CaseError

        raise CaseError("command line", None, f"{message} (see '{self.prog} --help')")


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="piezodyn", description="Piezoelectric actuators with contact and impact.")
    parser.add_argument("--version", action="version", version=f"piezodyn {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a case file")
    run.add_argument("case")
    run.add_argument("--out", help="output directory (default results/<case name>)")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a case key")
    run.add_argument("--resume", metavar="DIR", help="continue a transient run from its checkpoint in DIR")
    run.add_argument("--quiet", action="store_true")
    validate = sub.add_parser("validate", help="validate a case file without running it")
    validate.add_argument("case")
    validate.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    sub.add_parser("sweep", help="run a case over a grid of values of any case keys (see 'piezodyn sweep --help')",
                   add_help=False)
    sub.add_parser("cases", help="list the case files shipped with piezodyn, with their titles")
    plot = sub.add_parser("plot", help="write the tables and plots of an existing result directory again")
    plot.add_argument("dir", help="result directory (holds summary.json)")
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    import logging

    import ffcx  # noqa: F401  (installs its root log handler, which the JIT's compiler chatter reaches)
    from mpi4py import MPI

    # setuptools lowers the root logger to INFO while the JIT compiles; filter at the handlers instead
    for handler in logging.getLogger().handlers:
        handler.setLevel(logging.WARNING)

    from app.errors import CaseError, NumericalFailure

    rank = MPI.COMM_WORLD.rank
    try:
        if argv and argv[0] == "sweep":
            from app import sweep

            return sweep.main(argv[1:])
        args = _parser().parse_args(argv)
        if args.command in ("cases", "plot"):
            return _browse(args, rank)
        if args.command == "validate":
            from app.runner import check_case, load_for_run

            check_case(load_for_run(args.case, args.set), MPI.COMM_WORLD)
            if rank == 0:
                print(f"{args.case}: valid")
            return 0
        from app.runner import run_case

        if args.resume and args.out and args.out != args.resume:
            raise CaseError("--out", args.out, "give the output directory once: --resume DIR continues in DIR")
        out = args.resume or args.out
        run_case(args.case, args.set, out, quiet=args.quiet, resume=bool(args.resume))
        return 0
    except CaseError as exc:
        if rank == 0:
            print(f"piezodyn: error: {exc.line()}", file=sys.stderr, flush=True)
        return 2
    except NumericalFailure as exc:
        if rank == 0:
            print(f"piezodyn: numerical failure: {exc}", file=sys.stderr, flush=True)
        return 1
    except KeyboardInterrupt:
        return 130


def _browse(args, rank: int) -> int:
    """``cases`` and ``plot DIR``: read-only commands, output on rank 0."""
    if args.command == "cases":
        from app.catalog import format_cases

        if rank == 0:
            print(format_cases())
        return 0
    from app.report import replot
    from app.scenes import SCENES
    from app.sweep import replot_sweep

    log = (lambda line: print(line, flush=True)) if rank == 0 else (lambda line: None)
    directory = Path(args.dir)
    if directory.is_dir() and not (directory / "summary.json").exists() and (directory / "sweep.json").exists():
        written = replot_sweep(directory, log, write=rank == 0)
    else:
        written = replot(directory, log, SCENES, write=rank == 0)
    if rank == 0:
        print(f"{args.dir}: " + (", ".join(written) if written else "nothing to plot"))
    return 0


def entry() -> None:
    sys.exit(main())
