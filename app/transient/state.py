"""The state of a transient model at one time: FE fields (local arrays incl. ghosts) and rigid DOFs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class TransientState:
    """Time [s]; FE displacement/velocity/acceleration as local DOF arrays (owned + ghosts, the layout
    of ``Function.x.array``; empty without an FE part); rigid positions/velocities/accelerations
    (body-major, replicated on every rank)."""

    t: float
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    z: np.ndarray
    zd: np.ndarray
    zdd: np.ndarray

    def copy(self) -> TransientState:
        return TransientState(self.t, self.u.copy(), self.v.copy(), self.a.copy(),
                              self.z.copy(), self.zd.copy(), self.zdd.copy())

    def as_dict(self) -> dict:
        return {"t": np.array(self.t), "u": self.u, "v": self.v, "a": self.a,
                "z": self.z, "zd": self.zd, "zdd": self.zdd}

    @classmethod
    def from_dict(cls, data) -> TransientState:
        return cls(float(data["t"]), *(np.array(data[k]) for k in ("u", "v", "a", "z", "zd", "zdd")))
