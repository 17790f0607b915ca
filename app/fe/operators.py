"""Assembled PETSc operators of an FE model and its electrical states."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dolfinx import fem
from dolfinx.fem.petsc import assemble_matrix
from petsc4py import PETSc

from app.compat import petsc_vector
from app.fe.constraints import ConstraintSet
from app.fe.model import FEModel


@dataclass
class Operators:
    """K (coupled stiffness, symmetric indefinite), M (mass) and optionally C (damping), all without
    boundary conditions, in the full u-phi numbering."""

    K: PETSc.Mat
    M: PETSc.Mat
    C: PETSc.Mat | None = None

    def destroy(self):
        for mat in (self.K, self.M, self.C):
            if mat is not None:
                mat.destroy()


def _assemble(form) -> PETSc.Mat:
    A = assemble_matrix(fem.form(form), bcs=[])
    A.assemble()
    return A


def assemble_operators(model: FEModel, damping_frequency_Hz: float | None = None) -> Operators:
    ops = Operators(_assemble(model.stiffness), _assemble(model.mass))
    if damping_frequency_Hz is not None:
        add_damping(ops, model, damping_frequency_Hz)
    return ops


def add_damping(ops: Operators, model: FEModel, frequency_Hz: float) -> None:
    """(Re)assemble C for the material betas at ``frequency_Hz``; K and M are reused."""
    if ops.C is not None:
        ops.C.destroy()
        ops.C = None
    damping = model.damping(frequency_Hz)
    if damping is not None:
        ops.C = _assemble(damping)


def electrical_state(model: FEModel, state: str) -> ConstraintSet:
    """Constraints for ``state``: 'short' (driven electrodes at 0 V), 'open' (driven electrodes
    floating) or 'driven' (driven electrodes prescribed; same DOF set as 'short').

    In a Fourier-harmonic model of order n >= 1 the potential amplitude Phi multiplies cos n theta, and
    an electrode round the whole circumference is one equipotential, whose cos n theta part is zero: a
    floating electrode is then held at Phi = 0 like a grounded one (open circuit = short circuit)."""
    dirichlet = [model.support_dofs, model.grounded_dofs]
    floating = [model.electrode_dofs[n] for n in model.electrodes_of("floating")]
    dirichlet += [model.electrode_dofs[n] for n in model.electrodes_of("ground")]
    driven = [model.electrode_dofs[n] for n in model.electrodes_of("voltage")]
    if state in ("short", "driven"):
        dirichlet += driven
    elif state == "open":
        floating += driven
    else:
        raise ValueError(state)
    if model.kind == "fourier" and model.circumferential_order:
        dirichlet += floating
        floating = []
    return ConstraintSet(model.W, np.concatenate(dirichlet).astype(np.int32), floating)


def indicator(model: FEModel, electrode_names: list[str]) -> PETSc.Vec:
    """Vector equal to 1 on the potential DOFs of the named electrodes (full numbering)."""
    chi = fem.Function(model.W)
    for name in electrode_names:
        chi.x.array[model.electrode_dofs[name]] = 1.0
    return petsc_vector(chi).copy()


def charge(K: PETSc.Mat, x: PETSc.Vec, chi: PETSc.Vec) -> float:
    """Electrode charge Q = -chi^T K x [C]: the potential rows of the coupled form are minus the
    charges (see forms.piezo). Mass and damping have no potential rows."""
    Kx = K.createVecLeft()
    K.mult(x, Kx)
    value = -Kx.dot(chi)
    Kx.destroy()
    return value
