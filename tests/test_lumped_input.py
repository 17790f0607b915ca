"""Lumped tier input: bad values name their dotted key; circuit files; the shipped cases validate;
statistics hang together (the rock force closes the momentum balance)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from app.case.loader import read_toml
from app.case.lumped import CIRCUIT_KEYS, LumpedSection
from app.case.validate import from_dict
from app.errors import CaseError
from app.lumped.driver import compute
from app.lumped.parameters import derive_parameters

CASES = Path(__file__).resolve().parents[1] / "cases"


def section(data: dict, file: str = "case.toml") -> LumpedSection:
    return from_dict(LumpedSection, data, file, "lumped")


@pytest.mark.parametrize(
    "data, key",
    [
        ({"stem": {"mass_kg": -0.04}}, "lumped.stem.mass_kg"),
        ({"free_mass": {"mass_kg": 0.0}}, "lumped.free_mass.mass_kg"),
        ({"transducer": {"total_mass_kg": -0.3}}, "lumped.transducer.total_mass_kg"),
        ({"transducer": {"modal_mass_kg": 0}}, "lumped.transducer.modal_mass_kg"),
        (
            {"contact_tip_ball": {"stiffness_rule": "given", "stiffness_N_per_m": -1e7}},
            "lumped.contact_tip_ball.stiffness_N_per_m",
        ),
        (
            {"contact_stem_rock": {"youngs_modulus_lower_Pa": -5e10}},
            "lumped.contact_stem_rock.youngs_modulus_lower_Pa",
        ),
        ({"contact_ball_stem": {"damping_N_s_per_m": -3.0}}, "lumped.contact_ball_stem.damping_N_s_per_m"),
        ({"contact_ball_stem": {"restitution": 0.0}}, "lumped.contact_ball_stem.restitution"),
        ({"contact_ball_stem": {"restitution": 1.2}}, "lumped.contact_ball_stem.restitution"),
        ({"contact_tip_ball": {"stiffness_rule": "given"}}, "lumped.contact_tip_ball.stiffness_N_per_m"),
        ({"duration_s": 0.0}, "lumped.duration_s"),
        ({"duration_s": -0.2}, "lumped.duration_s"),
        ({"duration_s": 1e-3, "output": {"output_interval_s": 1e-2}}, "lumped.output.output_interval_s"),
        ({"downforce_N": -3.0}, "lumped.downforce_N"),
        (
            {"drive": {"tip_amplitude_m": 1e-5, "voltage_amplitude_V": 10.0}},
            "lumped.drive.voltage_amplitude_V",
        ),
        ({"drive": {"frequency_mode": "pll"}}, "lumped.drive.frequency_mode"),
        ({"free_mas": {"mass_kg": 0.002}}, "lumped.free_mas"),
        ({"source": "circuit"}, "lumped.circuit_file"),
        ({"source": "circuit", "circuit_file": "does-not-exist.json"}, "lumped.circuit_file"),
    ],
)
def test_bad_input_names_file_and_key(data, key):
    with pytest.raises(CaseError) as info:
        section(data)
    assert info.value.key == key
    assert info.value.file == "case.toml"
    assert "case.toml" in info.value.line() and key in info.value.line()


def test_negative_damping_message_says_it_would_pull():
    with pytest.raises(CaseError, match="pull"):
        section({"contact_stem_rock": {"damping_N_s_per_m": -1.0}})


def _circuit(mass=0.05, f=20100.0, q=400.0):
    omega = 2 * math.pi * f
    return {
        "modal_mass_kg": mass,
        "modal_stiffness_N_per_m": mass * omega**2,
        "modal_damping_N_s_per_m": mass * omega / q,
        "force_factor_N_per_V": 1.0,
        "clamped_capacitance_F": 8e-9,
    }


@pytest.mark.parametrize("nested", [False, True], ids=["flat", "summary"])
def test_circuit_source_equals_typed_parameters(tmp_path, nested):
    circuit = _circuit()
    payload = {"results": {"circuit": circuit}} if nested else circuit
    (tmp_path / "circuit.json").write_text(json.dumps(payload))
    case_file = tmp_path / "case.toml"
    from_circuit = derive_parameters(
        section({"source": "circuit", "circuit_file": "circuit.json"}, str(case_file))
    )
    typed = derive_parameters(section({}))
    for name in CIRCUIT_KEYS:
        assert getattr(from_circuit, name) == pytest.approx(getattr(typed, name), rel=1e-12)
    assert from_circuit.voltage_amplitude_V == pytest.approx(typed.voltage_amplitude_V, rel=1e-12)


def test_circuit_file_missing_a_key_is_rejected(tmp_path):
    circuit = _circuit()
    del circuit["force_factor_N_per_V"]
    (tmp_path / "c.json").write_text(json.dumps(circuit))
    with pytest.raises(CaseError, match="force_factor_N_per_V") as info:
        section({"source": "circuit", "circuit_file": str(tmp_path / "c.json")})
    assert info.value.key == "lumped.circuit_file"


def test_drive_voltage_gives_15_um_at_resonance():
    p = derive_parameters(section({}))
    # |x| = alpha U / (c_m omega) at resonance
    expected = (
        15e-6 * p.modal_damping_N_s_per_m * p.drive_angular_frequency_rad_per_s / p.force_factor_N_per_V
    )
    assert p.voltage_amplitude_V == pytest.approx(expected, rel=1e-12)
    assert p.free_mass_kg == pytest.approx(7850 * math.pi * 0.008**3 / 6, rel=1e-12)


@pytest.mark.parametrize("case", sorted(p.name for p in CASES.glob("usdc-lumped*.toml")))
def test_shipped_lumped_cases_validate(case):
    raw = read_toml(CASES / case)
    assert raw["tier"] == "lumped"
    sec = section(raw["lumped"], str(CASES / case))
    assert sec.duration_s >= 0.2


def test_statistics_on_a_short_drill_run(tmp_path):
    """The rock's mean force against the momentum balance of the whole drill. The only external forces
    on transducer (rigid coordinate z), ball and stem are gravity, the downforce and the rock, so
    integral F_rock dt = (weight + downforce) T + Delta(m_t z' + m_f w' + m_d v') exactly (the sum of
    eqs. 6-8); the modal coordinate x carries no momentum. The propagation is exact between events and
    the rock impulse is accumulated with the exact propagators, so the balance closes to round-off
    (measured 1e-13 of the impulse): 1e-9. The end term Delta(momentum) / T is the difference between
    the mean force and the static load (0.9 % of it in this 50 ms run), so "mean force = supported
    weight" alone would need a tolerance of the end effect and could not see a wrong impulse below it."""
    import h5py
    from conftest import run_case_quiet

    summary = run_case_quiet("usdc-lumped-9N.toml", tmp_path, "lumped.duration_s=0.05")
    results = summary["results"]["lumped"]
    rock = results["statistics"]["stem_rock_foundation"]
    p = results["parameters"]
    masses = {"transducer": p["transducer_mass_kg"], "ball": p["free_mass_kg"], "stem": p["stem_mass_kg"]}
    interval = summary["case"]["lumped"]["output"]["output_interval_s"]
    with h5py.File(tmp_path / "transient.h5") as f:
        duration = float(f["time_s"][-1] - f["time_s"][0])
        momentum_change = sum(m * float(f[f"{body}_velocity_m_per_s"][-1, -1] - f[f"{body}_velocity_m_per_s"][0, -1])
                              for body, m in masses.items())
        for name in ("time_s", "tip_displacement_m", "ball_position_m", "stem_position_m", "stem_rock_force_N",
                     "tip_ball_force_N", "ball_stem_force_N", "tip_ball_closed"):
            assert name in f and "units" in f[name].attrs and "description" in f[name].attrs
        assert f["stem_rock_force_N"].attrs["units"] == "N"
        assert len(f["time_s"]) == round(0.05 / interval) + 1
        assert f["events"].attrs["columns"].split(",")[0] == "time_s" and f["events"].shape[0] > 10
        assert f.attrs["model"].startswith("piezodyn lumped")
    assert duration == pytest.approx(0.05, rel=1e-12)
    weight = sum(masses.values()) * p["gravity_m_per_s2"] + p["downforce_N"]
    assert rock["static_load_N"] == pytest.approx(weight, rel=1e-12)
    assert rock["mean_force_N"] * duration == pytest.approx(weight * duration + momentum_change, rel=1e-9)
    assert abs(momentum_change) > 1e-3 * weight * duration       # the end term is there, and resolved
    assert results["statistics"]["impact_rate_per_s"]["stem_rock"] > 0
    assert results["energy_ledger"]["closure_relative"] < 1e-10
    for name, count in results["statistics"]["impact_count"].items():
        assert results["contacts"][name]["impacts"] == count
    assert (tmp_path / "transient.h5").exists() and (tmp_path / "transient_motion.png").exists()


def test_without_time_series_the_file_goes_and_the_statistics_stay(tmp_path):
    """``lumped.output.write_time_series = false``: no transient.h5 and no plots are left, the statistics (the
    scene's too, taken from the series before it is removed) are those of the run that keeps them."""
    from conftest import run_case_quiet

    kept = run_case_quiet("usdc-lumped.toml", tmp_path / "kept", "lumped.duration_s=0.01", "lumped.output.plots=false")
    gone = run_case_quiet("usdc-lumped.toml", tmp_path / "gone", "lumped.duration_s=0.01",
                          "lumped.output.write_time_series=false")
    assert not (tmp_path / "gone" / "transient.h5").exists() and not list((tmp_path / "gone").glob("*.png"))
    assert "transient.h5" not in gone["outputs"] and "time_series" not in gone["results"]["lumped"]
    assert gone["results"]["lumped"]["statistics"] == kept["results"]["lumped"]["statistics"]
    assert "transducer" in gone["results"]["lumped"]["statistics"]


def test_compute_is_deterministic():
    sec = section({"duration_s": 0.01, "downforce_N": 6.0})
    a, _ = compute(sec)
    b, _ = compute(sec)
    assert a["statistics"] == b["statistics"]
