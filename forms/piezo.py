"""e-type (stress-charge) piezoelectric law and the coupled u-phi operators.

    T = c^E S - e^T E,    D = e S + eps^S E,    E = -grad(phi)

The coupled stiffness form is symmetric and indefinite,

    a((u, phi), (v, psi)) = int S(v) . T(u, phi) dV - int E(psi) . D(u, phi) dV,

so its potential rows are minus the electrode charges: Q_electrode = -a(w, (0, chi)) with chi the
electrode's indicator function (the generalised reaction of the potential DOFs).
"""

from __future__ import annotations

import ufl

from forms.kinematics import electric_field, strain_voigt


def stress(S, E, c, e):
    """Stress 6-vector [Pa] from strain S, field E [V/m], stiffness c^E [Pa], e [C/m^2]."""
    return ufl.dot(c, S) - ufl.dot(ufl.transpose(e), E)


def electric_displacement(S, E, e, eps):
    """Electric displacement 3-vector [C/m^2] from strain S, field E and permittivity eps^S [F/m]."""
    return ufl.dot(e, S) + ufl.dot(eps, E)


def derived_quantities(u, phi, c, e, eps, kind):
    """(strain S [-], stress T [Pa], field E [V/m], displacement D [C/m^2]) of a region from the
    displacement ``u`` and potential ``phi``, by the law above: the Voigt 6-vectors S and T (IEEE order,
    engineering shear strain) and the 3-vectors E and D in the model's 3D axes. A region without
    piezoelectric data (e is None) is elastic, T = c S, and carries no D (its potential is held at 0 V)."""
    S, E = strain_voigt(u, kind), electric_field(phi, kind)
    if e is None:
        return S, ufl.dot(c, S), E, ufl.as_vector([0.0, 0.0, 0.0])
    return S, stress(S, E, c, e), E, electric_displacement(S, E, e, eps)


def coupled_stiffness(u, phi, v, psi, c, e, eps, kind: str, dx, weight=1.0):
    """Symmetric indefinite u-phi stiffness form of one piezoelectric region over measure ``dx``;
    ``weight`` is the volume weight (2 pi r for axisymmetric, see kinematics.volume_weight)."""
    S_u, S_v = strain_voigt(u, kind), strain_voigt(v, kind)
    E_phi, E_psi = electric_field(phi, kind), electric_field(psi, kind)
    T = stress(S_u, E_phi, c, e)
    D = electric_displacement(S_u, E_phi, e, eps)
    return (ufl.inner(T, S_v) - ufl.inner(D, E_psi)) * weight * dx


def elastic_stiffness(u, v, c, kind: str, dx, weight=1.0):
    """Purely mechanical stiffness form int S(v) . c S(u) dV (also the u-u block of a piezo region,
    used for stiffness-proportional damping)."""
    return ufl.inner(ufl.dot(c, strain_voigt(u, kind)), strain_voigt(v, kind)) * weight * dx


def dielectric_stiffness(phi, psi, eps, kind: str, dx, weight=1.0):
    """int E(psi) . eps E(phi) dV: the clamped dielectric block (gives the clamped capacitance)."""
    return ufl.inner(ufl.dot(eps, electric_field(phi, kind)), electric_field(psi, kind)) * weight * dx
