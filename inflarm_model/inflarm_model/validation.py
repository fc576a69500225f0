"""Argument checks the inflarm cores share: coerce, check shape and range, name the argument.

Each check coerces its argument (``float`` or ``np.asarray(x, dtype=float)``), checks the shape
and that every value is finite (and, for `check_positive`, > 0), and returns the coerced value
or raises a ValueError naming the argument, the expected shape or range with its unit, and what
it got::

    expected q of shape (7,), got (6,)
    expected start to be finite [m], got non-finite start[0] = nan
    expected max_speed to be a positive finite speed [m/s] (max_speed > 0), got -1.0

A single point is a batch of one: `check_batch` takes shape (n,) as well as (..., n).
"""

import math

import numpy as np
import numpy.typing as npt

__all__ = ['all_finite', 'check_batch', 'check_positive', 'check_rows', 'check_vector']

_isfinite = math.isfinite
_hypot = math.hypot


def all_finite(v: npt.NDArray[np.float64]) -> bool:
    """Whether every entry of a small float vector ``v`` (shape (n,)) is finite.

    hypot of the entries is finite iff every entry is, unless finite entries overflow it (then
    the entry-wise test decides): one C call on the list of entries.
    """
    return _isfinite(_hypot(*v.tolist())) or bool(np.isfinite(v).all())


def check_positive(name: str, value: float, unit: str = '', quantity: str = 'number') -> float:
    """Return ``value`` as a float, finite and > 0, or raise a ValueError naming ``name``.

    Parameters
    ----------
    name : str
        The argument's name, as the caller knows it.
    value : float
        The value to check; anything ``float()`` accepts.
    unit : str, optional
        Its unit, written in brackets after the expected range (``'m'``); none by default.
    quantity : str, optional
        What it is, for the message (``'length'``); ``'number'`` by default.

    Returns
    -------
    float
    """
    unit = _bracket(unit)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} to be a number{unit}, got {value!r}') from None
    if not (_isfinite(x) and x > 0.0):
        raise ValueError(f'expected {name} to be a positive finite {quantity}{unit} '
                         f'({name} > 0), got {value!r}')
    return x


def check_vector(name: str, x: npt.ArrayLike, n: int, unit: str = '') -> npt.NDArray[np.float64]:
    """Return ``x`` as a finite float array of shape (n,) or raise a ValueError naming ``name``.

    Parameters
    ----------
    name : str
        The argument's name.
    x : array-like, shape (n,)
        The vector to check.
    n : int
        Its length.
    unit : str, optional
        Its unit, for the message (``'rad'``); none by default.

    Returns
    -------
    ndarray, shape (n,)
    """
    expected = f'({n},)'
    v = _as_floats(name, x, expected, unit)
    if v.shape != (n,):
        raise _shape_error(name, expected, unit, v.shape)
    if not all_finite(v):
        raise _finite_error(name, v, unit)
    return v


def check_rows(name: str, X: npt.ArrayLike, n: int, unit: str = '') -> npt.NDArray[np.float64]:
    """Return ``X`` as a finite float array of shape (N, n) or raise a ValueError naming ``name``.

    Parameters
    ----------
    name : str
        The argument's name.
    X : array-like, shape (N, n)
        N rows of n values to check; N may be 0.
    n : int
        The length of a row.
    unit : str, optional
        Its unit, for the message; none by default.

    Returns
    -------
    ndarray, shape (N, n)
    """
    expected = f'(N, {n})'
    V = _as_floats(name, X, expected, unit)
    if V.ndim != 2 or V.shape[1] != n:
        raise _shape_error(name, expected, unit, V.shape)
    if not np.isfinite(V).all():
        raise _finite_error(name, V, unit)
    return V


def check_batch(name: str, x: npt.ArrayLike, n: int, unit: str = '', *,
                single: bool = False) -> npt.NDArray[np.float64]:
    """Return ``x`` as a finite float array of shape (..., n) or raise a ValueError naming it.

    Parameters
    ----------
    name : str
        The argument's name.
    x : array-like, shape (n,) or (..., n)
        One vector or a batch of them (any leading dimensions).
    n : int
        The length of the last axis.
    unit : str, optional
        Its unit, for the message (``'m'``); none by default.
    single : bool, optional
        Whether the caller documents one vector (n,) as a form of its own: the message then
        names both, ``(n,) or (..., n)``.

    Returns
    -------
    ndarray, shape of ``x``
    """
    expected = f'({n},) or (..., {n})' if single else f'(..., {n})'
    v = _as_floats(name, x, expected, unit)
    if v.ndim == 0 or v.shape[-1] != n:
        raise _shape_error(name, expected, unit, v.shape)
    if not np.isfinite(v).all():
        raise _finite_error(name, v, unit)
    return v


def _bracket(unit: str) -> str:
    return f' [{unit}]' if unit else ''


def _as_floats(name: str, x: npt.ArrayLike, expected: str, unit: str) -> npt.NDArray[np.float64]:
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'expected {name} of shape {expected}{_bracket(unit)}, '
                         f'got {x!r}') from None


def _shape_error(name: str, expected: str, unit: str, shape: tuple[int, ...]) -> ValueError:
    return ValueError(f'expected {name} of shape {expected}{_bracket(unit)}, got {shape}')


def _finite_error(name: str, v: npt.NDArray[np.float64], unit: str) -> ValueError:
    index = tuple(int(i) for i in np.argwhere(~np.isfinite(v))[0])
    where = ', '.join(str(i) for i in index)
    return ValueError(f'expected {name} to be finite{_bracket(unit)}, got non-finite '
                      f'{name}[{where}] = {float(v[index])!r}')
