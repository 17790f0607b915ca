"""Material library and user-defined materials, validated before any dolfinx object exists.

Library data (SI units): PZT-4 in stress-charge form exactly as the wedge-wave motor paper's
Table 2 (its density is not given there: 7500 kg/m^3, the common datasheet value); stainless
steel (Table 3) and naval brass (Table 1) of the same paper; a generic structural steel. Mechanical
quality factors follow the drill paper (steel 1000, piezoceramic 400).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from app.case.validate import param
from app.errors import CaseError
from forms import voigt

VACUUM_PERMITTIVITY_F_per_m = 8.854e-12


@dataclass(frozen=True)
class PiezoEForm:
    """Stress-charge data of a 6mm (poled along material axis 3) ceramic."""

    c11_Pa: float = param(gt=0)
    c12_Pa: float = param()
    c13_Pa: float = param()
    c33_Pa: float = param(gt=0)
    c44_Pa: float = param(gt=0)
    e31_C_per_m2: float = param()
    e33_C_per_m2: float = param()
    e15_C_per_m2: float = param()
    eps11_rel: float = param(gt=0, doc="eps11^S / eps0")
    eps33_rel: float = param(gt=0, doc="eps33^S / eps0")
    c66_Pa: float | None = param(None, gt=0, doc="default (c11 - c12)/2")


@dataclass(frozen=True)
class PiezoDForm:
    """Strain-charge data (datasheet form), converted to stress-charge on input."""

    s11_per_Pa: float = param(gt=0)
    s12_per_Pa: float = param()
    s13_per_Pa: float = param()
    s33_per_Pa: float = param(gt=0)
    s44_per_Pa: float = param(gt=0)
    d31_C_per_N: float = param()
    d33_C_per_N: float = param()
    d15_C_per_N: float = param()
    eps11T_rel: float = param(gt=0, doc="eps11^T / eps0")
    eps33T_rel: float = param(gt=0, doc="eps33^T / eps0")
    s66_per_Pa: float | None = param(None, gt=0, doc="default 2 (s11 - s12)")


@dataclass(frozen=True)
class Material:
    """One material. ``library`` copies a library entry; other keys override it."""

    library: str | None = param(None)
    density_kg_per_m3: float | None = param(None, gt=0)
    young_Pa: float | None = param(None, gt=0)
    poisson: float | None = param(None, gt=-1, lt=0.5)
    piezo_e: PiezoEForm | None = None
    piezo_d: PiezoDForm | None = None
    quality_factor: float | None = param(None, gt=0, doc="mechanical Q_m; beta_j = 1/(omega Q_m)")

    @property
    def is_piezo(self) -> bool:
        return self.piezo_e is not None or self.piezo_d is not None

    def tensors(self):
        """(c [Pa] 6x6, e [C/m^2] 3x6 or None, eps^S [F/m] 3x3 or None) in the material frame."""
        if self.piezo_e is not None:
            p = self.piezo_e
            c = voigt.transversely_isotropic_stiffness(p.c11_Pa, p.c12_Pa, p.c13_Pa, p.c33_Pa, p.c44_Pa,
                                                       p.c66_Pa)
            e = voigt.piezo_e_6mm(p.e31_C_per_m2, p.e33_C_per_m2, p.e15_C_per_m2)
            eps = np.diag([p.eps11_rel, p.eps11_rel, p.eps33_rel]) * VACUUM_PERMITTIVITY_F_per_m
            return c, e, eps
        if self.piezo_d is not None:
            p = self.piezo_d
            s66 = 2 * (p.s11_per_Pa - p.s12_per_Pa) if p.s66_per_Pa is None else p.s66_per_Pa
            sE = np.array([
                [p.s11_per_Pa, p.s12_per_Pa, p.s13_per_Pa, 0, 0, 0],
                [p.s12_per_Pa, p.s11_per_Pa, p.s13_per_Pa, 0, 0, 0],
                [p.s13_per_Pa, p.s13_per_Pa, p.s33_per_Pa, 0, 0, 0],
                [0, 0, 0, p.s44_per_Pa, 0, 0],
                [0, 0, 0, 0, p.s44_per_Pa, 0],
                [0, 0, 0, 0, 0, s66],
            ])
            d = np.zeros((3, 6))
            d[0, 4] = d[1, 3] = p.d15_C_per_N
            d[2, 0] = d[2, 1] = p.d31_C_per_N
            d[2, 2] = p.d33_C_per_N
            epsT = np.diag([p.eps11T_rel, p.eps11T_rel, p.eps33T_rel]) * VACUUM_PERMITTIVITY_F_per_m
            return voigt.d_form_to_e_form(sE, d, epsT)
        return voigt.isotropic_stiffness(self.young_Pa, self.poisson), None, None

    def check_complete(self, file, prefix):
        if self.piezo_e is not None and self.piezo_d is not None:
            raise CaseError(file, prefix, "give either piezo_e or piezo_d, not both")
        if self.density_kg_per_m3 is None:
            raise CaseError(file, f"{prefix}.density_kg_per_m3", "required key is missing")
        if not self.is_piezo and (self.young_Pa is None or self.poisson is None):
            missing = "young_Pa" if self.young_Pa is None else "poisson"
            raise CaseError(file, f"{prefix}.{missing}", "required for a non-piezoelectric material")
        c, e, eps = self.tensors()
        if not np.all(np.isfinite(c)) or np.linalg.eigvalsh(0.5 * (c + c.T)).min() <= 0:
            key = f"{prefix}.piezo_d" if self.piezo_d is not None else f"{prefix}.piezo_e"
            key = key if self.is_piezo else f"{prefix}.young_Pa"
            raise CaseError(file, key, "elastic tensor is not positive definite")
        if eps is not None and np.linalg.eigvalsh(eps).min() <= 0:
            raise CaseError(file, prefix, "clamped permittivity eps^S is not positive definite")


LIBRARY: dict[str, Material] = {
    "PZT-4": Material(
        density_kg_per_m3=7500.0,
        piezo_e=PiezoEForm(
            c11_Pa=139e9, c12_Pa=77.8e9, c13_Pa=74.3e9, c33_Pa=115e9, c44_Pa=25.6e9,
            e31_C_per_m2=-5.6, e33_C_per_m2=15.1, e15_C_per_m2=12.7,
            eps11_rel=730.0, eps33_rel=635.0,
        ),
        quality_factor=400.0,
    ),
    "stainless-steel": Material(density_kg_per_m3=7820.0, young_Pa=201.25e9, poisson=0.29,
                                quality_factor=1000.0),
    "naval-brass": Material(density_kg_per_m3=8470.0, young_Pa=105.46e9, poisson=0.34,
                            quality_factor=1000.0),
    "structural-steel": Material(density_kg_per_m3=7850.0, young_Pa=200e9, poisson=0.30,
                                 quality_factor=1000.0),
}


def resolve(material: Material, file, key) -> Material:
    """Merge a library entry with the user's overrides, then validate the result."""
    if material.library is None:
        material.check_complete(file, key)
        return material
    if material.library not in LIBRARY:
        raise CaseError(file, f"{key}.library",
                        f"unknown library material {material.library!r}; known: {', '.join(LIBRARY)}")
    base = LIBRARY[material.library]
    overrides = {f.name: getattr(material, f.name) for f in dataclasses.fields(Material)
                 if f.name != "library" and getattr(material, f.name) is not None}
    if "piezo_d" in overrides:
        overrides["piezo_e"] = None
    merged = dataclasses.replace(base, **overrides)
    merged = dataclasses.replace(merged, library=material.library)
    merged.check_complete(file, key)
    return merged
