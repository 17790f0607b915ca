"""Model surgery on a reduced structure: the steps of a chain of controlled runs (issue 25, docs/motor-chain.md),
each a :class:`app.reduced.model.ReducedModel` the modal tier runs unchanged.

A reduced model's coordinates are its interface displacements, its inputs (electrode potentials [V]) and its
fixed-interface modal amplitudes; ``P`` below are the inputs, ``F`` every other (free) coordinate.

* :func:`modal_pair`: the structure reduced to the ``count`` natural modes nearest a frequency (inputs held,
  mass-normalised, Phi) plus the inputs' static response Psi = -K_FF^-1 K_FP: q_F = Psi v + Phi eta. The
  modes' steady response to the inputs is the full reduced structure's exactly (the static correction carries the
  quasi-static response of every other mode to the inputs); contact forces load only the modes (no local or
  tangential compliance of the other modes).
* :func:`rigid_wave`: the sites' rows of a modal-pair model replaced by their free steady-state response to the
  drive, written as a real map of the electrode values v(t): y = G v. For electrode phasors a_e exp(i phi_e) the
  steady site displacement is Re(Y exp(i w t)) = Re(Y) cos wt - Im(Y) sin wt; cos wt and sin wt are the minimum-norm
  combinations of the electrode values, so G = scale (Re(Y) c^T - Im(Y) s^T): the wave the sites see is
  prescribed (a rigid stator surface), its amplitude ``scale`` times the free one; the contact forces load no
  coordinate. G holds for the drive's pattern (relative amplitudes and phases; any voltage, any start phase).
* ``rigid_wave(..., travelling=...)``: the same with the sites' wave reduced to its travelling component round
  the circle (:func:`travelling_component`): uniform amplitude, one order, one direction: the law's wave.
* :func:`planar_sites`: each site's rows of a cone contact projected onto the cone's normal and circumferential
  directions (the meridional component, along the cone's generator, dropped): the friction-drive law's
  kinematics (app/references/friction_drive.py). By reciprocity the sites' forces then have no meridional part on
  the structure either.
* :func:`site_wave`: the free steady wave at the sites in the cone's frame (normal, circumferential, meridional
  amplitudes [m]): what :func:`rigid_wave`'s ``scale`` is measured against.

Pure numpy/scipy on the model's arrays; the case keys ``reduction.surgery``, ``reduction.site_motion`` and
``reduction.wave_scale`` choose them (app/reduced/engine.py).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.linalg

from app.reduced.model import ReducedModel


def _partition(model: ReducedModel) -> tuple[np.ndarray, np.ndarray]:
    return model.input_coordinates, model.free_coordinates


def _transformed(model: ReducedModel, T: np.ndarray, **changes) -> ReducedModel:
    """The model in the coordinates q = T x (every operator and row projected)."""
    def rows(a):
        return a @ T if a.size else np.zeros((a.shape[0], T.shape[1]))

    values = dict(K=T.T @ model.K @ T, M=T.T @ model.M @ T, C=T.T @ model.C @ T,
                  charge_rows=rows(model.charge_rows), translation_loads=rows(model.translation_loads),
                  sample_rows=rows(model.sample_rows), site_rows=rows(model.site_rows),
                  vertex_basis=rows(model.vertex_basis), derived_basis=rows(model.derived_basis))
    values.update(changes)
    return dataclasses.replace(model, **values)


def pair_modes(model: ReducedModel, frequency_Hz: float, count: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(Phi (free coordinates x count), mass-normalised; natural frequencies [Hz]) of the ``count`` modes of the
    reduced structure nearest ``frequency_Hz``, inputs held (as ReducedModel.resonances_Hz finds them)."""
    _, F = _partition(model)
    values, vectors = scipy.linalg.eigh(model.K[np.ix_(F, F)], model.M[np.ix_(F, F)])
    frequencies = np.sqrt(np.abs(values)) / (2 * math.pi)
    chosen = np.sort(np.argsort(np.abs(frequencies - frequency_Hz))[:count])
    return vectors[:, chosen], frequencies[chosen]


def modal_pair(model: ReducedModel, frequency_Hz: float, count: int = 2) -> ReducedModel:
    """The model on [inputs, the ``count`` modes nearest ``frequency_Hz``] (module docstring)."""
    if len(model.inputs) != model.n_electrodes:
        raise ValueError("the modal pair keeps electrode inputs only (no base-motion patterns)")
    P, F = _partition(model)
    phi, frequencies = pair_modes(model, frequency_Hz, count)
    psi = -np.linalg.solve(model.K[np.ix_(F, F)], model.K[np.ix_(F, P)])
    T = np.zeros((model.size, P.size + count))
    T[P, np.arange(P.size)] = 1.0
    T[np.ix_(F, np.arange(P.size))] = psi
    T[np.ix_(F, P.size + np.arange(count))] = phi
    return _transformed(model, T, n_interface=0, mode_frequencies_Hz=frequencies,
                        enrichment_frequencies_Hz=np.zeros(0))


def harmonic_site_phasor(model: ReducedModel, frequency_Hz: float, phasors: np.ndarray) -> np.ndarray:
    """Complex steady-state site displacement Y (rows of site_rows) for the electrodes' phasors (the inputs
    v = Re(phasor exp(i w t)) [V]), every other coordinate free and no contact."""
    P, F = _partition(model)
    omega = 2 * math.pi * frequency_Hz
    D = model.K - omega**2 * model.M + 1j * omega * model.C
    x = np.zeros(model.size, dtype=complex)
    x[P] = phasors
    x[F] = np.linalg.solve(D[np.ix_(F, F)], -D[np.ix_(F, P)] @ x[P])
    return model.site_rows @ x


def drive_signals(amplitudes: np.ndarray, phases_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c, s): the minimum-norm weights with c . v(t) = cos wt and s . v(t) = sin wt for electrode values
    v_e(t) = a_e cos(wt + phi_e). ValueError when the electrodes do not span both (one phase, or opposite ones)."""
    E = np.vstack([amplitudes * np.cos(phases_rad), -amplitudes * np.sin(phases_rad)])     # v = E^T (cos, sin)
    if np.linalg.matrix_rank(E, tol=1e-9 * max(abs(E).max(), 1e-300)) < 2:
        raise ValueError("a prescribed wave needs electrodes driven in two independent phases")
    W = np.linalg.pinv(E.T)            # (2, n_e): W @ v = (cos, sin)
    return W[0], W[1]


def travelling_component(Y: np.ndarray, chosen: np.ndarray, frames: np.ndarray, angles_rad: np.ndarray
                         ) -> tuple[np.ndarray, int, int]:
    """(Y with the sites ``chosen`` given their wave's travelling component, its circumferential order k, its
    direction +-1): per site in its frame (normal, circumferential, meridional), the mean over the sites of
    Y exp(+-i k angle) times exp(-+i k angle), with k and the sign those of the largest such mean of the normal part
    (the sites evenly spaced round the circle: a discrete Fourier component). The wave of a pair that is not
    quite degenerate, or not quite a sine round the ring, becomes a uniform travelling wave, as the law's."""
    gdim = 3
    Yc = Y.reshape(-1, gdim)[chosen]
    local = np.einsum("nkj,nj->nk", frames, Yc)
    orders = np.arange(1, chosen.size // 2)
    best = (0.0, 1, 1)
    for k in orders:
        for sign in (1, -1):
            c = abs(np.mean(local[:, 0] * np.exp(sign * 1j * k * angles_rad)))
            if c > best[0]:
                best = (c, int(k), sign)
    _, k, sign = best
    phase = np.exp(sign * 1j * k * angles_rad)
    ideal = np.mean(local * phase[:, None], axis=0)[None, :] / phase[:, None]
    out = Y.reshape(-1, gdim).copy()
    out[chosen] = np.einsum("nkj,nk->nj", frames, ideal)
    return out.reshape(-1), k, sign


def rigid_wave(model: ReducedModel, frequency_Hz: float, amplitudes: np.ndarray, phases_rad: np.ndarray,
               scale: float = 1.0, travelling: tuple | None = None) -> ReducedModel:
    """A modal-pair (or any electrode-input) model whose sites follow ``scale`` x their free steady wave under the
    drive (weights ``amplitudes``, ``phases_rad``) as prescribed motion (module docstring); ``travelling`` =
    (chosen, frames, angles): those sites' wave reduced to its travelling component (:func:`travelling_component`)."""
    P, _ = _partition(model)
    Y = harmonic_site_phasor(model, frequency_Hz, amplitudes * np.exp(1j * phases_rad))
    if travelling is not None:
        Y = travelling_component(Y, *travelling)[0]
    c, s = drive_signals(amplitudes, phases_rad)
    rows = np.zeros_like(model.site_rows)
    rows[:, P] = scale * (np.outer(Y.real, c) - np.outer(Y.imag, s))
    return dataclasses.replace(model, site_rows=rows)


def cone_frames(points: np.ndarray, origin: np.ndarray, axis: np.ndarray, half_angle_rad: float) -> np.ndarray:
    """(n, 3, 3): each point's unit normal, circumferential and meridional directions on a cone about ``axis``
    through ``origin`` with the contact law's half angle (app/contact/law.py shape_gap: n = cos a e_r - sin a e_z;
    meridional m = sin a e_r + cos a e_z, circumferential e_z x e_r)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    d = np.asarray(points, float) - np.asarray(origin, float)
    radial = d - np.outer(d @ a, a)
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    ca, sa = math.cos(half_angle_rad), math.sin(half_angle_rad)
    normal = ca * radial - sa * a
    meridional = sa * radial + ca * a
    circumferential = np.cross(a, radial)
    return np.stack([normal, circumferential, meridional], axis=1)


def cone_angles(points: np.ndarray, origin: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Each point's angle [rad] round ``axis`` through ``origin`` (from a fixed direction normal to the axis)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    e1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    d = np.asarray(points, float) - np.asarray(origin, float)
    return np.arctan2(d @ e2, d @ e1)


def planar_sites(model: ReducedModel, chosen: np.ndarray, frames: np.ndarray) -> ReducedModel:
    """The rows of the sites ``chosen`` projected to drop their meridional component (frames from
    :func:`cone_frames` for those sites, in that order)."""
    if model.gdim != 3:
        raise ValueError("planar sites need a 3D structure")
    rows = model.site_rows.copy()
    for frame, i in zip(frames, np.asarray(chosen, int)):
        m = frame[2]
        block = rows[3 * i:3 * i + 3]
        rows[3 * i:3 * i + 3] = block - np.outer(m, m @ block)
    return dataclasses.replace(model, site_rows=rows)


def site_wave(model: ReducedModel, frequency_Hz: float, amplitudes: np.ndarray, phases_rad: np.ndarray,
              chosen: np.ndarray, frames: np.ndarray) -> dict:
    """The free steady wave at the sites ``chosen``: mean over them of the amplitude [m] along their normal,
    circumferential and meridional directions (the drive at weights ``amplitudes``, i.e. per volt of the largest)."""
    Y = harmonic_site_phasor(model, frequency_Hz, amplitudes * np.exp(1j * phases_rad)).reshape(-1, model.gdim)
    Y = Y[np.asarray(chosen, int)]
    parts = np.abs(np.einsum("nkj,nj->nk", frames, Y))
    return {"normal_m": float(parts[:, 0].mean()), "circumferential_m": float(parts[:, 1].mean()),
            "meridional_m": float(parts[:, 2].mean())}
