"""Experiential knowledge database for the iterative learning controller (section 3.2 of 001_...).

The positive-pressure workspace of the arm (paper section 2.2: x, y in -202..202 mm, z in
574..990 mm) is meshed with 1 cm "knowledge points". For every point the database keeps the
control information of the last of 30 learning trials that drove the arm from the home point to
that point: the ILC memory ``PidIlcController.finish_trial`` returns, i.e. chamber pressures for
the first 10 s at the 5 Hz control rate, 50 steps x 5 chambers, one uint16 each. A new task seeds
its first trial with the memory of the nearest knowledge point (`seed_memory`), so the iterative
learning controller starts "experienced" (eqs. (1), (4) of 001_...).

`build_knowledge_database` runs those trials on a plant it is given (the simulated arm,
``inflarm_hw.sra_plant``, in ``inflarm-build-knowledge``), thousands of points at once;
`KnowledgeDatabase` stores them in memory-mapped .npy arrays; `nearest_knowledge_point` snaps a
target to the grid without any file.

Frame and units: everything here is in the mount frame ``sra_mount`` in metres (origin at the
mount, z along PEA1 pointing away from the mount) and pascals. Convert the paper's millimetres
at the edges.

Default grid (67,200 points, the paper's 40 x 40 x 42)::

    x, y in {-0.19, -0.18, ..., 0.20} m   (40 values each)
    z    in { 0.58,  0.59, ..., 0.99} m   (42 values)

Whole-centimetre values reproduce the paper's example: target (111, 98, 733) mm -> knowledge
point (110, 100, 730) mm. A point belongs to the grid when it lies in the cell of a grid point,
i.e. within half a spacing of the outermost grid values: x, y in [-0.195, 0.205) m and z in
[0.575, 0.995) m; anything else is rejected with a ValueError naming the bound. (The 40 values
per horizontal axis cannot be symmetric about 0 on a whole-centimetre grid, so the workspace
strip x or y in [-0.202, -0.195) m is not covered.)

Storage (format 2): a directory of standard numpy files, memory-mapped, that numpy alone reads
(``np.load(path / 'codes.npy', mmap_mode='r')``)::

    knowledge.json   the metadata: format version (2), grid origin [m], spacing [m] and shape
                     (nx, ny, nz), steps per point (50), chambers (``CHAMBERS`` order), control
                     rate [Hz] (5.0), pressure scale [Pa per LSB]
    codes.npy        uint16 little-endian, shape (points, steps, chambers): the pressure codes
    filled.npy       bool, shape (points,): which points hold a memory

Points are numbered in C order over (ix, iy, iz): ``index = (ix * ny + iy) * nz + iz``. The codes
of the full grid are 67,200 x 50 x 5 x 2 = 33,600,000 B (the paper's 32.04 MiB); the mask adds
67,200 B. Pressures are stored as ``code = round(p / scale)`` clamped to
[0, 65535], decoded as ``p = code * scale``. The default 15 Pa/LSB gives a full scale of
983.025 kPa, above the 0-900 kPa range of the ITV2050 valves (and the controller's 100 kPa output
limit), with a round-trip error of at most 7.5 Pa.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
import functools
import hashlib
import importlib.metadata
import importlib.util
import itertools
import json
import math
import os
from pathlib import Path
import shutil
import socket
import sys

import numpy as np
import numpy.typing as npt

from inflarm_control.pid_ilc import PidIlcController, PidIlcParams, run_trials
from inflarm_model.soft_arm import CHAMBERS
from inflarm_model.validation import check_vector

__all__ = [
    'DEFAULT_GRID',
    'DEFAULT_SCALE_PA_PER_LSB',
    'HOME_POINT',
    'N_CHAMBERS',
    'ClusterError',
    'KnowledgeDatabase',
    'KnowledgeGrid',
    'build_knowledge_database',
    'code_fingerprint',
    'decode_pressure',
    'encode_pressure',
    'nearest_knowledge_point',
    'seed_memory',
]

#: Chambers per knowledge point, in ``CHAMBERS`` order (PEA, B1, B2, B3, B4).
N_CHAMBERS = len(CHAMBERS)
#: Pressure resolution of the stored codes [Pa per LSB]: 983.025 kPa full scale, above the
#: 900 kPa range of the ITV2050 valves, so no valve output can clamp; the +-7.5 Pa rounding
#: moves the simulated end point by less than 0.1 mm.
DEFAULT_SCALE_PA_PER_LSB = 15.0
#: Start point of every learning trial, the paper's (0, 0, 604) mm [m, sra_mount].
HOME_POINT = (0.0, 0.0, 0.604)

_FORMAT = 2
_METADATA, _CODES, _FILLED = 'knowledge.json', 'codes.npy', 'filled.npy'
_CODE_MAX = 65535
_AXES = ('x', 'y', 'z')
# Rounding offset in cells: 0.5 plus a hair, so the inclusive lower bound survives float error
# ((-0.195 + 0.19) / 0.01 is -0.4999999...).
_HALF = 0.5 + 1e-9


@dataclass(frozen=True)
class KnowledgeGrid:
    """
    A regular grid of knowledge points in the mount frame.

    Parameters
    ----------
    origin : tuple of 3 float
        Grid point with index (0, 0, 0) [m, sra_mount].
    spacing : float
        Distance between neighbouring grid points along every axis [m].
    shape : tuple of 3 int
        Number of grid values along x, y and z.
    """

    origin: tuple[float, float, float] = (-0.19, -0.19, 0.58)
    spacing: float = 0.01
    shape: tuple[int, int, int] = (40, 40, 42)

    def __post_init__(self) -> None:
        origin = np.asarray(self.origin, dtype=float)
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise ValueError(f'expected origin of 3 finite floats [m], got {self.origin!r}')
        spacing = float(self.spacing)
        if not (math.isfinite(spacing) and spacing > 0.0):
            raise ValueError(f'expected spacing > 0 [m], got {self.spacing!r}')
        shape = tuple(self.shape)
        if len(shape) != 3 or not all(
            isinstance(n, int | np.integer) and 1 <= n < 2**32 for n in shape
        ):
            raise ValueError(f'expected shape of 3 positive ints, got {self.shape!r}')
        object.__setattr__(self, 'origin', tuple(float(v) for v in origin))
        object.__setattr__(self, 'spacing', spacing)
        object.__setattr__(self, 'shape', tuple(int(n) for n in shape))

    @property
    def size(self) -> int:
        """Number of knowledge points."""
        nx, ny, nz = self.shape
        return nx * ny * nz

    @property
    def lower(self) -> tuple[float, float, float]:
        """Inclusive lower corner of the covered box, half a spacing below the grid [m]."""
        return tuple(o - 0.5 * self.spacing for o in self.origin)

    @property
    def upper(self) -> tuple[float, float, float]:
        """Exclusive upper corner of the covered box, half a spacing above the grid [m]."""
        return tuple(
            o + (n - 0.5) * self.spacing for o, n in zip(self.origin, self.shape, strict=True)
        )

    def index_of(self, point: npt.ArrayLike) -> int | npt.NDArray[np.int64]:
        """
        Flat index of the knowledge point nearest to each point.

        Parameters
        ----------
        point : array-like, shape (3,) or (N, 3)
            Positions [m, sra_mount], inside the covered box (``lower`` <= p < ``upper``).

        Returns
        -------
        int or ndarray of int64, shape (N,)
            ``(ix * ny + iy) * nz + iz``; ties halfway between grid values go up.

        Raises
        ------
        ValueError
            If the shape is wrong, a value is not finite or a point is outside the grid.
        """
        points = _coerce_points(point, 'point')
        ijk = self._ijk_of(points.reshape(-1, 3))
        index = np.ravel_multi_index(tuple(ijk.T), self.shape).astype(np.int64)
        return int(index[0]) if points.ndim == 1 else index

    def point_of(self, index: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """
        Position of knowledge points given their flat indices.

        Parameters
        ----------
        index : int or array-like of int, shape (N,)
            Flat indices in ``[0, size)``.

        Returns
        -------
        ndarray, shape (3,) or (N, 3)
            Grid positions [m, sra_mount], rounded to 1 nm so that 1 cm grids print exactly.
        """
        idx = _coerce_indices(index, self.size)
        ijk = np.stack(np.unravel_index(idx, self.shape), axis=-1)
        points = np.round(np.asarray(self.origin) + ijk * self.spacing, 9)
        return points[0] if np.ndim(index) == 0 else points

    def points(self) -> npt.NDArray[np.float64]:
        """All knowledge points in flat-index order, shape (size, 3) [m, sra_mount]."""
        return self.point_of(np.arange(self.size))

    def nearest(self, point: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """
        Knowledge point nearest to each point.

        Parameters
        ----------
        point : array-like, shape (3,) or (N, 3)
            Positions [m, sra_mount] inside the covered box.

        Returns
        -------
        ndarray, shape (3,) or (N, 3)
            Grid positions [m, sra_mount].
        """
        return self.point_of(self.index_of(point))

    def _ijk_of(self, points: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
        ijk = np.floor((points - np.asarray(self.origin)) / self.spacing + _HALF).astype(np.int64)
        if np.any((ijk < 0) | (ijk >= np.asarray(self.shape))):
            self._raise_outside(points)
        return ijk

    def _raise_outside(self, points: npt.NDArray[np.float64]) -> None:
        ijk = np.floor((points - np.asarray(self.origin)) / self.spacing + _HALF)
        bad = (ijk < 0) | (ijk >= np.asarray(self.shape))
        row, axis = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f'expected point {_AXES[axis]} in [{self.lower[axis]:.4f}, {self.upper[axis]:.4f})'
            f' m (knowledge grid, sra_mount frame), got {float(points[row, axis])!r}'
            + (f' at row {row}' if len(points) > 1 else '')
        )


#: The paper's 40 x 40 x 42 grid with 1 cm spacing (67,200 points).
DEFAULT_GRID = KnowledgeGrid()


def nearest_knowledge_point(
    point: npt.ArrayLike, grid: KnowledgeGrid = DEFAULT_GRID
) -> npt.NDArray[np.float64]:
    """
    Knowledge point nearest to a target (section 3.2 of 001_...).

    Parameters
    ----------
    point : array-like, shape (3,) or (N, 3)
        Target positions [m, sra_mount].
    grid : KnowledgeGrid, optional
        Grid to snap to; the paper's 1 cm, 40 x 40 x 42 grid by default.

    Returns
    -------
    ndarray, shape (3,) or (N, 3)
        Nearest grid positions [m, sra_mount], e.g. (0.111, 0.098, 0.733) -> (0.11, 0.10, 0.73).

    Raises
    ------
    ValueError
        If a point is outside the grid (the message names the violated bound) or malformed.
    """
    if not isinstance(grid, KnowledgeGrid):
        raise ValueError(f'expected grid to be a KnowledgeGrid, got {type(grid).__name__}')
    return grid.nearest(point)


class KnowledgeDatabase:
    """
    Memory-mapped store of the learned chamber pressures of every knowledge point.

    Build one with :meth:`create` (or :func:`build_knowledge_database`) and reopen it with
    :meth:`open`. Nothing is read eagerly: opening maps the arrays and checks the metadata.

    Attributes
    ----------
    path : pathlib.Path
        The database directory (module docstring: storage).
    grid : KnowledgeGrid
        The knowledge points.
    steps : int
        Control steps per point (50 for 10 s at 5 Hz).
    rate_hz : float
        Control rate the steps were recorded at [Hz].
    scale : float
        Pressure resolution of the stored codes [Pa per LSB].
    mode : str
        ``'r'`` (read only) or ``'r+'`` (read and write).
    """

    def __init__(self, path: Path, grid: KnowledgeGrid, steps: int, rate_hz: float,
                 scale: float, mode: str, codes: np.memmap, filled: np.memmap) -> None:
        # Private: use create() or open(), which validate the files first.
        self.path = path
        self.grid = grid
        self.steps = steps
        self.rate_hz = rate_hz
        self.scale = scale
        self.mode = mode
        self._maps = (codes, filled)
        # Plain ndarray views: indexing a memmap subclass costs a few us per call.
        self._data = codes.view(np.ndarray)
        self._mask = filled.view(np.ndarray).view(np.uint8)

    @classmethod
    def create(
        cls,
        path: str | os.PathLike,
        grid: KnowledgeGrid = DEFAULT_GRID,
        steps: int = 50,
        rate_hz: float = 5.0,
        scale: float = DEFAULT_SCALE_PA_PER_LSB,
        overwrite: bool = False,
    ) -> KnowledgeDatabase:
        """
        Create an empty database directory (nothing filled) and open it for writing.

        Parameters
        ----------
        path : str or os.PathLike
            Directory to create. The codes alone are ``grid.size * steps * 5 * 2`` bytes
            (sparse until written where supported).
        grid : KnowledgeGrid, optional
            Knowledge points; the paper's 67,200-point grid by default.
        steps : int, optional
            Control steps stored per point (50 = the first 10 s at 5 Hz).
        rate_hz : float, optional
            Control rate of the steps [Hz].
        scale : float, optional
            Pressure per stored LSB [Pa]; full scale is ``65535 * scale``.
        overwrite : bool, optional
            Replace an existing database instead of raising.

        Returns
        -------
        KnowledgeDatabase
            Opened in mode ``'r+'``.
        """
        if not isinstance(grid, KnowledgeGrid):
            raise ValueError(f'expected grid to be a KnowledgeGrid, got {type(grid).__name__}')
        if not (isinstance(steps, int | np.integer) and 1 <= steps < 2**32):
            raise ValueError(f'expected steps to be a positive int, got {steps!r}')
        rate_hz, scale = float(rate_hz), float(scale)
        if not (math.isfinite(rate_hz) and rate_hz > 0.0):
            raise ValueError(f'expected rate_hz > 0 [Hz], got {rate_hz!r}')
        if not (math.isfinite(scale) and scale > 0.0):
            raise ValueError(f'expected scale > 0 [Pa per LSB], got {scale!r}')
        path = Path(path)
        if path.exists() and not overwrite:
            raise ValueError(f'expected path to not exist (or overwrite=True), got {str(path)!r}')
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
        # Built beside ``path`` and renamed into place: a reader never maps half a database.
        staging = path.with_name(f'.{path.name}.creating-{os.getpid()}')
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir()
        metadata = {'format': _FORMAT, 'grid': {'origin': list(grid.origin),
                                                'spacing': grid.spacing,
                                                'shape': list(grid.shape)},
                    'steps': int(steps), 'chambers': list(CHAMBERS), 'rate_hz': rate_hz,
                    'scale_pa_per_lsb': scale}
        try:
            (staging / _METADATA).write_text(json.dumps(metadata, indent=2) + '\n')
            # open_memmap extends the files without writing them: no 32 MB write.
            codes = np.lib.format.open_memmap(staging / _CODES, 'w+', '<u2',
                                              (grid.size, int(steps), N_CHAMBERS))
            filled = np.lib.format.open_memmap(staging / _FILLED, 'w+', np.bool_, (grid.size,))
            staging.rename(path)  # the maps stay valid: they hold the files, not their names
        except OSError as err:
            shutil.rmtree(staging, ignore_errors=True)
            raise OSError(err.errno, f'cannot create the knowledge database {str(path)!r}: '
                          f'{err.strerror}') from err
        return cls(path, grid, int(steps), rate_hz, scale, 'r+', codes, filled)

    @classmethod
    def open(cls, path: str | os.PathLike, mode: str = 'r') -> KnowledgeDatabase:
        """
        Map an existing database, checking its metadata but reading no pressures.

        Parameters
        ----------
        path : str or os.PathLike
            A directory written by :meth:`create`.
        mode : {'r', 'r+'}, optional
            Read only, or read and write.

        Returns
        -------
        KnowledgeDatabase

        Raises
        ------
        ValueError
            If the mode is unknown, or ``path`` is not a format-2 knowledge database, its
            metadata is inconsistent with its arrays, or an array is truncated or garbled.
        """
        if mode not in ('r', 'r+'):
            raise ValueError(f"expected mode 'r' or 'r+', got {mode!r}")
        path = Path(path)
        name = str(path)
        if path.is_file() and _starts_with(path, b'INFLKDB\x00'):
            raise ValueError(f'{name!r} is a knowledge database of format 1 (one file), before '
                             f'format {_FORMAT} (a directory of .npy files): rebuild it with '
                             'inflarm-build-knowledge')
        try:
            metadata = json.loads((path / _METADATA).read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise ValueError(f'expected a knowledge database directory at {name!r} with '
                             f'{_METADATA}: {err}') from None
        if not isinstance(metadata, dict) or metadata.get('format') != _FORMAT:
            found = metadata.get('format') if isinstance(metadata, dict) else metadata
            raise ValueError(f'expected knowledge database format {_FORMAT} at {name!r}, got '
                             f'{found!r}')
        try:
            g = metadata['grid']
            grid = KnowledgeGrid(origin=tuple(g['origin']), spacing=g['spacing'],
                                 shape=tuple(g['shape']))
            steps, rate_hz = metadata['steps'], float(metadata['rate_hz'])
            scale, chambers = float(metadata['scale_pa_per_lsb']), metadata['chambers']
        except (KeyError, TypeError, ValueError) as err:
            raise ValueError(f'knowledge database at {name!r} has invalid metadata: '
                             f'{err!r}') from None
        if (chambers != list(CHAMBERS) or not isinstance(steps, int) or steps < 1
                or not (rate_hz > 0.0 and scale > 0.0)):
            raise ValueError(f'knowledge database at {name!r} has inconsistent metadata')
        codes = _load_array(path / _CODES, mode, np.dtype('<u2'),
                            (grid.size, steps, N_CHAMBERS))
        filled = _load_array(path / _FILLED, mode, np.dtype(np.bool_), (grid.size,))
        db = cls(path, grid, steps, rate_hz, scale, mode, codes, filled)
        if np.any(db._mask > 1):  # 67 kB: cheap, and catches a garbled mask
            raise ValueError(f'knowledge database at {name!r} has a corrupt filled mask')
        return db

    def __enter__(self) -> KnowledgeDatabase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f'KnowledgeDatabase({str(self.path)!r}, mode={self.mode!r}, grid={self.grid},'
            f' steps={self.steps}, filled={self.n_filled}/{self.grid.size})'
        )

    @property
    def filled(self) -> npt.NDArray[np.bool_]:
        """Read-only mask of the points holding a memory, shape (size,) in flat-index order."""
        mask = self._mask.view(np.bool_)
        mask.flags.writeable = False
        return mask

    @property
    def n_filled(self) -> int:
        """Number of points holding a memory."""
        return int(np.count_nonzero(self._mask))

    def has(self, index: int) -> bool:
        """Whether the knowledge point with this flat index holds a memory."""
        self._check_open()
        (idx,) = _coerce_indices(index, self.grid.size)
        return bool(self._mask[idx])

    def lookup(
        self, point: npt.ArrayLike
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """
        Memory of the knowledge point nearest to a target.

        Parameters
        ----------
        point : array-like, shape (3,)
            Target position [m, sra_mount], inside the grid.

        Returns
        -------
        grid_point : ndarray, shape (3,)
            The nearest knowledge point [m, sra_mount].
        memory : ndarray, shape (steps, 5)
            Its chamber output pressures per control step [Pa], chambers in ``CHAMBERS`` order.

        Raises
        ------
        ValueError
            If the point is malformed or outside the grid.
        KeyError
            If the nearest knowledge point holds no memory yet.
        """
        self._check_open()
        if np.ndim(point) != 1:
            raise ValueError(f'expected point of shape (3,) [m], got shape {np.shape(point)}')
        idx = self.grid.index_of(point)
        grid_point = self.grid.point_of(idx)
        if not self._mask[idx]:
            raise KeyError(f'knowledge point {tuple(grid_point.tolist())} (index {idx}) holds '
                           'no memory')
        return grid_point, decode_pressure(self._data[idx], self.scale)

    def read(self, index: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """
        Memories of knowledge points given their flat indices.

        Parameters
        ----------
        index : int or array-like of int, shape (N,)
            Flat indices of filled points.

        Returns
        -------
        ndarray, shape (steps, 5) or (N, steps, 5)
            Chamber output pressures [Pa].

        Raises
        ------
        KeyError
            If a point holds no memory.
        """
        self._check_open()
        idx = _coerce_indices(index, self.grid.size)
        empty = idx[self._mask[idx] == 0]
        if empty.size:
            raise KeyError(f'knowledge point index {int(empty[0])} holds no memory')
        memory = decode_pressure(self._data[idx], self.scale)
        return memory[0] if np.ndim(index) == 0 else memory

    def write(self, index: npt.ArrayLike, memory: npt.ArrayLike) -> None:
        """
        Store memories of knowledge points and mark them filled.

        Parameters
        ----------
        index : int or array-like of int, shape (N,)
            Flat indices.
        memory : array-like, shape (steps, 5) or (N, steps, 5)
            Chamber output pressures [Pa]; rounded to the nearest LSB and clamped to
            ``[0, 65535 * scale]``.

        Raises
        ------
        ValueError
            If the database is read only, or an index or the memory is malformed.
        """
        self._check_open()
        if self.mode != 'r+':
            raise ValueError(f"expected a database opened with mode 'r+', got mode {self.mode!r}")
        idx = _coerce_indices(index, self.grid.size)
        memory = np.asarray(memory, dtype=float)
        expected = (len(idx), self.steps, N_CHAMBERS)
        if memory.shape != expected and not (
            np.ndim(index) == 0 and memory.shape == expected[1:]
        ):
            raise ValueError(f'expected memory of shape {expected} [Pa], got {memory.shape}')
        if not np.all(np.isfinite(memory)):
            raise ValueError('expected finite memory [Pa], got NaN or inf')
        self._data[idx] = encode_pressure(memory, self.scale).reshape(expected)
        self._mask[idx] = 1

    def flush(self) -> None:
        """Write pending changes to disk: the codes before the marks, so that an interrupted
        build never marks a point whose codes are not on disk."""
        if self.mode == 'r+' and self._maps is not None:
            for array in self._maps:
                array.flush()

    def _check_open(self) -> None:
        if self._maps is None:
            raise ValueError(f'expected an open database, {str(self.path)!r} is closed')

    def close(self) -> None:
        """Flush and release the mappings (the views die with them)."""
        self.flush()
        self._maps = self._mask = self._data = None


def seed_memory(db: KnowledgeDatabase, target: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    ILC memory for the first trial of a new task: that of the nearest knowledge point.

    Pass the result as ``memory`` to ``PidIlcController.start_trial`` (or ``run_trials``); the
    tasks must start from the point the database was built from (``HOME_POINT`` by default).

    Parameters
    ----------
    db : KnowledgeDatabase
        A (partly) built database.
    target : array-like, shape (3,) or (N, 3)
        Task targets [m, sra_mount], inside ``db.grid``.

    Returns
    -------
    ndarray, shape (steps, 5) or (N, steps, 5)
        Chamber output pressures per control step [Pa], in ``CHAMBERS`` order.

    Raises
    ------
    ValueError
        If a target is malformed or outside the grid.
    KeyError
        If a nearest knowledge point holds no memory (start with ``memory=None``, PID alone).
    """
    if not isinstance(db, KnowledgeDatabase):
        raise ValueError(f'expected db to be a KnowledgeDatabase, got {type(db).__name__}')
    if np.ndim(target) == 1:
        return db.lookup(target)[1]
    return db.read(db.grid.index_of(target))


def holding_pressure(db: KnowledgeDatabase, point: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """
    Chamber pressures that hold the end at ``point``, interpolated from the knowledge points.

    The last step of a knowledge point's memory is the output its learned trial settled on:
    the pressures that hold the end there. Between points they are interpolated trilinearly
    over the 8 surrounding knowledge points (clamped to the grid at its faces), a feedforward
    for a target that moves (a planned path, section 4.2).

    Parameters
    ----------
    db : KnowledgeDatabase
        A database whose points around ``point`` are all filled.
    point : array-like, shape (3,)
        [m, sra_mount], inside ``db.grid``.

    Returns
    -------
    ndarray, shape (5,)
        [Pa], in ``CHAMBERS`` order.

    Raises
    ------
    ValueError
        If the point is malformed or outside the grid.
    KeyError
        If a surrounding knowledge point holds no memory.
    """
    if not isinstance(db, KnowledgeDatabase):
        raise ValueError(f'expected db to be a KnowledgeDatabase, got {type(db).__name__}')
    grid = db.grid
    grid.index_of(point)  # checks the point: finite, inside the covered box
    cells = (np.asarray(point, dtype=float) - grid.origin) / grid.spacing
    low = np.clip(np.floor(cells).astype(int), 0, np.asarray(grid.shape) - 2)
    fraction = np.clip(cells - low, 0.0, 1.0)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    index = np.ravel_multi_index(tuple((low + corners).T), grid.shape)
    weights = np.prod(np.where(corners, fraction, 1.0 - fraction), axis=1)
    return weights @ db.read(index)[:, -1, :]  # KeyError where one holds no memory


class ClusterError(RuntimeError):
    """The Dask cluster cannot run a knowledge build: its scheduler is unreachable or has no
    worker, a worker runs other code than the client, or a block was lost with every worker
    that tried it. The database keeps every block written so far: fix the cause and resume."""


@dataclass(frozen=True)
class _BuildJob:
    # Everything a worker (forked, or a Dask worker on another machine) needs to learn a block.
    grid: KnowledgeGrid
    start: tuple[float, float, float]
    n_trials: int
    plant_factory: Callable[[int], object]
    controller_params: PidIlcParams
    packages: tuple[str, ...]  # whose sources `code_fingerprint` hashes


@dataclass(frozen=True)
class _LearnedBlock:
    index: npt.NDArray[np.int64]
    memory: npt.NDArray[np.float64]  # (len(index), steps, 5) [Pa]
    fingerprint: str  # `code_fingerprint` of the process that learned it
    host: str


def _learn_block(job: _BuildJob, index: npt.NDArray[np.int64]) -> _LearnedBlock:
    # The one block computation, for this process, the local pool and Dask workers alike: its
    # result depends on the job and the block's points only.
    plant = job.plant_factory(len(index))
    controller = PidIlcController(len(index), job.controller_params)
    rate_hz = job.controller_params.rate_hz
    result = run_trials(
        plant,
        controller,
        job.start,
        job.grid.point_of(index),
        job.n_trials,
        # twice the memory (20 s by default, the Fig 7 task's trials): what the PID adds while
        # the memory's last entry is held is what teaches the hold (pid_ilc, gamma)
        duration_s=2 * job.controller_params.memory_steps / rate_hz,
        dt=1.0 / rate_hz,
        keep_trajectories=False,
    )
    fingerprint = code_fingerprint(job.packages)
    return _LearnedBlock(index, result.memory, fingerprint, socket.gethostname())


@functools.cache
def code_fingerprint(packages: tuple[str, ...]) -> str:
    """
    Hash of the code a knowledge build runs, to refuse workers of another version.

    Parameters
    ----------
    packages : tuple of str
        Top-level packages (``('inflarm_control', 'inflarm_hw', ...)``); the sources (``*.py``)
        of each, its distribution version, and the versions of Python and numpy are hashed.

    Returns
    -------
    str
        SHA-256 hex digest; a package that cannot be found here hashes as missing.
    """
    digest = hashlib.sha256(f'{sys.version_info[:2]} numpy {np.__version__}'.encode())
    for name in sorted(packages):
        spec = importlib.util.find_spec(name)
        try:
            version = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            version = 'unknown'
        digest.update(f'\0{name} {version}'.encode())
        if spec is None or not spec.submodule_search_locations:
            digest.update(b' missing')
            continue
        for location in spec.submodule_search_locations:
            for source in sorted(Path(location).rglob('*.py')):
                digest.update(f'\0{source.relative_to(location)}\0'.encode())
                digest.update(source.read_bytes())
    return digest.hexdigest()


def _blocks_here(job: _BuildJob, blocks: list) -> Iterator[_LearnedBlock]:
    for index in blocks:
        yield _learn_block(job, index)


_POOL_JOB: dict[str, _BuildJob] = {}


def _set_pool_job(job: _BuildJob) -> None:
    _POOL_JOB['job'] = job


def _learn_pool_block(index: npt.NDArray[np.int64]) -> _LearnedBlock:
    return _learn_block(_POOL_JOB['job'], index)


def _blocks_on_pool(job: _BuildJob, blocks: list, workers: int) -> Iterator[_LearnedBlock]:
    from concurrent.futures import ProcessPoolExecutor, as_completed
    import multiprocessing

    # Forked: the job (plant factory included) needs no pickling; workers start at the first
    # submit, before the caller's progress bar starts its monitor thread.
    pool = ProcessPoolExecutor(min(workers, len(blocks)), multiprocessing.get_context('fork'),
                               _set_pool_job, (job,))
    try:
        futures = [pool.submit(_learn_pool_block, index) for index in blocks]
        for future in as_completed(futures):
            yield future.result()
    finally:
        pool.shutdown(cancel_futures=True)


def _blocks_on_dask(job: _BuildJob, blocks: list, scheduler: str,
                    fingerprint: str) -> Iterator[_LearnedBlock]:
    import dask
    from distributed import Client, KilledWorker, as_completed

    timeout = dask.config.get('distributed.comm.timeouts.connect')
    try:
        client = Client(scheduler, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as err:
        raise ClusterError(
            f'cannot reach the Dask scheduler at {scheduler!r} (connect timeout {timeout}): {err}'
        ) from err
    try:
        try:
            client.wait_for_workers(1, timeout=timeout)
        except TimeoutError as err:
            raise ClusterError(
                f'no Dask worker joined the scheduler at {scheduler!r} within {timeout}'
            ) from err
        try:
            found = client.run(code_fingerprint, job.packages)
        except Exception as err:  # noqa: BLE001 - an older worker may not have the function
            raise ClusterError(
                f'the Dask workers of {scheduler!r} cannot run the version check of this'
                f' inflarm_control, a worker of another version? ({type(err).__name__}: {err})'
            ) from err
        other = sorted(address for address, value in found.items() if value != fingerprint)
        if other:
            raise ClusterError(
                f'Dask workers {other} of {scheduler!r} run another version of'
                f' {", ".join(job.packages)} than this process (code fingerprint'
                f' {found[other[0]][:12]} != {fingerprint[:12]}): update them and resume'
            )
        # pure=False: random keys, so two builds on one cluster never share a result.
        futures = {client.submit(_learn_block, job, index, pure=False): index for index in blocks}
        for future in as_completed(futures, loop=client.loop):
            try:
                block = future.result()
            except KilledWorker as err:
                index = futures[future]
                raise ClusterError(
                    f'the block of {len(index)} points from index {int(index[0])} was lost with'
                    f' every Dask worker that ran it: {err}'
                ) from err
            future.release()
            yield block
    finally:
        client.close()


def build_knowledge_database(
    path: str | os.PathLike,
    grid: KnowledgeGrid = DEFAULT_GRID,
    *,
    plant_factory: Callable[[int], object],
    n_trials: int = 30,
    batch_size: int = 4096,
    start: npt.ArrayLike = HOME_POINT,
    controller_params: PidIlcParams | None = None,
    scale: float = DEFAULT_SCALE_PA_PER_LSB,
    workers: int | None = None,
    scheduler: str | None = None,
    overwrite: bool = False,
    progress: bool = True,
) -> KnowledgeDatabase:
    """
    Learn every knowledge point on a plant and store it (section 3.2 of 001_...).

    For each point the task ``start -> point`` is repeated ``n_trials`` times with the PID +
    iterative learning controller (each trial feeding the next, eqs. (1), (3), (4)), each trial
    twice the memory long (20 s by default), and the chamber outputs of the first ``memory_steps``
    steps of the last trial are stored. Points are learned in blocks of ``batch_size`` consecutive
    flat indices (the plant is vectorized over the arms of a block), in this process, in a local
    pool of processes, or on a Dask cluster; the executor of the blocks is the only difference.
    This process alone writes the database, a block at a time (its memories, then its filled
    marks). An existing one is resumed: only points not yet filled are learned, so an interrupted
    build can be restarted.

    The blocks are fixed by the grid (block ``k`` holds indices ``k * batch_size`` to
    ``(k + 1) * batch_size - 1``, less those already filled), and a block's memories depend
    only on the job and its points, not on where or when it ran: a build, resumed or not, local
    or distributed, writes the same bytes as any other with the same arguments (for a plant
    factory that is itself deterministic, such as ``inflarm-build-knowledge``'s noise-free one).

    Parameters
    ----------
    path : str or os.PathLike
        Database directory; created if missing, resumed if present (unless ``overwrite``). Its full
        size is reserved before anything is learned.
    grid : KnowledgeGrid, optional
        Knowledge points; the paper's 67,200 by default.
    n_trials : int, optional
        Learning trials per point (30 in the paper).
    batch_size : int, optional
        Points per block; a few thousand keeps the arrays in cache, fewer spread a small grid
        over more workers.
    start : array-like, shape (3,), optional
        Start point of every trial [m, sra_mount]; the paper's (0, 0, 0.604) m.
    plant_factory : callable
        ``plant_factory(n)`` makes a plant of ``n`` arms with ``reset()``, ``step(command,
        dt)`` and ``measure()`` (see ``inflarm_control.pid_ilc.run_trials``), e.g. the simulated
        ``inflarm_hw.sra_plant.SoftArmPlant``. The plant comes from outside: this package does
        not depend on any hardware or simulator. With a ``scheduler`` it is pickled to the
        workers (by reference when importable there, as ``inflarm-build-knowledge``'s is).
    controller_params : PidIlcParams, optional
        Controller gains; its defaults if None. Its ``memory_steps`` and ``rate_hz`` become the
        database's ``steps`` and ``rate_hz`` (10 s at 5 Hz by default).
    scale : float, optional
        Pressure per stored LSB [Pa]; must cover the controller's ``p_max``.
    workers : int, optional
        Without a ``scheduler``: processes learning blocks in parallel, forked (POSIX only);
        one per CPU by default, 1 learns in this process. Must be None with a ``scheduler``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``'tcp://HOST:8786'``) whose workers learn the
        blocks; None for the local pool. The connection times out after Dask's
        ``distributed.comm.timeouts.connect`` (30 s unless configured). Workers must run the
        same code as this process (`code_fingerprint` of every loaded ``inflarm*`` package);
        a worker that dies loses only the block it was learning, which Dask reruns elsewhere.
    overwrite : bool, optional
        Start from an empty database even if ``path`` exists.
    progress : bool, optional
        Show a tqdm progress bar over points.

    Returns
    -------
    KnowledgeDatabase
        The database, opened in mode ``'r+'``, every point filled.

    Raises
    ------
    ValueError
        On bad arguments, a scale too coarse for the controller's ``p_max``, or an existing
        database whose grid, steps, rate or scale differ from the requested ones.
    OSError
        If the database cannot be created, or its size reserved (``ENOSPC``: the disk is full).
    ClusterError
        If the scheduler cannot be reached or has no worker, a worker runs another version, or
        a block was lost with every worker that tried it.
    """
    if scheduler is not None:
        if not isinstance(scheduler, str) or not scheduler:
            raise ValueError(f"expected scheduler an address like 'tcp://HOST:8786', got"
                             f' {scheduler!r}')
        if workers is not None:
            raise ValueError(f"expected workers=None with a scheduler (the cluster's workers"
                             f' learn the blocks), got workers={workers!r}')
    workers = (os.cpu_count() or 1) if workers is None else workers
    for name, value in (('n_trials', n_trials), ('batch_size', batch_size), ('workers', workers)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f'expected {name} to be an int >= 1, got {value!r}')
    start = tuple(check_vector('start', start, 3, 'm').tolist())
    params = PidIlcParams() if controller_params is None else controller_params
    if not isinstance(params, PidIlcParams):
        raise ValueError(
            f'expected controller_params to be a PidIlcParams, got {type(params).__name__}'
        )
    steps, rate_hz = int(params.memory_steps), float(params.rate_hz)
    if max(params.p_max) > _CODE_MAX * float(scale):
        raise ValueError(
            f'expected scale >= {max(params.p_max) / _CODE_MAX:.3f} Pa per LSB to store the'
            f' controller p_max of {max(params.p_max):.0f} Pa, got {scale!r}'
        )
    if not callable(plant_factory):
        raise ValueError(f'expected plant_factory to be callable, got {plant_factory!r}')
    path = Path(path)
    if path.exists() and not overwrite:
        db = KnowledgeDatabase.open(path, mode='r+')
        found = (db.grid, db.steps, db.rate_hz, db.scale)
        if found != (grid, steps, rate_hz, float(scale)):
            db.close()
            raise ValueError(
                f'expected existing {str(path)!r} to hold (grid, steps, rate_hz, scale) ='
                f' {(grid, steps, rate_hz, float(scale))} to resume, got {found}'
                ' (pass overwrite=True to rebuild)'
            )
    else:
        db = KnowledgeDatabase.create(path, grid, steps, rate_hz, scale, overwrite=True)
    try:
        _reserve(path)
    except OSError:
        db.close()
        raise
    todo = np.flatnonzero(db._mask == 0)
    # Blocks fixed by the grid, so a resumed build learns the same blocks as an uninterrupted one.
    blocks = [b for b in np.split(todo, np.flatnonzero(np.diff(todo // batch_size)) + 1) if b.size]
    packages = tuple(sorted({name.partition('.')[0] for name in sys.modules
                             if name.startswith('inflarm')}))
    job = _BuildJob(grid, start, int(n_trials), plant_factory, params, packages)
    fingerprint = code_fingerprint(packages)
    if scheduler is not None:
        learned = _blocks_on_dask(job, blocks, scheduler, fingerprint)
    elif workers == 1 or len(blocks) < 2:
        learned = _blocks_here(job, blocks)
    else:
        learned = _blocks_on_pool(job, blocks, workers)

    from tqdm import tqdm

    try:
        # The first block is asked for before tqdm starts its monitor thread (the pool forks).
        first = next(learned, None)
        with tqdm(total=len(todo), unit='pt', desc='knowledge points',
                  disable=not progress) as shown:
            for block in itertools.chain([] if first is None else [first], learned):
                if block.fingerprint != fingerprint:
                    raise ClusterError(
                        f'a block was learned on {block.host} by another version of'
                        f' {", ".join(packages)} (code fingerprint {block.fingerprint[:12]} !='
                        f' {fingerprint[:12]}): update that worker and resume'
                    )
                db.write(block.index, block.memory)
                db.flush()
                shown.update(len(block.index))
    except BaseException:
        learned.close()  # stops the pool or the cluster's futures first
        db.close()  # every block written so far stays: the database resumes
        raise
    db.flush()
    return db


def _reserve(path: Path) -> None:
    # Allocate the whole arrays now: a full disk then stops the build here with ENOSPC, not
    # later with a SIGBUS in the writer on a page of a sparse file. Allocating keeps the bytes.
    for name in (_CODES, _FILLED):
        size = (path / name).stat().st_size
        with open(path / name, 'r+b') as f:
            try:
                os.posix_fallocate(f.fileno(), 0, size)
            except OSError as err:
                raise OSError(err.errno, f'cannot reserve the {size} B of the knowledge '
                              f'database {str(path / name)!r}: {err.strerror}') from err


def encode_pressure(pressure: npt.ArrayLike, scale: float) -> npt.NDArray[np.uint16]:
    """
    Pressures to uint16 codes: ``clip(round(p / scale), 0, 65535)``.

    Parameters
    ----------
    pressure : array-like, any shape
        Pressures [Pa], finite.
    scale : float
        Pa per LSB, > 0.

    Returns
    -------
    ndarray of uint16, same shape
    """
    codes = np.rint(np.asarray(pressure, dtype=float) / scale)
    return np.clip(codes, 0, _CODE_MAX).astype(np.uint16)


def decode_pressure(code: npt.ArrayLike, scale: float) -> npt.NDArray[np.float64]:
    """
    Codes to pressures: ``code * scale`` [Pa].

    Parameters
    ----------
    code : array-like of int, any shape
        Stored codes.
    scale : float
        Pa per LSB, > 0.

    Returns
    -------
    ndarray of float64, same shape
    """
    return np.asarray(code, dtype=np.uint16) * float(scale)


def _starts_with(path: Path, prefix: bytes) -> bool:
    with open(path, 'rb') as f:
        return f.read(len(prefix)) == prefix


def _load_array(path: Path, mode: str, dtype: np.dtype, shape: tuple[int, ...]) -> np.memmap:
    """Map the .npy file at ``path``, or raise ValueError unless it holds ``dtype``, ``shape``."""
    try:
        array = np.load(path, mmap_mode=mode)
    except (OSError, ValueError, EOFError) as err:  # missing, not .npy, empty or truncated
        raise ValueError(f'knowledge database array {str(path)!r} cannot be mapped: '
                         f'{err}') from None
    if not isinstance(array, np.memmap) or array.dtype != dtype or array.shape != shape:
        raise ValueError(f'expected knowledge database array {str(path)!r} of {dtype} '
                         f'{shape}, got {array.dtype} {array.shape}')
    return array


def _coerce_points(points: npt.ArrayLike, name: str) -> npt.NDArray[np.float64]:
    # One point, shape (3,), or N of them, shape (N, 3).
    arr = np.asarray(points, dtype=float)
    if arr.shape != (3,) and (arr.ndim != 2 or arr.shape[1] != 3):
        raise ValueError(f'expected {name} of shape (3,) or (N, 3) [m], got shape {arr.shape}')
    if not np.all(np.isfinite(arr)):
        raise ValueError(f'expected finite {name} [m], got NaN or inf')
    return arr


def _coerce_indices(index: npt.ArrayLike, size: int) -> npt.NDArray[np.int64]:
    idx = np.asarray(index)
    if idx.ndim > 1 or not (idx.dtype.kind in 'iu' or (idx.size == 0 and idx.ndim == 1)):
        raise ValueError(f'expected index as int or 1-D ints, got {index!r}')
    idx = np.atleast_1d(idx).astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= size):
        bad = int(idx[(idx < 0) | (idx >= size)][0])
        raise ValueError(f'expected index in [0, {size}), got {bad}')
    return idx
