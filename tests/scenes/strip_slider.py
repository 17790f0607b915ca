"""A third scene, written outside app/ as a user would: the strip under a slider (the friction-drive
validation's scene, cases/validation/strip-friction-drive.toml). Its report: the slider's mean drive force
over the last drive periods against mu N, ``statistics.strip.force_ratio``, and the law's value beside it
(app/references/friction_drive.py), as a summary key, a table row and a sweep column. Registered through
the registry when imported (PIEZODYN_SCENES=scenes.strip_slider)."""

from __future__ import annotations

import math

import numpy as np

from app import series as S
from app.references import friction_drive as fd
from app.scenes.registry import SceneReport, register

PERIODS = 4


class StripSlider(SceneReport):
    name = "strip-slider"
    sweep_columns = ("statistics.strip.force_ratio", "statistics.strip.normal_force_N")

    def statistics(self, data, case, results):
        cfg = case.transient
        contact, slider = cfg.contacts[0], cfg.bodies[0]
        t = data[S.TIME]
        period = 1.0 / cfg.drive.frequency_Hz
        window = t >= t[-1] - PERIODS * period - 1e-12
        force = data[S.contact_force(contact.name)][window]
        tw = t[window]

        def mean(y):
            return float(np.trapz(y, tw) / (tw[-1] - tw[0]))

        normal, drive = mean(force[:, 1]), -mean(force[:, 0])
        mu = contact.friction.mu_dynamic
        wave = cfg.base_motions[0]
        carrier = case.materials[case.regions[0].material]
        h = case.geometry.parameters["length_m"]
        k = 2 * math.pi / wave.wavelength_m
        w_s, u_s = fd.layer_surface_amplitudes(wave.normal_amplitude_m, wave.tangential_amplitude_m, k, h,
                                               carrier.poisson)
        omega = 2 * math.pi * cfg.drive.frequency_Hz
        theta_c = math.acos((slider.position_m[1] - h) / w_s)
        speed = -slider.velocity_m_per_s[0]
        return {"strip": {"normal_force_N": normal, "drive_force_N": drive, "force_ratio": drive / (mu * normal),
                          "law_force_ratio": float(fd.force_ratio(speed, omega * u_s, theta_c))}}

    def table_rows(self, results):
        strip = (results.get("statistics") or {}).get("strip")
        if not strip:
            return []
        return [("slider drive force / (mu N)", f"{strip['force_ratio']:+.4f}", "1"),
                ("the friction-drive law's", f"{strip['law_force_ratio']:+.4f}", "1")]


SCENE = register(StripSlider())
