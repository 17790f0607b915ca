"""The first run of the motor's chain (docs/motor-chain.md) against the friction-drive law: the shipped motor case on
the tests' coarse stator (6 mm, 2 mm at the tip, 32 interface nodes; the case's 512 contact points), its F(1,4)
pair's free wave at the contact reduced to a uniform travelling wave and prescribed with its normal and
circumferential parts only (``reduction.surgery = "travelling_wave"``, ``site_motion = "planar"``): the law's
kinematics, a rigid stator surface, the penalty as Winkler layer.

* Held rotor: every contact point slides forward, so the torque is mu N r (law: F = mu N at V = 0), mu = mu_s
  (DC = 0), with the run's N and the friction's lever r the contact point's, r_c - W cos(alpha) (the crest pushes it
  in by the normal wave's radial part: 0.25 % here). Measured T / (mu N r_c) = 0.99747 and T / (mu N (r_c - W cos
  alpha)) = 1.00004 here (3 ms); over the chain's 1 000-period window 0.99810 and 1.000003
  (docs/figures/motor_chain_coarse.csv). Allowed 0.1 % (what is left: the regularisation, 1e-4 m/s against slip
  speeds of metres per second, and the rotor's small axial motion giving the slip a meridional share); without the
  lever's correction the test fails.
* Free rotor: the no-load deficit 1 - V_0 / (w U_t) against the law's (app/references/friction_drive.py) with the
  run's own N, W, U_t and the contact half-angle those give. The run's V_0 and crest speed carry two terms the law
  (first order in the wave) leaves out, each larger than the deficit (6.2e-4) itself: the contact point sits
  W cos(alpha) = 33 um inside r_c (-0.25 %), and the scheme's crest speed is |g_v| U_t, |g_v| / w - 1 = 5.8e-4 at
  80 steps per period (trapezoidal rule: tan(w dt / 2) / (w dt / 2)). With both (derived, not fitted) the deficit
  is the law's to +2.0 % here (150 periods, the rotor started at the crest speed). The chain's 2 000-period runs
  on this stator: +1.3 % with a tenth of the regularisation, +1.8 % at 80 steps per period, +3.1 % at 40
  (docs/figures/motor_chain_coarse.csv); on the case mesh +0.6, +1.8, +1.8 % (docs/motor-chain.md). Allowed
  5 %. Without the contact radius the deficit is -1.9e-3 (-410 %), and with the prescribed wave started on the
  continuous rates instead of the scheme's steady state (an alternation of the prescribed site velocity from step
  to step, app/reduced/engine.py) +17 %: measured, so the test sees either.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest
from conftest import CASES

ROOT = Path(__file__).resolve().parents[1]
MOTOR = CASES / "wwusm-motor.toml"
STEP_S = 1 / (36065.0 * 80)
COARSE = ["geometry.parameters.mesh_size_m=0.006", "geometry.parameters.tip_mesh_size_m=0.002",
          "reduction.interface_nodes=32", "output.fields=false", "output.plots=false",
          'reduction.surgery="travelling_wave"', 'reduction.site_motion="planar"',
          f"transient.steps.open_s={STEP_S!r}", f"transient.steps.closed_s={STEP_S!r}",
          f"transient.steps.change_s={STEP_S!r}"]


@pytest.fixture(scope="module")
def chain_first(tmp_path_factory):
    from app.runner import run_case

    sys.path.insert(0, str(ROOT / "bench"))
    root = tmp_path_factory.mktemp("chain")
    probe = run_case(MOTOR, COARSE + ["transient.end_time_s=6e-5"], root / "probe", quiet=True)
    wave = probe["results"]["transient"]["surgery"]["site_wave_m"]
    omega = 2 * math.pi * probe["results"]["transient"]["drive_frequency_Hz"]
    start = omega * wave["circumferential_m"] / 0.012862384017536786
    free = run_case(MOTOR, COARSE + ["transient.end_time_s=0.004", "transient.steady_state.min_cycles=150",
                                     f"transient.bodies[0].rotations[0].rate_rad_per_s={start!r}"],
                    root / "free", quiet=True)
    held = run_case(MOTOR, COARSE + ["transient.end_time_s=0.003", 'transient.bodies[0].rotations[0].motion="fixed"'],
                    root / "held", quiet=True)
    return root, free, held


def test_held_rotor_takes_mu_N_r(chain_first):
    import bench_motor_chain as chain

    root, _, _ = chain_first
    row = chain.chain_row(chain.read_summary(root / "held"), root / "held", "held", 1.0)
    assert row["stall_ratio_at_contact"] == pytest.approx(1.0, abs=1e-3)


def test_no_load_deficit_is_the_laws(chain_first):
    import bench_motor_chain as chain

    root, free, _ = chain_first
    summary = chain.read_summary(root / "free")
    row = chain.chain_row(summary, root / "free", "free", 1.0)
    assert row["deficit_law"] == pytest.approx(6.5e-4, rel=0.1)        # the regime: theta_c ~ 0.1 rad
    assert row["deficit"] == pytest.approx(row["deficit_law"], rel=0.05)
