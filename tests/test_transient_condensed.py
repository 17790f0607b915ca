"""The condensed step (Newton on contact forces + rigid DOFs, app/transient/coupled.py) against the
same step iterated on all FE + rigid unknowns (demos/demo_fullspace.py): same time steps, same
contact forces and motions to solver tolerance, and a converged condensed step leaves no residual
in the uncondensed equations."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from app.transient.control import StepSizes
from app.transient.coupled import CoupledSystem
from app.transient.stepper import run_scene
from demos.demo_fullspace import FullSpaceSystem
from demos.demo_rod_impact import RodImpact, build_rod_impact, rod_step_sizes
from demos.demo_vibrating_block import vibrating_block_with_ball
from forms.newmark import TimeScheme


def _rod_history(system_class, check_residual=False):
    rod = RodImpact(elements_along=20)
    system, state = build_rod_impact(MPI.COMM_WORLD, rod, TimeScheme.generalized_alpha(0.5), system_class)
    worst = []

    def on_step(rec):
        if check_residual and rec["contact_closed"][0]:
            # SNES stops at the absolute tolerance or 1e-10 x the first residual (~ the contact force)
            atol = system.relative_force_tolerance * system._force_scale + system._roundoff_force
            force = abs(rec["contact_force_N"]["rod_wall"][0])
            worst.append(system.full_residual_norm() / max(atol, 1e-9 * force))

    from app.transient.control import StepController
    from app.transient.stepper import TimeStepper

    records = []
    stepper = TimeStepper(system, StepController(rod_step_sizes(rod)))
    stepper.run(state, 1.4 * rod.contact_duration_s, on_step=lambda rec: (records.append(rec), on_step(rec)))
    return rod, records, stepper, worst


@pytest.mark.mpi
def test_condensed_equals_full_space_on_rod_impact():
    rod, condensed, stats_c, worst = _rod_history(CoupledSystem, check_residual=True)
    _, full, stats_f, _ = _rod_history(FullSpaceSystem)
    assert len(condensed) == len(full)
    np.testing.assert_allclose([r["time_s"] for r in condensed], [r["time_s"] for r in full], rtol=1e-12)
    f_c = np.array([r["contact_force_N"]["rod_wall"][0] for r in condensed])
    f_f = np.array([r["contact_force_N"]["rod_wall"][0] for r in full])
    assert np.count_nonzero(f_c) > 20
    np.testing.assert_allclose(f_c, f_f, rtol=1e-7, atol=1e-7 * rod.contact_force_N)
    # The uncondensed residual of every converged contact step is within the Newton tolerance.
    assert len(worst) > 20 and max(worst) < 1.0
    # Contact iterations cost no back-substitution: the condensed run needs no more Newton
    # iterations than the full-space one.
    assert stats_c.stats.newton_iterations <= stats_f.stats.newton_iterations + len(condensed) // 10


@pytest.mark.mpi
def test_condensed_equals_full_space_with_free_ball_and_shaken_base():
    """FE + a free rigid ball + a moving Dirichlet base (the predictor's Dirichlet correction)."""
    sizes = StepSizes(open_s=2.5e-6, closed_s=5e-7, change_s=5e-8, min_s=1e-12)
    out = []
    for cls in (CoupledSystem, FullSpaceSystem):
        system, state = vibrating_block_with_ball(MPI.COMM_WORLD, TimeScheme.generalized_alpha(0.7),
                                                  amplitude_m=0.3e-6, frequency_Hz=3000.0, system_class=cls)
        records, final, _ = run_scene(system, state, sizes, 1.5e-3)
        out.append((records, final))
    (rc, fc), (rf, ff) = out
    assert len(rc) == len(rf)
    z_c = np.array([r["position_m"][1] for r in rc])
    z_f = np.array([r["position_m"][1] for r in rf])
    assert np.ptp(z_c) > 1e-7                           # the ball moved
    np.testing.assert_allclose(z_c, z_f, rtol=0, atol=1e-8 * np.ptp(z_c))   # solver tolerance
    assert sum(r["contact_closed"][0] for r in rc) > 10
    assert fc.u.size == ff.u.size
    assert np.max(np.abs(fc.u - ff.u)) == pytest.approx(0.0, abs=1e-8 * np.max(np.abs(ff.u)))
