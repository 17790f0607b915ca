"""The output convention of every tier (``lumped``, ``fe``, ``modal``): one time-series file name, one
name per quantity, one ``units`` attribute, and the one HDF5 writer that applies them.

A quantity has the same dataset name, shape convention and unit in every tier, so a reader (the
plots, the statistics, ``bench/bench_tiers.py``, ``piezodyn plot DIR``) never maps names:

===================================  =======  ==========================================================
dataset                              unit     meaning (one row per accepted step or output sample)
===================================  =======  ==========================================================
``time_s``                           s        time of the row
``dt_s``                             s        time since the previous row (0 on a first row at t = 0)
``drive_voltage_V``                  V        drive U(t) of the first driven electrode
``<electrode>_voltage_V``            V        each electrode of a multi-phase drive
``<point>_displacement_m``           m        named point's displacement component (``tip``: the tip)
``<body>_position_m``                m        rigid body's coordinates (n_rows x axes); a reference
                                              point of the body, so read it relative to its start
``<body>_velocity_m_per_s``          m/s      rigid body's velocity (n_rows x axes)
``<body>_angle_rad``                 rad      rotations of a rigid body about its named axes
``<body>_angular_velocity_rad_per_s`` rad/s   their rates
``<contact>_force_N``                N        force of the contact on its rigid body (node and surface
                                              contacts) or on its upper body (rigid-rigid links),
                                              n_rows x axes, upward positive
``<contact>_closed``                 1        1 while the contact is closed
``<contact>_torque_N_m``             N m      torque of a contact on a rotating body
``<contact>_dissipated_J``           J        energy the contact's damping and friction have dissipated
                                              since t = 0 (FE tier)
``<contact>_normal_force_N``         N        a surface contact on a rotating body: total normal force,
                                              the integral of the contact pressure (motor: N)
``<contact>_area_in_contact_m2``     m^2      a surface contact on a rotating body (FE tier): area of its
                                              quadrature points in contact
===================================  =======  ==========================================================

Every dataset carries the attribute :data:`UNITS`. The summary's statistics use the same names in
every tier (``app/transient/impacts.py`` for the generic ones, the scene report of
``app/scenes/`` for those of one scene).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.errors import CaseError

TIME_SERIES_FILE = "transient.h5"
UNITS = "units"
TABLE = "table"           # attribute of a dataset whose rows are not the time rows
DESCRIPTION = "description"
TIME = "time_s"
STEP = "dt_s"
DRIVE = "drive_voltage_V"
MOTION_PLOT = "transient_motion.png"
FORCE_PLOT = "transient_force.png"


def point_displacement(point: str) -> str:
    return f"{point}_displacement_m"


def electrode_voltage(electrode: str) -> str:
    return f"{electrode}_voltage_V"


def body_position(body: str) -> str:
    return f"{body}_position_m"


def body_velocity(body: str) -> str:
    return f"{body}_velocity_m_per_s"


def body_angle(body: str) -> str:
    return f"{body}_angle_rad"


def body_angular_velocity(body: str) -> str:
    return f"{body}_angular_velocity_rad_per_s"


def contact_force(contact: str) -> str:
    return f"{contact}_force_N"


def contact_closed(contact: str) -> str:
    return f"{contact}_closed"


def contact_torque(contact: str) -> str:
    return f"{contact}_torque_N_m"


def contact_normal_force(contact: str) -> str:
    return f"{contact}_normal_force_N"


def contact_area(contact: str) -> str:
    return f"{contact}_area_in_contact_m2"


def contact_peak_pressure(contact: str) -> str:
    return f"{contact}_peak_pressure_Pa"


def contact_dissipated(contact: str) -> str:
    return f"{contact}_dissipated_J"


def electrode_charge(electrode: str) -> str:
    return f"{electrode}_charge_C"


def contact_probe(contact: str) -> str:
    return f"{contact}_probe_displacement_m"


def sites_table(contact: str, quantity: str) -> str:
    """A per-site diagnostics table of a sampled contact: ``time`` (interval start, end [s]), ``geometry``
    (x, y, z [m], area [m^2] per site, written once), ``pressure`` [Pa] and the fractions ``closed``,
    ``stick``, ``slip_positive``, ``slip_negative``; ``slip_speed_e1``, ``slip_speed_e2``, ``slip_speed`` [m/s],
    ``friction_power_e1``, ``friction_power_e2`` [W/m^2]; the first harmonics ``pressure_cos``, ``pressure_sin``
    [Pa], ``normal_displacement_cos``, ``normal_displacement_sin`` [m] (rows: output intervals; columns: sites);
    ``wave_frame`` (rows x groups x wave-phase bins x 8: app/contact/tables.py)."""
    return f"{contact}_sites_{quantity}"


#: energy columns of a run with ``output.energies`` (every tier): structure kinetic and strain energy, rigid
#: bodies' kinetic energy, the contacts' penalty energy, the structure's damping loss since t = 0
ENERGY_COLUMNS = {"kinetic_energy_J": "J", "strain_energy_J": "J", "rigid_kinetic_energy_J": "J",
                  "contact_energy_J": "J", "damping_dissipated_J": "J (since t = 0)"}


def contact_columns(contact: str) -> dict[str, str]:
    """Units of the columns every contact writes (what they mean: the table above)."""
    return {contact_force(contact): "N", contact_closed(contact): "1"}


def body_columns(body: str) -> dict[str, str]:
    return {body_position(body): "m", body_velocity(body): "m/s"}


class TimeSeriesWriter:
    """The one HDF5 time-series writer (h5py, rank 0 only; the rows are replicated on every rank).

    ``write(row)`` buffers one row (a dict name -> scalar or 1-D array) and appends blocks of
    ``block_rows`` rows; ``write_block(columns)`` appends many rows at once (n_rows x ...). The
    datasets are resizable and chunked and the file is flushed after every block, so a run that is
    killed leaves a readable file up to the last flush. ``units`` (and optionally ``descriptions``)
    map each name to its unit; ``attrs`` are file attributes; ``resume_rows`` continues an existing
    file after its first rows (a resumed run: rows written after the checkpoint are dropped). Collective
    with ``comm``: a file that cannot continue (missing, shorter than the checkpoint, unreadable) is a
    one-line CaseError on every rank."""

    def __init__(self, path: Path, units: dict[str, str], comm=None, block_rows: int = 2000,
                 resume_rows: int | None = None, descriptions: dict[str, str] | None = None,
                 attrs: dict[str, str] | None = None, resume_tables: dict[str, int] | None = None):
        self.path = Path(path)
        self.units = dict(units)
        self.descriptions = dict(descriptions or {})
        self.attrs = dict(attrs or {})
        self.block_rows = block_rows
        self.active = comm is None or comm.rank == 0
        self._rows: list[dict] = []
        self._file = None
        self.rows_written = 0
        #: rows of each table: a dataset with rows of its own (an event table, per-interval diagnostics)
        self.table_rows: dict[str, int] = dict(resume_tables or {})
        if resume_rows is not None:
            why = self._reopen(resume_rows) if self.active else None
            if comm is not None:
                why = comm.bcast(why, root=0)
            if why:
                self.close()
                raise CaseError(str(self.path), None, why)

    def _reopen(self, rows: int) -> str | None:
        """Keep the file's first ``rows`` rows; the reason it cannot, or None."""
        if not self.path.exists():
            return f"is missing: the checkpoint continues its first {rows} rows" if rows else None
        import h5py

        try:
            self._file = h5py.File(self.path, "a")
            for name in self._file:
                ds = self._file[name]
                keep = self.table_rows.get(name, rows)
                if name not in self.table_rows and ds.attrs.get(TABLE):
                    keep = 0                          # a table the checkpoint does not know: after it
                if ds.shape[0] < keep:
                    return f"{name} has {ds.shape[0]} rows, the checkpoint needs {keep}"
                if ds.maxshape[0] is None:
                    ds.resize(keep, axis=0)
        except (OSError, ValueError) as exc:
            return f"cannot be continued ({exc})"
        self.rows_written = rows
        self._file.flush()
        return None

    def _create(self, shapes: dict[str, tuple]) -> None:
        import h5py

        if self._file is None:
            self._file = h5py.File(self.path, "w")
            for key, value in self.attrs.items():
                self._file.attrs[key] = value
        for name, shape in shapes.items():
            ds = self._file.create_dataset(name, shape=(0, *shape), maxshape=(None, *shape), dtype="f8",
                                           chunks=(min(self.block_rows, 4096), *shape))
            ds.attrs[UNITS] = self.units.get(name, "")
            if name in self.descriptions:
                ds.attrs[DESCRIPTION] = self.descriptions[name]

    def write(self, row: dict) -> None:
        if not self.active:
            return
        self._rows.append(row)
        if len(self._rows) >= self.block_rows:
            self.flush()

    def flush(self) -> None:
        if not self.active or not self._rows:
            return
        rows, self._rows = self._rows, []
        self.write_block({name: np.array([r[name] for r in rows], dtype=float) for name in rows[0]})

    def write_block(self, columns: dict[str, np.ndarray]) -> None:
        if not self.active:
            return
        if self._file is None or not any(name in self._file for name in columns):
            self._create({name: np.shape(values)[1:] for name, values in columns.items()})
        n = len(next(iter(columns.values())))
        for name, values in columns.items():
            ds = self._file[name]
            ds.resize(self.rows_written + n, axis=0)
            ds[self.rows_written:] = values
        self.rows_written += n
        self._file.flush()

    def append_table(self, name: str, block: np.ndarray, units: str, **attrs: str) -> None:
        """Append rows to table ``name`` (a dataset whose rows are not the time rows; created on first use)."""
        if not self.active:
            return
        block = np.asarray(block, dtype=float)
        if self._file is None:
            import h5py

            self._file = h5py.File(self.path, "w")
            for key, value in self.attrs.items():
                self._file.attrs[key] = value
        if name not in self._file:
            ds = self._file.create_dataset(name, shape=(0, *block.shape[1:]), maxshape=(None, *block.shape[1:]),
                                           dtype="f8", chunks=(64, *block.shape[1:]))
            ds.attrs[UNITS] = units
            ds.attrs[TABLE] = 1
            for key, value in attrs.items():
                ds.attrs[key] = value
        ds = self._file[name]
        start = self.table_rows.get(name, 0)
        ds.resize(start + block.shape[0], axis=0)
        ds[start:] = block
        self.table_rows[name] = start + block.shape[0]
        self._file.flush()

    def add_table(self, name: str, data: np.ndarray, units: str, **attrs: str) -> None:
        """A dataset that is not a time column (e.g. the lumped tier's event table), written once."""
        if not self.active:
            return
        ds = self._file.create_dataset(name, data=data)
        ds.attrs[UNITS] = units
        for key, value in attrs.items():
            ds.attrs[key] = value

    def close(self) -> None:
        self.flush()
        if self._file is not None:
            self._file.close()
            self._file = None


def check_time_series(path: Path) -> None:
    """A time-series file that can be read: present, an HDF5 file, every dataset readable; else one CaseError
    naming the file (``piezodyn plot`` on a damaged directory)."""
    import h5py

    if not path.is_file():
        raise CaseError(str(path), None, "is missing (the summary names it)")
    try:
        with h5py.File(path, "r") as f:
            for name in f:
                f[name][...]
    except (OSError, ValueError, KeyError, RuntimeError) as exc:
        raise CaseError(str(path), None, f"cannot be read (truncated or damaged: {str(exc).splitlines()[0]})") from None


def read_time_series(path: Path) -> dict[str, np.ndarray]:
    """Every dataset of a time-series file, by name."""
    import h5py

    with h5py.File(path, "r") as f:
        return {name: f[name][:] for name in f}


SERIES_CSV = "transient.csv"


def write_series_csv(h5_path: Path, csv_path: Path, block_rows: int = 20000) -> None:
    """The time rows of a time-series file as CSV (``output.series_csv``): one header line naming each column
    with its unit, ``<dataset> [<units>]`` or ``<dataset>[<k>] [<units>]`` for component k of a vector (time_s and
    dt_s first, then the datasets by name), then one
    line per row with every value exact (17 significant digits). Tables (datasets marked :data:`TABLE`) stay
    in the HDF5 file. Written to a temporary name and renamed."""
    import io

    import h5py

    from app.files import atomic_write

    with h5py.File(h5_path, "r") as f:
        names = [name for name in f if TABLE not in f[name].attrs and f[name].ndim in (1, 2)]
        first = [name for name in (TIME, STEP) if name in names]        # then the others, by name
        names = first + [name for name in names if name not in first]
        rows = f[names[0]].shape[0] if names else 0
        header = []
        for name in names:
            units = f[name].attrs.get(UNITS, "")
            units = units.decode() if isinstance(units, bytes) else str(units)
            if f[name].ndim == 1:
                header.append(f"{name} [{units}]")
            else:
                header += [f"{name}[{k}] [{units}]" for k in range(f[name].shape[1])]

        def write(fh) -> None:
            out = io.TextIOWrapper(fh, encoding="utf-8", newline="\n")
            out.write(",".join(header) + "\n")
            for start in range(0, rows, block_rows):
                stop = min(start + block_rows, rows)
                block = np.column_stack([np.asarray(f[name][start:stop], dtype=float).reshape(stop - start, -1)
                                         for name in names])
                np.savetxt(out, block, fmt="%.17g", delimiter=",")
            out.flush()
            out.detach()

        atomic_write(csv_path, write)
