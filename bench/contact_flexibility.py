"""The stator's static flexibility at a ring contact, from reduced models: what the contact forces see.

For each reduced model (a case with ``--set`` overrides, built or taken from the cache; or cache files with
``--files``), with the electrodes grounded (short circuit, as the driven transient sees them) and the rotor
absent, K_r^-1 on the interface and modal coordinates gives:

- node flexibility: the 3 x 3 blocks of K_r^-1 on each interface node (default interface, ``"nodes"``), their
  eigenvalues averaged over the nodes, and the coupling to the next node; a point load on a 3D continuum has an
  unbounded displacement, so these grow like 1/h when the mesh is refined (docs/reduced.md, "The band
  interface");
- site flexibility along the contact normal (the 15 deg cone face's, pointing at the axis and up): a site's own,
  a crest patch's (1 N spread over the sites where cos 4 theta > 0.9) and the whole ring's (1 N spread evenly).

    # the motor case on three meshes, either interface
    .venv/bin/python bench/contact_flexibility.py --case cases/wwusm-motor.toml --refinements 0.6 0.8 1.0 \\
        --set 'reduction.interface="band"' output.fields=false
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def flexibility(model, half_angle_deg: float = 15.0) -> dict:
    n, ni, n_inputs = model.size, model.n_interface, len(model.inputs)
    keep = np.r_[0:ni, ni + n_inputs:n]
    inverse = np.linalg.inv(model.K[np.ix_(keep, keep)])
    out = {"fe_dofs": model.fe_dofs, "interface": ni, "coordinates": n}
    blocks = inverse[:ni, :ni]
    nodes = ni // 3
    eig = np.array([np.linalg.eigvalsh(blocks[3 * k:3 * k + 3, 3 * k:3 * k + 3]) for k in range(nodes)])
    out["node_eigen_nm_per_N"] = (eig.mean(axis=0) * 1e9).tolist()
    out["next_node_xx_nm_per_N"] = float(np.mean([blocks[3 * k, 3 * ((k + 1) % nodes)] for k in range(nodes)]) * 1e9)
    points = model.site_points
    sites = points.shape[0]
    theta = np.arctan2(points[:, 1], points[:, 0])
    half = math.radians(half_angle_deg)
    normal = np.stack([-np.cos(theta) * math.cos(half), -np.sin(theta) * math.cos(half),
                       np.full(sites, math.sin(half))], axis=1)
    rows = np.einsum("sk,skj->sj", normal, model.site_rows[:, keep].reshape(sites, 3, -1))
    F = rows @ inverse @ rows.T
    patch = (np.cos(4 * theta) > 0.9).astype(float)
    patch /= patch.sum()
    ring = np.full(sites, 1.0 / sites)
    out["site_self_nm_per_N"] = float(np.diag(F).mean() * 1e9)
    out["crest_patch_nm_per_N"] = float(patch @ F @ patch * 1e9)
    out["ring_nm_per_N"] = float(ring @ F @ ring * 1e9)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=ROOT / "cases" / "wwusm-motor.toml")
    parser.add_argument("--refinements", type=float, nargs="*", default=[])
    parser.add_argument("--set", nargs="*", default=[])
    parser.add_argument("--files", type=Path, nargs="*", default=[], help="reduced-model cache files instead")
    args = parser.parse_args()
    from app.reduced.model import ReducedModel

    models = [ReducedModel.load(path) for path in args.files]
    if not args.files:
        from mpi4py import MPI

        from app.case.schema import load_case
        from app.reduced.model import load_or_build

        for refinement in args.refinements or [None]:
            extra = [] if refinement is None else [f"geometry.parameters.mesh_refinement={refinement}"]
            case = load_case(args.case, args.set + extra)
            models.append(load_or_build(case, MPI.COMM_WORLD, lambda *a: None)[0])
    print("| FE DOFs | interface | node flexibility, eigenvalues [nm/N] | next node [nm/N] | site, own [nm/N] | "
          "crest patch [nm/N] | ring [nm/N] |")
    print("|---|---|---|---|---|---|---|")
    for model in models:
        f = flexibility(model)
        print(f"| {f['fe_dofs']} | {f['interface']} | {', '.join(f'{v:.2f}' for v in f['node_eigen_nm_per_N'])} | "
              f"{f['next_node_xx_nm_per_N']:.2f} | {f['site_self_nm_per_N']:.2f} | {f['crest_patch_nm_per_N']:.3f} | "
              f"{f['ring_nm_per_N']:.3f} |")


if __name__ == "__main__":
    main()
