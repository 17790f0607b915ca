"""The modal tier's structure in its free modes (app/reduced/coordinates.py, issue 27) against the same structure in
its own coordinates: the compiled loop's diagonal path (one product by K_eff^-1 per step, C_FF through K_eff) and its
dense path (products by M, C, K and K_eff^-1) must take the same steps to the contact Newton's tolerance; the
drill's engine runs in its free modes, reads a checkpoint state written in physical coordinates into them, and a run
split in two within them resumes bit for bit.
"""

import math

import numpy as np
import pytest
from conftest import CASES
from mpi4py import MPI
from reduced_scene import Body, Contact, bodies_record, contacts_record, links_record, sites_record

from app.contact import law
from app.reduced import engine as reduced_engine
from app.reduced import kernel as kr
from app.reduced.coordinates import FREE_MODES, RECORD_KEY, modes_of, operators_in_modes, rows_in_modes
from forms.newmark import TimeScheme

N = 10
INPUT = 1              # the prescribed coordinate
STEPS = 2000
SPLIT_STEPS = 100
TINY_DRILL = ['tier="modal"', "geometry.parameters.mesh_size_m=0.004",
              "geometry.parameters.ceramic_mesh_size_m=0.0025", "output.plots=false", "output.fields=false"]


def _structure(seed=3):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N, N))
    M = 0.01 * (np.eye(N) + 0.1 * A @ A.T / N)
    B = rng.normal(size=(N, N))
    K = 1e9 * (B @ B.T / N + 0.05 * np.eye(N))          # natural frequencies ~ 1e4 .. 1e6 rad/s
    D = rng.normal(size=(N, 3))
    C = 8e-9 * K + 5.0 * (D @ D.T)                       # Rayleigh plus a non-proportional part
    return K, M, C


def _run(K, M, C, rows, sample_rows, q, v, a, steps):
    free = np.setdiff1d(np.arange(N), [INPUT]).astype(np.int64)
    ball = Body(2.1e-3, [0.0, -0.004 - 1e-7], [False, True], load_N=[0.0, 10.0], velocity=[0.0, 0.0])
    contact = Contact(body=0, kind=law.NODE, shape="sphere", vector=(0.0, 1.0, 0.0), radius_m=0.004,
                      stiffness=9.27e9, exponent=1.5)
    Cr, B, L = contacts_record([contact]), bodies_record([ball], 2), links_record([])
    sites = sites_record([[0.0, 0.0, 0.0]], [1.0], [0], rows, Cr, B)
    structure = kr.Structure(K, M, C, np.zeros(N), free, np.array([INPUT], np.int64))
    inputs = kr.Inputs(np.array([kr.ELECTRODE]), np.array([2e-6]), np.array([0.3]), np.zeros(1), 2 * math.pi * 2e4,
                       False)
    control = kr.Control(1e-6, 2.5e-7, 6.25e-8, 1e-12, 2.0)
    s = TimeScheme.generalized_alpha(0.5)
    cap, m = steps, B.mass.size
    out = kr.Outputs(np.zeros(cap), np.zeros(cap), np.zeros((cap, sample_rows.shape[0])), np.zeros((cap, 1)),
                     np.zeros((cap, m)), np.zeros((cap, m)), np.zeros((cap, 1, 3)), np.zeros((cap, 1, 3)),
                     np.zeros((cap, 1)), np.zeros((cap, 1)), np.zeros((cap, 1), np.bool_), np.zeros((cap, 1)),
                     np.zeros((cap, 5)), np.zeros((cap, 1, 3)), np.zeros((cap, 1)), np.zeros((1, 14)),
                     np.zeros((1, 36, 8)), np.zeros(1, np.int64), np.full(1, np.nan))
    z = np.array([0.0, -0.004 - 1e-7])
    zdd = B.load / B.mass * B.free
    istate, fstate = np.zeros(kr.N_ISTATE, np.int64), np.zeros(kr.N_FSTATE)
    fstate[kr.F_CAP], fstate[kr.F_STOP] = np.inf, np.inf
    state = kr.State(q.copy(), v.copy(), a.copy(), z, np.zeros(m), zdd, istate, fstate,
                     kr.Sums(np.zeros(1), np.full(1, np.nan), np.zeros(2)), np.zeros((1, 3)))
    model = kr.Model(structure, inputs, kr.Scheme(s.beta, s.gamma, s.alpha_m, s.alpha_f), control, B, sites, Cr, L,
                     sample_rows)
    code, written = kr.run(1.0, state, model, kr.make_cache(free.size, rows.shape[0]), out, False,
                           kr.no_frames(N, m))
    assert code == kr.BUFFER_FULL and written == steps
    return state, out, kr._diagonal_free(structure)


def test_free_modes_take_the_steps_of_the_physical_coordinates():
    """The scene: a 10-coordinate structure (random symmetric positive definite K and M, damping C = beta K plus a
    non-proportional part, as the material quality factors give: C is not diagonal in the modes), one prescribed
    input coordinate driven at 20 kHz (coupled to every other coordinate through M, C and K), a node site on the
    first coordinate and a ball pressed onto it by a load of 10 N: it strikes the vibrating node again and again (the
    drill's tip-ball contact: Hertz law, its stiffness and ball). 2 000 steps, all three step sizes.

    Reference: the dense path's final coordinates (physical: x mapped back by T), body state, samples, forces and
    every step's size. Tolerance 1e-9 (relative to the largest value): the paths differ in the order of their
    arithmetic only, and the contact Newton converges to 1e-9 of each site's increment (kernel SITE_RTOL), so the
    states differ by that at most over the few impacts of these 2 000 steps (measured: coordinates 4e-11, samples
    and forces ~1e-10); a wrong term of the diagonal path (a 1 % change of the input coordinate's damping coupling
    changes the coordinates by 200 % here; a dropped c_K/c_C term by far more) is far outside."""
    K, M, C = _structure()
    rows = np.zeros((2, N))
    rows[1, 0] = 1.0                                     # the node's z displacement: the first coordinate
    sample_rows = np.random.default_rng(5).normal(size=(2, N))
    # start: the input at its value and rate at t = 0 (A sin(0.3) and A w cos(0.3)), the rest at rest
    q, v, a = np.zeros(N), np.zeros(N), np.zeros(N)
    omega = 2 * math.pi * 2e4
    q[INPUT], v[INPUT], a[INPUT] = 2e-6 * math.sin(0.3), 2e-6 * omega * math.cos(0.3), -2e-6 * omega**2 * math.sin(0.3)
    dense, dense_out, dense_diagonal = _run(K, M, C, rows, sample_rows, q, v, a, STEPS)

    free = np.setdiff1d(np.arange(N), [INPUT])
    modes = modes_of(K, M, free)
    Kx, Mx, Cx = operators_in_modes(K, M, C, modes)
    assert np.abs(Cx[np.ix_(free, free)] - np.diag(np.diag(Cx[np.ix_(free, free)]))).max() > 1e-3 * np.abs(Cx).max()
    x, xv, xa = modes.to_modes(q), modes.to_modes(v), modes.to_modes(a)
    diag, diag_out, diag_diagonal = _run(Kx, Mx, Cx, rows_in_modes(rows, modes), rows_in_modes(sample_rows, modes),
                                         x, xv, xa, STEPS)
    assert diag_diagonal and not dense_diagonal          # each run took the path under test

    closings = np.sum(np.diff(dense_out.closed[:, 0].astype(int)) == 1)
    assert closings >= 5                                # impacts, and all three step sizes
    assert {6.25e-8, 2.5e-7, 1e-6} <= set(np.round(dense_out.dt, 20))
    np.testing.assert_array_equal(diag_out.dt, dense_out.dt)
    q_back = modes.to_physical(diag.q)
    assert np.abs(q_back - dense.q).max() <= 1e-9 * np.abs(dense.q).max()
    for name in ("z", "zd"):
        a_, b_ = getattr(dense, name), getattr(diag, name)
        assert np.abs(a_ - b_)[1] <= 1e-9 * abs(a_[1])
    assert np.abs(diag_out.samples - dense_out.samples).max() <= 1e-9 * np.abs(dense_out.samples).max()
    assert np.abs(diag_out.force - dense_out.force).max() <= 1e-9 * np.abs(dense_out.force).max()
    assert diag.istate[kr.I_NEWTON] == pytest.approx(dense.istate[kr.I_NEWTON], abs=2)


def _drill(monkeypatch=None, physical=False, found=None, case=None):
    """The tiny drill's modal engine (its free modes, or the model as built with ``physical``)."""
    from app.reduced.engine import ModalEngine
    from app.runner import load_for_run

    case = case or load_for_run(CASES / "usdc-fe.toml", TINY_DRILL)
    if physical:
        monkeypatch.setattr(reduced_engine, "free_modes", lambda *a, **k: None)
    engine = ModalEngine(case, MPI.COMM_WORLD, lambda *a, **k: None, found)
    if physical:
        monkeypatch.undo()
    return engine


@pytest.mark.mpi
def test_the_drill_in_free_modes_takes_the_steps_of_the_model_as_built(monkeypatch):
    """The drill (tiny mesh, harmonic start) over its first 40 us (~150 steps: the ball's first strike on the tip at
    25.9 us, its release at 37.8 us; one impact, too early for the chaotic growth of differences), engine and series
    as a run writes them, in its free modes against the model as built (the kernel's dense path, as before issue 27).
    Reference: the physical run's series (drive voltage, tip displacement, bodies' positions and velocities, contact
    forces) and its final state. Tolerance 1e-9 relative to each column's largest value: the paths differ in the
    order of their arithmetic (the target tip amplitude's voltage from the harmonic solve in the other coordinates:
    measured 2.2e-11; one product by K_eff^-1 against four; the site and sample rows dense on x), and the contact
    Newton stops at 1e-9 of each site's increment (kernel SITE_RTOL); measured: at most 6.4e-11 (the tip-ball
    force), tip displacement 3.2e-11. The step sizes must be the same; a wrong term of the diagonal path moves the
    tip's displacement by far more (the kernel scene above)."""
    free = _drill()
    built = _drill(monkeypatch, physical=True)
    assert free.free_modes is not None and built.free_modes is None
    assert kr._diagonal_free(free.structure) and not kr._diagonal_free(built.structure)
    series = []
    for engine in (free, built):
        engine.start()
        series.append(engine.advance(4e-5, 10**9, math.inf))
    a, b = series
    assert set(a) == set(b)
    np.testing.assert_array_equal(a["time_s"], b["time_s"])
    assert a["time_s"].size > 100 and b["tip_ball_closed"].any()      # the first impact is in the window
    for key in a:
        scale = np.abs(b[key]).max()
        assert np.abs(a[key] - b[key]).max() <= 1e-9 * scale, key
    q = free.physical(free.q)
    assert np.abs(q - built.q).max() <= 1e-9 * np.abs(built.q).max()
    assert np.abs(free.z - built.z).max() <= 1e-9 * np.abs(built.z).max()
    assert free.results()["reduction"]["free_modes"] and not built.results()["reduction"]["free_modes"]


def _found(engine, tmp_path, arrays, record):
    from app.loop.checkpoint import Found

    if MPI.COMM_WORLD.rank == 0:
        with open(tmp_path / "reduced-model.npz", "wb") as fh:
            engine.built_model.save(fh)
    MPI.COMM_WORLD.barrier()
    return Found({"engine": record, "files": {"reduced_model": "reduced-model.npz"}},
                 {k: np.array(v) for k, v in arrays.items()}, tmp_path / "checkpoint.json")


@pytest.mark.mpi
def test_a_checkpoint_in_physical_coordinates_is_read_into_the_free_modes(shared_tmp):
    """The drill's engine runs in its free modes and says so in its checkpoint record; a checkpoint without that key
    (written before the free modes: physical q, v, a) is converted on reading. Reference: the state it was made
    from; tolerance 1e-12 of the largest coordinate (one product by T and one by T^-1 = Phi^T M_FF: round-off)."""
    first = _drill()
    first.start()
    first.advance(2e-5, 10**9, math.inf)
    arrays, record = first.snapshot()
    arrays = MPI.COMM_WORLD.bcast(arrays, root=0)
    assert record[RECORD_KEY] == FREE_MODES
    physical = {k: np.array(v) for k, v in arrays.items()}
    for name in ("q", "v", "a"):
        physical[name] = first.physical(arrays[name])
    older = {k: v for k, v in record.items() if k != RECORD_KEY}
    second = _drill(found=_found(first, shared_tmp, physical, older))
    second.restore(_found(first, shared_tmp, physical, older))
    free = first.free_modes.free           # (the input coordinate, the electrode's volts, is the same in both)
    for name in ("q", "v", "a"):
        expected = getattr(first, name)[free]
        assert np.abs(getattr(second, name)[free] - expected).max() <= 1e-12 * np.abs(expected).max(), name
    assert np.abs(physical["q"][free] - first.q[free]).max() > 0.1 * np.abs(first.q[free]).max()   # they differ


@pytest.mark.mpi
def test_a_run_split_in_two_in_the_free_modes_resumes_bit_for_bit(shared_tmp):
    """The drill in its free modes to 60 us in one go, and split after its 100th step (~9 us) into a run and
    a second engine restored from the first one's checkpoint state (its free-mode q, v, a; the model file as built,
    whose free modes it computes again). Reference: the one-go run; tolerance: none (bit for bit), as for every
    resumed run (app/loop/checkpoint.py): the eigenvectors are computed again from the same model by the same
    LAPACK call, and the loop's state holds everything the next step needs."""
    one_go = _drill()
    one_go.start()
    whole = one_go.advance(6e-5, 10**9, math.inf)
    first = _drill()
    first.start()
    head = first.advance(6e-5, SPLIT_STEPS, math.inf)      # a checkpoint comes after a step count (the loop's rule)
    assert first.steps == SPLIT_STEPS
    arrays, record = first.snapshot()
    arrays = MPI.COMM_WORLD.bcast(arrays, root=0)
    second = _drill(found=_found(first, shared_tmp, arrays, record))
    second.restore(_found(first, shared_tmp, arrays, record))
    assert second.free_modes is not None
    np.testing.assert_array_equal(second.free_modes.phi, first.free_modes.phi)
    tail = second.advance(6e-5, 10**9, math.inf)
    assert tail["time_s"].size > 100
    for key in whole:
        np.testing.assert_array_equal(np.concatenate([head[key], tail[key]]), whole[key], err_msg=key)
    for name in ("q", "v", "a", "z", "zd", "zdd"):
        np.testing.assert_array_equal(getattr(second, name), getattr(one_go, name), err_msg=name)


def test_the_drill_in_free_modes_writes_the_fields_and_series_of_the_model_as_built(monkeypatch, tmp_path):
    """Field output and series of a run (the loop, the files) in the free modes against the model as built: the
    frames are mapped back to q = T x and expanded with the built model's vertex and derived bases; the series holds
    the electrode's charge (charge rows on x) and the energies (quadratic forms of M, K, C on x) too. The tiny drill
    to 60 us (its first impact; 8 field frames over the first drive period). Reference: the physical run's files;
    tolerance 1e-9 of each field's and column's largest value, as for the series above (measured: displacement
    2.0e-10, potential 1.3e-10, series 7.0e-11: the contact energy); a frame expanded from x without T (the vertex
    basis on the wrong coordinates) is off by order one (measured: the whole displacement)."""
    from conftest import run_case_quiet
    from test_transient_checkpoint import frame_group, read_series, xdmf_times

    sets = [*TINY_DRILL[:-1], "output.fields=true", "output.energies=true", "transient.end_time_s=6e-05",
            "transient.output_interval_s=5e-05"]
    free_out, built_out = tmp_path / "free", tmp_path / "built"
    run_case_quiet("usdc-fe.toml", free_out, *sets)
    monkeypatch.setattr(reduced_engine, "free_modes", lambda *a, **k: None)
    run_case_quiet("usdc-fe.toml", built_out, *sets)
    times = xdmf_times(built_out)
    assert len(times) >= 2 and xdmf_times(free_out) == times
    for k in range(len(times)):
        with frame_group(free_out, k) as f, frame_group(built_out, k) as g:
            for field in ("displacement", "potential"):
                a, b = f[field][:], g[field][:]
                assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max(), (k, field)
    a, b = read_series(free_out / "transient.h5"), read_series(built_out / "transient.h5")
    np.testing.assert_array_equal(a["time_s"], b["time_s"])
    for key in b:
        assert np.abs(a[key] - b[key]).max() <= 1e-9 * max(np.abs(b[key]).max(), 1e-300), key


def test_a_warm_start_of_the_drill_begins_from_the_free_modes_state_it_names(tmp_path):
    """``transient.start_from`` a drill run in its free modes: its checkpoint keeps the model as built (the warm
    start's model check compares that) and its state in the free modes (record: ``coordinates = "free_modes"``),
    which the warm-started engine takes as it is. Reference: the source run's last checkpoint state; tolerance:
    none (the state is copied, not converted); a state converted once more (taken for physical) moves q by order
    one (the checkpoint test above)."""
    import json

    from conftest import run_case_quiet

    from app.loop.checkpoint import read_warm_start
    from app.runner import load_for_run

    source = tmp_path / "source"
    run_case_quiet("usdc-fe.toml", source, *TINY_DRILL, "transient.end_time_s=1e-04")
    record = json.loads((source / "checkpoint" / "checkpoint.json").read_text())
    assert record["engine"][RECORD_KEY] == FREE_MODES
    case = load_for_run(CASES / "usdc-fe.toml", [*TINY_DRILL, "transient.end_time_s=1e-04",
                                                 f"transient.start_from={str(source)!r}"])
    warm = _drill(case=case)
    warm.start()
    saved = read_warm_start(case, MPI.COMM_WORLD, "modal").arrays
    for name in ("q", "v", "a"):
        np.testing.assert_array_equal(getattr(warm, name), saved[name], err_msg=name)
    assert warm.warm_start["source_time_s"] == pytest.approx(1e-4, rel=1e-12)
