"""The Docker image as users run it, checked without a container engine.

Static: a non-root USER, the apt layer built from the install script alone (before the source is
copied), the JIT/numba/matplotlib caches under a writable /tmp, a .dockerignore that keeps the host's
venv, results and .git out. Dynamic: the install script's phases, and a run as an unprivileged user with
no home directory using exactly the Dockerfile's ENV (the `docker run --user $(id -u)` crash of issue 13).
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _instructions(name: str = "Dockerfile") -> list[tuple[str, str]]:
    """Dockerfile instructions as (KEYWORD, arguments), continuation lines joined, comments dropped."""
    text = (ROOT / name).read_text()
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("#")]
    joined = re.sub(r"\\\n", " ", "\n".join(lines))
    out = []
    for line in joined.splitlines():
        if line.strip():
            keyword, _, args = line.strip().partition(" ")
            out.append((keyword.upper(), args.strip()))
    return out


def _env() -> dict[str, str]:
    env = {}
    for keyword, args in _instructions():
        if keyword == "ENV":
            for item in shlex.split(args):
                key, _, value = item.partition("=")
                env[key] = value
    return env


def test_image_runs_as_a_non_root_user():
    users = [args for keyword, args in _instructions() if keyword == "USER"]
    assert users, "no USER instruction: the image would run as root"
    user = users[-1].split(":")[0]
    assert user not in ("root", "0")
    # the user is created before it is used
    run_lines = " ".join(args for keyword, args in _instructions() if keyword == "RUN")
    assert "useradd" in run_lines and user in run_lines


def test_apt_layer_depends_only_on_the_install_script():
    steps = _instructions()
    copies = [(i, args) for i, (k, args) in enumerate(steps) if k == "COPY"]
    packages = next(i for i, (k, args) in enumerate(steps) if k == "RUN" and ".ci/install.sh packages" in args)
    source = next(i for i, args in copies if args.split()[0] == ".")
    assert packages < source, "the apt packages must be installed before the source is copied"
    before = [args for i, args in copies if i < packages]
    assert before == [".ci/install.sh .ci/install.sh"], before
    project = next(i for i, (k, args) in enumerate(steps) if k == "RUN" and ".ci/install.sh project" in args)
    assert project > source


def test_jit_and_other_caches_point_at_a_writable_place():
    env = _env()
    assert env["HOME"].startswith("/tmp")
    for key in ("XDG_CACHE_HOME", "NUMBA_CACHE_DIR", "MPLCONFIGDIR"):
        assert env[key].startswith("/tmp/"), key
    assert "/opt/piezodyn/.venv/bin" in env["PATH"]


def test_dockerignore_keeps_host_state_out():
    patterns = {ln.strip().lstrip("/") for ln in (ROOT / ".dockerignore").read_text().splitlines()
                if ln.strip() and not ln.startswith("#")}
    for needed in (".venv", "results", ".git", "**/__pycache__"):
        assert needed in patterns, needed
    # the Dockerfiles too: the test image's run of this file reads them
    for kept in ("app", "cases", "pyproject.toml", ".ci", "forms", "geometry", "tests", "Dockerfile",
                 "Dockerfile.test"):
        assert kept not in patterns


def test_one_install_script_with_two_phases():
    for caller in ("README.md", ".ci/run", "Dockerfile"):
        assert ".ci/install.sh" in (ROOT / caller).read_text(), caller
    bad = subprocess.run(["bash", str(ROOT / ".ci/install.sh"), "everything"], capture_output=True, text=True)
    assert bad.returncode == 2 and "usage" in bad.stderr
    if os.geteuid() == 0:  # idempotent: every package is there, so this only queries dpkg
        ok = subprocess.run(["bash", str(ROOT / ".ci/install.sh"), "packages"], capture_output=True, text=True,
                            timeout=120)
        assert ok.returncode == 0, ok.stderr
        assert "piezodyn" not in ok.stdout  # the project phase did not run


def test_test_image_runs_the_suite_with_paraview():
    """Dockerfile.test: the runtime image plus the test extras the runtime image leaves out (ParaView,
    Xvfb), running .ci/test.sh, which requires the ParaView checks (they fail, not skip, without it)."""
    steps = _instructions("Dockerfile.test")
    assert steps[0][0] == "ARG" and steps[0][1] == "BASE=piezodyn" and steps[1] == ("FROM", "${BASE}")
    runs = [args for keyword, args in steps if keyword == "RUN"]
    assert any(".ci/install.sh packages" in r and "PIEZODYN_NO_TEST_EXTRAS" not in r for r in runs), runs
    assert ("ENTRYPOINT", '["bash", ".ci/test.sh"]') in steps
    install = (ROOT / ".ci/install.sh").read_text()
    assert "PACKAGES+=(paraview python3-paraview xvfb xauth)" in install
    assert 'PIEZODYN_NO_TEST_EXTRAS=1 bash .ci/install.sh packages' in (ROOT / "Dockerfile").read_text()
    assert 'export PIEZODYN_REQUIRE_PARAVIEW="${PIEZODYN_REQUIRE_PARAVIEW:-1}"' in (ROOT / ".ci/test.sh").read_text()


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to drop to another user")
def test_run_as_unprivileged_user_with_the_images_environment():
    """`docker run --user <uid>`: a uid with no passwd entry and no home, the Dockerfile's ENV with /tmp
    replaced by a fresh directory, read-only source tree. The FE case compiles its forms (JIT) and runs."""
    with tempfile.TemporaryDirectory(prefix="piezodyn-docker-") as name:  # pytest's tmp_path is root-only
        scratch = Path(name)
        scratch.chmod(0o1777)
        _run_unprivileged(scratch)


def _run_unprivileged(scratch: Path) -> None:
    env = {k: v.replace("/tmp", str(scratch)) for k, v in _env().items()
           if k not in ("PATH", "OMPI_ALLOW_RUN_AS_ROOT", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM")}
    env["PATH"] = "/usr/bin:/bin"
    out = scratch / "results"
    cmd = ["setpriv", "--reuid", "54321", "--regid", "54321", "--clear-groups",
           str(ROOT / ".venv/bin/piezodyn"), "run", str(ROOT / "cases/validation/pzt4-bar-axisymmetric.toml"),
           "--out", str(out), "--quiet", "--set", "analyses=[\"modal\"]"]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600, cwd=scratch)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert (out / "summary.json").stat().st_uid == 54321
    assert any((scratch / ".cache" / "fenics").iterdir())  # the JIT cache went where ENV says


def test_cases_listed_in_the_image_open_from_its_working_directory(tmp_path):
    """`docker run piezodyn cases`: the image's working directory is not the install directory (the cases
    live in /opt/piezodyn/cases), so every path `piezodyn cases` prints must open from the final WORKDIR;
    checked by listing from a directory outside the source tree, as the image does."""
    from app.catalog import CASES_DIR, format_cases

    workdirs = [args for keyword, args in _instructions() if keyword == "WORKDIR"]
    assert workdirs[0] == "/opt/piezodyn" and workdirs[-1] == "/work", workdirs   # the layout this test mimics
    text = format_cases(CASES_DIR, cwd=tmp_path)
    listed = [ln.split()[0] for ln in text.splitlines() if ln.startswith("  ")]
    assert listed and len(listed) == len(list(CASES_DIR.rglob("*.toml")))
    for name in listed:
        assert (tmp_path / name).is_file(), name
