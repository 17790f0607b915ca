"""Mode identification and travelling-wave measures of bodies of revolution about z.

Displacements are sampled round a circle (r, z) and along a generatrix, turned into cylindrical
components (r, theta, z) and Fourier-analysed round the circle:
- circumferential order n: the harmonic with the most energy over all three components;
- axial order m: 1 + the sign changes of the n-th harmonic of u_r along the generatrix (weak values
  below 5 % of the largest are skipped), so m = 1 is the family without a nodal circle; not given
  for torsional (u_theta-dominated) modes;
- partner: the other mode of the same (m, n) nearest in frequency; split = its frequency difference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from app.compat import cell_candidates, cell_geometry_nodes

SKIP_FRACTION = 0.05
SPECTRUM_ORDERS = 16  # orders reported round the wave's circle: 0..16 covers n = 4's neighbours 0, 8, 12, 16


class PointSet:
    """Values of a Function at many physical points on any partition (result on every rank)."""

    def __init__(self, mesh, points: np.ndarray):
        self.mesh = mesh
        pts = np.zeros((points.shape[0], 3))
        pts[:, : points.shape[1]] = points
        self.points = pts
        candidates = cell_candidates(mesh, pts)
        self._cell_nodes = cell_geometry_nodes(mesh)
        n_owned = mesh.topology.index_map(mesh.topology.dim).size_local
        size = mesh.comm.size
        first = np.full(len(pts), -1, dtype=np.int32)
        rank_has = np.full(len(pts), size, dtype=np.int32)
        for i in range(len(pts)):
            owned = [c for c in candidates.links(i) if c < n_owned and self._contains(c, pts[i])]
            if owned:
                first[i] = owned[0]
                rank_has[i] = mesh.comm.rank
        owner = np.empty_like(rank_has)
        mesh.comm.Allreduce(rank_has, owner, op=MPI.MIN)
        self.found = owner < size
        mine = owner == mesh.comm.rank
        self.local_index = np.flatnonzero(mine)
        self.cells = first[mine]

    def _contains(self, cell: int, point: np.ndarray) -> bool:
        """Is ``point`` in ``cell``? Barycentric test on a simplex (a tetrahedron or a triangle of a 2D mesh; a
        curved cell is tested by the straight-sided simplex of its vertices); for a quadrilateral or
        hexahedron, the reference point of its multilinear map (Newton) must lie in [0, 1]^d. dolfinx 0.5's
        compute_colliding_cells (GJK with an absolute tolerance) misses interior points of millimetre-sized
        cells in SI units."""
        tdim = self.mesh.topology.dim
        vertices = 2**tdim if self.mesh.topology.cell_type.name in ("quadrilateral", "hexahedron") else tdim + 1
        nodes = self.mesh.geometry.x[self._cell_nodes[cell, :vertices], :tdim]
        if vertices == tdim + 1:
            jacobian = (nodes[1:] - nodes[0]).T
            lam = np.linalg.solve(jacobian, point[:tdim] - nodes[0])
            return bool(lam.min() >= -1e-10 and lam.sum() <= 1 + 1e-10)
        return _in_multilinear_cell(nodes, point[:tdim])

    def __call__(self, function) -> np.ndarray:
        """(n_points, value_size) array; points outside the mesh give NaN."""
        size = function.function_space.dofmap.index_map_bs
        local = np.zeros((len(self.points), size))
        if self.local_index.size:
            local[self.local_index] = np.asarray(function.eval(self.points[self.local_index], self.cells)).reshape(
                self.local_index.size, -1)
        out = np.empty_like(local)
        self.mesh.comm.Allreduce(local, out, op=MPI.SUM)
        out[~self.found] = np.nan
        return out


def _in_multilinear_cell(nodes: np.ndarray, point: np.ndarray, tol: float = 1e-9) -> bool:
    """Point in a quadrilateral or hexahedron with dolfinx's vertex order (vertex k at the reference corner
    whose coordinate i is bit i of k), by Newton on its multilinear map from [0, 1]^d."""
    d = nodes.shape[1]
    corners = np.array([[(k >> i) & 1 for i in range(d)] for k in range(2**d)], dtype=float)
    xi = np.full(d, 0.5)
    for _ in range(30):
        weights = np.prod(np.where(corners == 1, xi, 1 - xi), axis=1)            # (2^d,)
        grads = np.empty((2**d, d))
        for i in range(d):
            others = np.delete(np.arange(d), i)
            grads[:, i] = np.where(corners[:, i] == 1, 1.0, -1.0) * np.prod(
                np.where(corners[:, others] == 1, xi[others], 1 - xi[others]), axis=1)
        residual = weights @ nodes - point
        step = np.linalg.solve(nodes.T @ grads, residual)
        xi = xi - step
        if np.abs(step).max() < 1e-13:
            break
    return bool(xi.min() >= -tol and xi.max() <= 1 + tol)


def circle_points(radius_m: float, height_m: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    theta = 2 * np.pi * np.arange(n) / n
    return np.column_stack([radius_m * np.cos(theta), radius_m * np.sin(theta), np.full(n, height_m)]), theta


def cylindrical(u_xyz: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(n, 3) Cartesian -> (n, 3) cylindrical (u_r, u_theta, u_z) at angles ``theta``."""
    c, s = np.cos(theta), np.sin(theta)
    return np.column_stack([c * u_xyz[:, 0] + s * u_xyz[:, 1], -s * u_xyz[:, 0] + c * u_xyz[:, 1], u_xyz[:, 2]])


def harmonics(values: np.ndarray) -> np.ndarray:
    """Complex Fourier coefficients c_k, k = 0..N-1, of samples round the circle along axis 0:
    values(theta_j) = sum_k c_k exp(i k theta_j)."""
    return np.fft.fft(values, axis=0) / values.shape[0]


def circumferential_order(u_cyl: np.ndarray) -> tuple[int, str, float]:
    """(n, dominant component 'r'/'theta'/'z', fraction of the energy in order n)."""
    c = harmonics(u_cyl)
    n_max = u_cyl.shape[0] // 2
    energy = np.abs(c) ** 2
    folded = energy[: n_max + 1].copy()
    folded[1:n_max] += energy[-1:-n_max:-1]  # order k and its mirror N - k
    per_order = folded.sum(axis=1)
    n = int(np.argmax(per_order))
    component = ("r", "theta", "z")[int(np.argmax(folded[n]))]
    return n, component, float(per_order[n] / per_order.sum()) if per_order.sum() > 0 else 0.0


def axial_order(u_r_grid: np.ndarray, n: int) -> int:
    """1 + sign changes along the generatrix of the n-th harmonic of u_r; grid (n_theta, n_z)."""
    c = harmonics(u_r_grid)[n]  # (n_z,)
    k = int(np.argmax(np.abs(c)))
    if abs(c[k]) == 0:
        return 1
    real = (c * np.exp(-1j * np.angle(c[k]))).real
    kept = real[np.abs(real) > SKIP_FRACTION * abs(c[k])]
    return 1 + int(np.count_nonzero(np.diff(np.sign(kept)) != 0))


@dataclass
class ModeOrder:
    n: int
    m: int | None
    component: str
    purity: float
    partner: int | None = None
    split_Hz: float | None = None


class ModeIdentifier:
    """Samples a displacement Function on the identification circle and generatrix."""

    def __init__(self, mesh, cfg):
        self.cfg = cfg
        pts, self.theta = circle_points(cfg.circle_radius_m, cfg.circle_height_m, cfg.n_circle_points)
        self.circle = PointSet(mesh, pts)
        if not self.circle.found.all():
            raise ValueError("circle")
        self.line = None
        if cfg.line_radius_m is not None:
            z = np.linspace(cfg.line_z_start_m, cfg.line_z_stop_m, cfg.n_line_points)
            grid = np.array([[cfg.line_radius_m * math.cos(t), cfg.line_radius_m * math.sin(t), zz]
                             for t in self.theta for zz in z])
            self.line = PointSet(mesh, grid)
            self.n_z = z.size
            if not self.line.found.all():
                raise ValueError("line")

    def circle_cylindrical(self, u) -> np.ndarray:
        return cylindrical(self.circle(u), self.theta)

    def order(self, u) -> ModeOrder:
        n, component, purity = circumferential_order(self.circle_cylindrical(u))
        m = None
        if self.line is not None and component != "theta":  # u_r says nothing of a torsional shape
            values = self.line(u).reshape(self.theta.size, self.n_z, 3)
            u_r = np.cos(self.theta)[:, None] * values[..., 0] + np.sin(self.theta)[:, None] * values[..., 1]
            m = axial_order(u_r, n)
        return ModeOrder(n, m, component, purity)


class FourierModeIdentifier:
    """Mode orders of a Fourier-harmonic model of order n (geometry.model = 'fourier'): n is the model's; the
    dominant component is the largest amplitude of (U_r, U_theta, U_z) at the identification circle's (r, z);
    m = 1 + the sign changes of U_r along the generatrix (as ModeIdentifier). Each mode of order n >= 1 stands
    for a pair of the body (cos and sin n theta), exactly degenerate: no partner, split 0."""

    def __init__(self, mesh, cfg, order: int):
        self.cfg, self.n = cfg, order
        self.point = PointSet(mesh, np.array([[cfg.circle_radius_m, cfg.circle_height_m]]))
        if not self.point.found.all():
            raise ValueError("circle")
        self.line = None
        if cfg.line_radius_m is not None:
            z = np.linspace(cfg.line_z_start_m, cfg.line_z_stop_m, cfg.n_line_points)
            self.line = PointSet(mesh, np.column_stack([np.full(z.size, cfg.line_radius_m), z]))
            if not self.line.found.all():
                raise ValueError("line")

    def order(self, u) -> ModeOrder:
        amplitude = np.abs(self.point(u)[0])
        component = ("r", "theta", "z")[int(np.argmax(amplitude))]
        m = None
        if self.line is not None and component != "theta":
            u_r = self.line(u)[:, 0]
            k = int(np.argmax(np.abs(u_r)))
            m = 1
            if abs(u_r[k]) > 0:
                kept = u_r[np.abs(u_r) > SKIP_FRACTION * abs(u_r[k])]
                m = 1 + int(np.count_nonzero(np.diff(np.sign(kept)) != 0))
        return ModeOrder(self.n, m, component, 1.0, None, 0.0 if self.n else None)


def pair_partners(frequencies_Hz: list[float], orders: list[ModeOrder]) -> None:
    """Set each mode's partner (same m, n and dominant component, n > 0, nearest in frequency)."""
    for i, a in enumerate(orders):
        if a.n == 0:
            continue
        best = None
        for j, b in enumerate(orders):
            if j != i and (b.n, b.m, b.component) == (a.n, a.m, a.component):
                if best is None or abs(frequencies_Hz[j] - frequencies_Hz[i]) < abs(
                        frequencies_Hz[best] - frequencies_Hz[i]):
                    best = j
        if best is not None:
            a.partner = best
            a.split_Hz = frequencies_Hz[best] - frequencies_Hz[i]


def normal_component(u_cyl_phasor: np.ndarray, normal_rz: tuple[float, float]) -> np.ndarray:
    """w = u_r n_r + u_z n_z along the unit outward normal (n_r, n_z) of the surface in the (r, z) plane."""
    nr, nz = normal_rz
    return (u_cyl_phasor[:, 0] * nr + u_cyl_phasor[:, 2] * nz) / math.hypot(nr, nz)


def travelling_parts(w: np.ndarray, n: int) -> tuple[complex, complex]:
    """(towards +theta, towards -theta) complex amplitudes of order n of phasors w round the circle:
    Re(c exp(i(omega t - n theta))) travels towards +theta, i.e. the coefficient of exp(-i n theta)."""
    c = harmonics(w)
    return complex(c[-n % len(w)]), complex(c[n % len(w)])


def order_spectrum(w: np.ndarray, n_max: int) -> dict:
    """Amplitudes [m] of orders n = 0..n_max of w, split into the parts travelling towards +theta and
    -theta (n = 0, the breathing part, is reported as towards +theta with -theta zero). A pure
    travelling wave of order n has one non-zero entry; a standing one two equal entries."""
    n_max = min(n_max, len(w) // 2 - 1)
    parts = [travelling_parts(w, n) for n in range(n_max + 1)]
    return {"n": list(range(n_max + 1)),
            "towards_plus_theta_m": [abs(p) for p, _ in parts],
            "towards_minus_theta_m": [0.0] + [abs(m) for _, m in parts[1:]]}


def balance_factor(w_fixed: np.ndarray, w_trimmed: np.ndarray, n: int) -> complex:
    """Factor s on the trimmed phase's drive such that w_fixed + s w_trimmed has no order-n part
    travelling against the wave of the nominal drive w_fixed + w_trimmed (a driver's amplitude and
    phase balance of a two-phase motor). Raises ValueError when the trimmed phase has no such part."""
    plus, minus = travelling_parts(w_fixed + w_trimmed, n)
    against = 1 if abs(plus) >= abs(minus) else 0  # index of the unwanted part in travelling_parts
    fixed, trimmed = travelling_parts(w_fixed, n)[against], travelling_parts(w_trimmed, n)[against]
    if trimmed == 0:
        raise ValueError("the trimmed phase does not excite the unwanted part")
    return -fixed / trimmed


def travelling_wave(u_cyl_phasor: np.ndarray, theta: np.ndarray, normal_rz: tuple[float, float], n: int,
                    frequency_Hz: float, radius_m: float) -> dict:
    """Measures of a steady wave from complex displacement phasors (n_points, 3) round a circle.

    Normal displacement w = u_r n_r + u_z n_z (outward normal of the surface in the (r, z) plane);
    tangential = u_theta. A component c_{-n} exp(-i n theta) of w travels towards +theta."""
    w = normal_component(u_cyl_phasor, normal_rz)
    t = u_cyl_phasor[:, 1]
    amp_w, amp_t = np.abs(w), np.abs(t)
    forward, backward = (abs(p) for p in travelling_parts(w, n))
    omega = 2 * math.pi * frequency_Hz
    ratio = float(amp_w.min() / amp_w.max()) if amp_w.max() > 0 else 0.0
    phase = np.angle(t * np.conj(w))  # tangential relative to normal, per point
    return {
        "frequency_Hz": frequency_Hz,
        "circumferential_order": n,
        "normal_amplitude_min_m": float(amp_w.min()),
        "normal_amplitude_max_m": float(amp_w.max()),
        "travelling_wave_ratio": ratio,
        "direction": "+theta" if forward >= backward else "-theta",
        "forward_fraction": float(forward / (forward + backward)) if forward + backward > 0 else 0.0,
        "wave_speed_m_per_s": omega * radius_m / n if n else None,
        "wave_angular_speed_rad_per_s": omega / n if n else None,
        "ellipse_normal_amplitude_m": float(amp_w.mean()),
        "ellipse_tangential_amplitude_m": float(amp_t.mean()),
        "ellipse_phase_deg": float(math.degrees(np.angle(np.exp(1j * phase).mean()))),
        "orders": order_spectrum(w, SPECTRUM_ORDERS),
    }
