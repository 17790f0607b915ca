"""Every run speaks (app/progress.py, app/report.py): with stderr going to a file (a batch job), each tier and
analysis prints plain progress lines at least every 10 % of its work, and the end-of-run table gives one number
and one unit per row.

Runs: the drill in the FE, modal and lumped tiers (short), a PZT bar's modal and harmonic analyses (the harmonic
sweep's progress). The table rule: a row's value is one number (no "a / b" pairs of quantities, no number in
brackets behind it) and its unit one non-empty unit ("1" for a count or a ratio, never "-")."""

from __future__ import annotations

import re

import pytest
from conftest import CASES, run_cli

TINY_DRILL = ["geometry.parameters.mesh_size_m=0.004", "geometry.parameters.ceramic_mesh_size_m=0.0025",
              "output.fields=false", "output.plots=false"]
RUNS = {
    "fe": (CASES / "usdc-fe.toml", [*TINY_DRILL, "transient.end_time_s=2e-4"]),
    "modal": (CASES / "usdc-fe.toml", [*TINY_DRILL, 'tier="modal"', "transient.end_time_s=1e-3"]),
    "lumped": (CASES / "usdc-lumped.toml", ["lumped.duration_s=0.02", "lumped.output.plots=false"]),
    "harmonic": (CASES / "validation" / "pzt4-bar-axisymmetric.toml",
                 ["geometry.parameters.axial_divisions=8", "output.fields=false", "output.plots=false"]),
}
PROGRESS = re.compile(r"^(?P<phase>[\w -]+):\s+(?P<percent>\d+) % \|")
NUMBER = re.compile(r"^[-+]?(\d+(\.\d*)?|\.\d+)([eE][-+]?\d+)?$")


@pytest.fixture(scope="module", params=sorted(RUNS))
def run(request, tmp_path_factory):
    case, sets = RUNS[request.param]
    out = tmp_path_factory.mktemp(request.param)
    proc = run_cli("run", case, "--out", out / "run", *[a for s in sets for a in ("--set", s)])
    assert proc.returncode == 0, proc.stderr[-3000:]
    return request.param, proc


def test_progress_lines_at_least_every_ten_percent(run):
    name, proc = run
    phases: dict[str, list[int]] = {}
    for line in proc.stderr.splitlines():
        match = PROGRESS.match(line)
        if match:
            phases.setdefault(match["phase"].strip(), []).append(int(match["percent"]))
    assert phases, f"{name}: no progress line on stderr:\n{proc.stderr[-2000:]}"
    for phase, percents in phases.items():
        # a line in every tenth of the work (printed when the work crosses it: 31 % after a step over 30 %)
        assert {p // 10 for p in percents} >= set(range(1, 11)), f"{name}: {phase}: {percents}"


def test_end_of_run_table_has_one_number_and_one_unit_per_row(run):
    name, proc = run
    lines = proc.stdout.splitlines()
    rules = [i for i, line in enumerate(lines) if line and set(line) == {"-"}]
    assert len(rules) >= 2, f"{name}: no table in\n{proc.stdout}"
    rows = lines[rules[0] + 1:rules[1]]
    assert rows
    for row in rows:
        label, _, rest = row.partition("  ")
        fields = rest.split()
        assert label.strip() and len(fields) >= 2, f"{name}: {row!r}"
        value, unit = fields[0], " ".join(fields[1:])
        assert NUMBER.match(value), f"{name}: {row!r}: the value is not one number"
        assert unit != "-" and "/ " not in unit and "(" not in unit, f"{name}: {row!r}: not one unit"
