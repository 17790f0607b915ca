"""The drill scene in the modal tier against the FE tier: the same case, ``tier = "modal"``.

Before the impact motion's chaos separates them, the two tiers must give the same contact events:
the first 20 closings (tip-ball, ball-stem, stem-rock) in the same order at the same times, to the
event resolution of the step control (change_s = 62.5 ns; measured: 0.25 us at the default basis).
"""

import h5py
import numpy as np
import pytest
from conftest import run_case_quiet

END_S = 0.0009          # the first 20 contact events happen within 0.86 ms
SETTINGS = [f"transient.end_time_s={END_S}", "output.fields=false", "output.plots=false"]


def _closing_events(path):
    with h5py.File(path, "r") as f:
        t = f["time_s"][:]
        events = []
        for name in ("tip_ball", "ball_stem", "stem_rock"):
            closed = f[f"{name}_closed"][:]
            rows = np.flatnonzero(np.diff(np.concatenate([[0], closed])) == 1)
            events += [(float(t[i]), name) for i in rows if i > 0]
    return sorted(events)


@pytest.mark.mpi
def test_drill_contact_events_match_the_fe_tier(shared_tmp):
    fe = run_case_quiet("usdc-fe.toml", shared_tmp / "fe", *SETTINGS)
    modal = run_case_quiet("usdc-fe.toml", shared_tmp / "modal", 'tier="modal"', *SETTINGS)
    reduction = modal["results"]["transient"]["reduction"]
    assert reduction["interface_dofs"] == 1 and reduction["electrodes"] == ["hot"]
    assert modal["results"]["transient"]["drive_voltage_V"] == pytest.approx(
        fe["results"]["transient"]["drive_voltage_V"], rel=1e-4)
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank != 0:
        return
    reference = _closing_events(shared_tmp / "fe" / "transient.h5")
    reduced = _closing_events(shared_tmp / "modal" / "transient.h5")
    assert len(reference) >= 20 and len(reduced) >= 20
    assert [name for _, name in reduced[:20]] == [name for _, name in reference[:20]]
    errors = [abs(a - b) for (a, _), (b, _) in zip(reduced[:20], reference[:20])]
    assert max(errors) <= 0.5e-6, errors
