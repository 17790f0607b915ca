"""Outputs of a transient run: the HDF5 time series (h5py, rank 0) and the progress bar.

The time series holds one row per accepted step. Rows are buffered and appended to resizable,
chunked datasets, and the file is flushed after every block, so a run that is killed leaves a
readable file with everything up to the last flush. Units are attributes of every dataset.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.progress import SimulatedTimeProgress as Progress  # noqa: F401  (moved to app/progress.py)


class TimeSeriesExport:
    """``write(row)`` with ``row`` a dict name -> scalar or 1-D array; ``units`` maps each name to
    its unit. Only rank 0 opens the file (the rows are replicated on every rank)."""

    def __init__(self, path: Path, units: dict[str, str], comm, block_rows: int = 2000,
                 resume_rows: int | None = None):
        self.path = Path(path)
        self.units = dict(units)
        self.block_rows = block_rows
        self.active = comm.rank == 0
        self._rows: list[dict] = []
        self._file = None
        self.rows_written = 0
        if resume_rows is not None and self.active:
            self._reopen(resume_rows)

    def _reopen(self, rows: int) -> None:
        """Continue an existing series after its first ``rows`` rows (a resumed run): rows written
        after the checkpoint by the killed run are dropped."""
        if rows == 0 and not self.path.exists():
            return
        import h5py

        self._file = h5py.File(self.path, "a")
        for name in self._file:
            ds = self._file[name]
            if ds.shape[0] < rows:
                raise ValueError(f"{self.path}: {name} has {ds.shape[0]} rows, the checkpoint needs {rows}")
            ds.resize(rows, axis=0)
        self.rows_written = rows
        self._file.flush()

    def _open(self, row: dict) -> None:
        import h5py

        if self._file is None:
            self._file = h5py.File(self.path, "w")
        for name, value in row.items():
            shape = np.shape(value)
            ds = self._file.create_dataset(name, shape=(0, *shape), maxshape=(None, *shape), dtype="f8",
                                           chunks=(min(self.block_rows, 4096), *shape))
            ds.attrs["unit"] = self.units.get(name, "")

    def write(self, row: dict) -> None:
        if not self.active:
            return
        self._rows.append(row)
        if len(self._rows) >= self.block_rows:
            self.flush()

    def flush(self) -> None:
        if not self.active or not self._rows:
            return
        if self._file is None or not len(self._file):
            self._open(self._rows[0])
        n = len(self._rows)
        for name in self._rows[0]:
            ds = self._file[name]
            ds.resize(self.rows_written + n, axis=0)
            ds[self.rows_written:] = np.array([r[name] for r in self._rows], dtype=float)
        self.rows_written += n
        self._rows.clear()
        self._file.flush()

    def close(self) -> None:
        self.flush()
        if self._file is not None:
            self._file.close()
            self._file = None


def plot_time_series(h5_path: Path, png_motion: Path, png_force: Path, point: str | None, bodies: list[str],
                     force_contacts: list[str], title: str = "") -> list[str]:
    """Fig. 7/9-like displacement plot (tip, bodies, vertical component) and Fig. 5-like force plot
    with one panel per contact (force magnitude on the rigid body), both titled ``title``."""
    import h5py
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    with h5py.File(h5_path, "r") as f:
        if "time_s" not in f:
            return written
        t_ms = f["time_s"][:] * 1e3
        fig, ax = plt.subplots(figsize=(8, 4))
        if point and f"{point}_displacement_m" in f:
            ax.plot(t_ms, f[f"{point}_displacement_m"][:] * 1e3, label=f"transducer {point}", lw=0.8)
        for body in bodies:
            key = f"{body}_position_m"
            if key in f:
                z = f[key][:, -1]
                ax.plot(t_ms, (z - z[0]) * 1e3, label=f"{body} (from its start)", lw=0.8)
        ax.set_xlabel("time [ms]")
        ax.set_ylabel("axial displacement [mm]")     # mm as the lumped tier's plots
        if title:
            ax.set_title(title)
        ax.legend()
        fig.tight_layout()
        fig.savefig(png_motion, dpi=120)
        plt.close(fig)
        written.append(png_motion.name)
        contacts = [c for c in force_contacts if f"{c}_force_N" in f]
        if contacts:
            fig, axes = plt.subplots(len(contacts), 1, figsize=(8, 1.2 + 1.8 * len(contacts)), sharex=True,
                                     squeeze=False)
            for ax, contact in zip(axes[:, 0], contacts):
                ax.plot(t_ms, np.linalg.norm(f[f"{contact}_force_N"][:], axis=1), lw=0.8)
                ax.set_ylabel(f"{contact} [N]")
            axes[-1, 0].set_xlabel("time [ms]")
            axes[0, 0].set_title(f"{title}: contact forces" if title else "contact forces")
            fig.tight_layout()
            fig.savefig(png_force, dpi=120)
            plt.close(fig)
            written.append(png_force.name)
    return written
