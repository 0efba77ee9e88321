"""The motion-primitive library file (docs/motion_library_format.md): write, read, validate.

frog_sim writes it (``frog-library generate``), frog_planner reads it; both through this one
schema. The reader rejects, with a message naming the problem, anything that is not a
complete format-1 library. Paper seed 000, "Data Collection Using the DER Simulation", eq. 14.
"""

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic_files import atomic_save_npz
from .primitives import PRIMITIVE_BITS, PRIMITIVE_NAMES

FORMAT_NAME = "frog-motion-library"
FORMAT_VERSION = 1
STATE_NAMES = ("forward_velocity", "lateral_velocity", "yaw_rate")
TRANSITION_NAMES = ("x", "y", "heading", "forward_velocity", "lateral_velocity", "yaw_rate")
REQUIRED_KEYS = ("format", "format_version", "primitive_names", "primitive_bits", "state_names",
                 "initial_states", "times", "transition_names", "transitions", "converged", "metadata")
_TIME_TOLERANCE_S = 1e-6


class LibraryFormatError(ValueError):
    """A library file is unreadable or does not follow docs/motion_library_format.md."""


@dataclass(frozen=True)
class MotionLibrary:
    """A validated motion-primitive library (all arrays as in the file, SI units).

    Attributes
    ----------
    primitive_names : numpy.ndarray, shape (P,), str
        ``A``..``I`` in id order.
    primitive_bits : numpy.ndarray, shape (P,), str
        Limb bits [FR, FL, BL, BR] of each primitive.
    initial_states : numpy.ndarray, shape (N, 3)
        Initial body velocities: forward m/s, lateral m/s, yaw rate rad/s.
    times : numpy.ndarray, shape (T,)
        Sample times in s, ``times[0] = 0``, uniform step.
    transitions : numpy.ndarray, shape (P, N, T, 6), float32
        x m, y m, heading rad (start body frame), forward m/s, lateral m/s, yaw rate rad/s
        (body frame at that time).
    converged : numpy.ndarray, shape (P, N), bool
        False where the simulation failed (row is NaN).
    metadata : dict
        Parsed metadata JSON.
    source : str
        Where it was read from.
    """

    primitive_names: np.ndarray
    primitive_bits: np.ndarray
    initial_states: np.ndarray
    times: np.ndarray
    transitions: np.ndarray
    converged: np.ndarray
    metadata: dict = field(default_factory=dict)
    source: str = ""

    @property
    def sample_interval(self):
        """Time between samples in s."""
        return float(self.times[1] - self.times[0])

    @property
    def horizon(self):
        """Last sample time in s."""
        return float(self.times[-1])

    def time_index(self, period):
        """Index into ``times`` of a planner period.

        Parameters
        ----------
        period : float
            Planner period T in s: a multiple of ``sample_interval`` in (0, horizon].

        Returns
        -------
        int

        Raises
        ------
        ValueError
            If the period is not positive, beyond the horizon, or not on the sample grid.
        """
        period = float(period)
        if not (period > 0.0 and np.isfinite(period)):
            raise ValueError(f"period {period} s must be a positive number of seconds")
        if period > self.horizon + _TIME_TOLERANCE_S:
            raise ValueError(f"period {period} s is beyond the library horizon {self.horizon} s")
        index = int(round(period / self.sample_interval))
        if abs(self.times[index] - period) > _TIME_TOLERANCE_S:
            raise ValueError(f"period {period} s is not a multiple of the library sample interval "
                             f"{self.sample_interval} s; nearest is {self.times[index]} s")
        return index

    def transitions_at(self, period):
        """Transitions after one period T (paper eq. 14 with t_f = T).

        On the sample grid the stored sample is returned; between two samples (e.g. the
        hardware's measured 1.43 s period on a 0.05 s grid) the two nearest samples are
        interpolated linearly. Between samples the body only coasts (a kick is over within
        0.2 s), so the error is second order in the interval (see the tests).

        Returns
        -------
        numpy.ndarray, shape (P, N, 6), float64
            Units as ``transitions``.
        """
        period = float(period)
        try:
            return np.asarray(self.transitions[:, :, self.time_index(period), :], dtype=float)
        except ValueError:
            if not (period > 0.0 and period <= self.horizon + _TIME_TOLERANCE_S):
                raise
        lo = int(np.searchsorted(self.times, period)) - 1
        w = (period - self.times[lo]) / (self.times[lo + 1] - self.times[lo])
        a = np.asarray(self.transitions[:, :, lo, :], dtype=float)
        b = np.asarray(self.transitions[:, :, lo + 1, :], dtype=float)
        return (1.0 - w) * a + w * b


def _text(value):
    return str(np.asarray(value)[()])


def load_motion_library(path):
    """Load and validate a motion-primitive library ``.npz`` (format version 1).

    Parameters
    ----------
    path : str or os.PathLike
        The library file.

    Returns
    -------
    MotionLibrary

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    LibraryFormatError
        If the file is not a zip/npz, is truncated, lacks a key, has a wrong format name or
        version, shapes that disagree, non-uniform or non-increasing times, non-finite
        values in converged rows, or unparseable metadata. The message names the problem.
    """
    src = str(path)
    try:
        with open(src, "rb"):
            pass
    except FileNotFoundError:
        raise FileNotFoundError(f"motion library {src} does not exist") from None
    try:
        npz = np.load(src, allow_pickle=False)
        if not isinstance(npz, np.lib.npyio.NpzFile):
            raise LibraryFormatError(f"{src} is a single .npy array, not a motion library .npz")
        with npz:
            missing = [k for k in REQUIRED_KEYS if k not in npz.files]
            if missing:
                raise LibraryFormatError(f"{src} lacks key(s) {missing}; expected all of {list(REQUIRED_KEYS)}")
            data = {k: npz[k] for k in REQUIRED_KEYS}
    except LibraryFormatError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError, zipfile.LargeZipFile) as exc:
        # numpy's wording for a file with no zip/npy header speaks of pickles: not the user's problem
        detail = "no .npz (zip) header" if "pickle" in str(exc) else f"{type(exc).__name__}: {exc}"
        raise LibraryFormatError(f"{src} is not a readable .npz (truncated, corrupt or not a zip): "
                                 f"{detail}") from None
    return _validate(data, src)


def _validate(data, src):
    def fail(msg):
        raise LibraryFormatError(f"{src}: {msg}")

    if _text(data["format"]) != FORMAT_NAME:
        fail(f"format is {_text(data['format'])!r}; expected {FORMAT_NAME!r}")
    try:
        version = int(np.asarray(data["format_version"])[()])
    except (TypeError, ValueError):
        fail(f"format_version is {data['format_version']!r}; expected the integer {FORMAT_VERSION}")
    if version != FORMAT_VERSION:
        fail(f"format_version is {version}; this reader understands {FORMAT_VERSION}")
    names = np.asarray(data["primitive_names"]).astype(str)
    bits = np.asarray(data["primitive_bits"]).astype(str)
    if names.ndim != 1 or names.size == 0:
        fail(f"primitive_names has shape {names.shape}; expected (P,) with P >= 1")
    n_prim = names.size
    if bits.shape != (n_prim,):
        fail(f"primitive_bits has shape {bits.shape}; expected ({n_prim},) like primitive_names")
    if tuple(np.asarray(data["state_names"]).astype(str)) != STATE_NAMES:
        fail(f"state_names is {list(np.asarray(data['state_names']).astype(str))}; expected {list(STATE_NAMES)}")
    if tuple(np.asarray(data["transition_names"]).astype(str)) != TRANSITION_NAMES:
        fail(f"transition_names is {list(np.asarray(data['transition_names']).astype(str))}; "
             f"expected {list(TRANSITION_NAMES)}")
    init = np.asarray(data["initial_states"])
    if init.ndim != 2 or init.shape[1] != 3 or init.shape[0] == 0:
        fail(f"initial_states has shape {init.shape}; expected (N, 3) with N >= 1")
    if not np.issubdtype(init.dtype, np.floating) or not np.all(np.isfinite(init)):
        fail("initial_states must be finite floats (m/s, m/s, rad/s)")
    n_states = init.shape[0]
    times = np.asarray(data["times"])
    if times.ndim != 1 or times.size < 2 or not np.issubdtype(times.dtype, np.floating):
        fail(f"times has shape {times.shape} and dtype {times.dtype}; expected (T,) floats with T >= 2")
    if not np.all(np.isfinite(times)) or times[0] != 0.0:
        fail(f"times starts at {times[0]} s; expected finite times starting at 0 s")
    step = np.diff(times)
    if np.any(step <= 0.0):
        bad = int(np.flatnonzero(step <= 0.0)[0])
        fail(f"times are not increasing at index {bad + 1} ({times[bad]} s then {times[bad + 1]} s)")
    if np.max(np.abs(step - step[0])) > max(_TIME_TOLERANCE_S, 1e-6 * step[0]):
        bad = int(np.argmax(np.abs(step - step[0])))
        fail(f"times are not uniform: step {step[bad]} s at index {bad + 1}; expected {step[0]} s")
    trans = np.asarray(data["transitions"])
    expected = (n_prim, n_states, times.size, 6)
    if trans.shape != expected:
        fail(f"transitions has shape {trans.shape}; expected {expected} (P, N, T, 6) from primitive_names, "
             "initial_states and times")
    if not np.issubdtype(trans.dtype, np.floating):
        fail(f"transitions has dtype {trans.dtype}; expected float32")
    conv = np.asarray(data["converged"])
    if conv.shape != (n_prim, n_states) or conv.dtype != bool:
        fail(f"converged has shape {conv.shape} and dtype {conv.dtype}; expected ({n_prim}, {n_states}) bool")
    finite_rows = np.all(np.isfinite(trans), axis=(2, 3))
    bad = conv & ~finite_rows
    if np.any(bad):
        p, n = (int(i) for i in np.argwhere(bad)[0])
        fail(f"transitions[{p}, {n}] (primitive {names[p]}, initial state {n}) is marked converged but holds "
             f"non-finite values ({int(bad.sum())} such row(s))")
    try:
        metadata = json.loads(_text(data["metadata"]))
    except json.JSONDecodeError as exc:
        fail(f"metadata is not valid JSON ({exc})")
    if not isinstance(metadata, dict):
        fail(f"metadata is a JSON {type(metadata).__name__}; expected an object")
    return MotionLibrary(primitive_names=names, primitive_bits=bits, initial_states=init.astype(float),
                         times=times.astype(float), transitions=trans, converged=conv,
                         metadata=metadata, source=src)


def write_motion_library(path, initial_states, times, transitions, converged, metadata: dict,
                         primitive_names=PRIMITIVE_NAMES) -> Path:
    """Write a format-1 library so that ``path`` is either absent or complete (atomic rename).

    The arrays are as :class:`MotionLibrary` holds them; the result is validated by reading it
    back, so a writer can never produce a file the planner refuses.
    """
    path = Path(path)
    arrays = {
        "format": np.array(FORMAT_NAME), "format_version": np.array(FORMAT_VERSION),
        "primitive_names": np.array(tuple(primitive_names)),
        "primitive_bits": np.array([PRIMITIVE_BITS[n] for n in primitive_names]),
        "state_names": np.array(STATE_NAMES), "initial_states": np.asarray(initial_states),
        "times": np.asarray(times), "transition_names": np.array(TRANSITION_NAMES),
        "transitions": np.asarray(transitions), "converged": np.asarray(converged),
        "metadata": np.array(json.dumps(metadata))}
    _validate(arrays, str(path))
    atomic_save_npz(path, arrays)
    return path
