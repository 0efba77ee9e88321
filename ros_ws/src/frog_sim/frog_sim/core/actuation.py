"""SMA limb actuation: the paper's piecewise logistic curvature model (eq. 9).

    kappa(t) = C1a / (1 + exp(-C2a (t - C3a))) + C4a     for t <  t0  (actuation)
    kappa(t) = C1d / (1 + exp(-C2d (t - C3d))) + C4d     for t >= t0  (de-actuation)

``t`` is the time since the limb was fired. One model is fitted to every measured
(EGaIn, frequency) mean profile in ``limb_curvature_profiles.csv`` (paper,
"Actuator Characterization"). The switch time t0 is the time of the measured
curvature minimum (end of the actuation phase). After the measured cycle
(t >= 1/f) a limb that is not fired again holds the end-of-cycle curvature.

Where the coefficients come from ("runs anywhere")
-----------------------------------------------------------
The project's own fit of every measured profile ships with the package as
``frog_sim/data/actuation_fit.json`` (coefficients per EGaIn and frequency, each fit's
RMS, the sha256 of the profile CSV it came from, fit and code version). At run time
:meth:`ActuationLibrary.load` uses it, so a clone without the measurements runs. The raw
measurements are used only when they are given (``$FROG_DATA_DIR`` or an ancestor's
``shared/data/frog``) and:

* a refit is asked for (``refit=True`` or ``$FROG_SIM_REFIT=1``), or
* their sha256 differs from the one recorded in the shipped fit: then the shipped fit is
  stale for these data; the data are refitted (cached in ``$FROG_SIM_CACHE_DIR``, default
  ``~/.cache/frog_sim``) and a ``StaleFitWarning`` names both hashes. A mismatch is never
  ignored silently; ``frog-sim fit --write-package-data`` regenerates the shipped file.

With no data at hand the shipped fit is used as is (``source['verified'] = False``).

Stiffness: while a limb is in its actuation phase (0 <= t < t0, SMA hot) its Young's
modulus is E_max, otherwise E_0 (paper: E_0 = 3.0 MPa, E_max = 8.04 MPa).
"""
from __future__ import annotations

import csv
import hashlib
import json
import os
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit
from scipy.optimize import curve_fit
from frog_common.version import code_version

FIT_VERSION = 1
#: Package-data file of the shipped fit (relative to the ``frog_sim`` package).
PACKAGE_FIT_FILE = ('data', 'actuation_fit.json')
DATA_FILE_NAME = 'limb_curvature_profiles.csv'
CALIBRATION_FILE_NAME = 'calibration_runs_10pct.csv'


class StaleFitWarning(UserWarning):
    """The shipped eq. 9 fit was made from other data than the measurements at hand."""


def find_data_dir(required: str = DATA_FILE_NAME) -> Path:
    """Directory with the frog measurements (``$FROG_DATA_DIR`` or ``<ancestor>/shared/data/frog``).

    Parameters
    ----------
    required : str
        File the directory must hold (default the limb curvature profiles).

    Raises
    ------
    FileNotFoundError
        If no directory holding ``required`` is found (the message names the file).
    """
    env = os.environ.get('FROG_DATA_DIR')
    if env:
        path = Path(env)
        if (path / required).is_file():
            return path
        raise FileNotFoundError(f'FROG_DATA_DIR={env} does not contain {required}')
    for parent in Path(__file__).resolve().parents:
        for cand in (parent / 'shared' / 'data' / 'frog', parent.parent / 'shared' / 'data' / 'frog'):
            if (cand / required).is_file():
                return cand
    raise FileNotFoundError(f'{required} not found; set FROG_DATA_DIR to the folder '
                            'with the frog measurements (shared/data/frog)')


def find_data_file(name: str) -> Path:
    """Path of one measurement file (see :func:`find_data_dir`); ``name`` may hold a sub-folder."""
    return find_data_dir(name) / name


def optional_data_dir() -> Path | None:
    """:func:`find_data_dir`, or ``None`` when no measurements are at hand.

    An explicit ``$FROG_DATA_DIR`` that lacks the profiles still counts as "not given"
    here (callers that need the data raise with :func:`find_data_dir`'s message).
    """
    try:
        return find_data_dir()
    except FileNotFoundError:
        return None


def file_sha256(path: Path | str) -> str:
    """Hex sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def package_fit_path() -> Path:
    """Location of the shipped fit (``frog_sim/data/actuation_fit.json``)."""
    from importlib.resources import files
    return Path(str(files('frog_sim').joinpath(*PACKAGE_FIT_FILE)))


def cache_dir() -> Path:
    """Directory for generated artefacts (``$FROG_SIM_CACHE_DIR`` or ``~/.cache/frog_sim``)."""
    path = Path(os.environ.get('FROG_SIM_CACHE_DIR', Path.home() / '.cache' / 'frog_sim'))
    path.mkdir(parents=True, exist_ok=True)
    return path


def read_curvature_profiles(path: Path | str | None = None) -> dict:
    """Read the measured profiles.

    Returns
    -------
    dict
        ``{(egain_pct, frequency_hz): (t_s (n,), curvature_per_m (n,))}`` with keys
        rounded to 0.1.
    """
    path = Path(path) if path else find_data_dir() / DATA_FILE_NAME
    rows: dict = {}
    with open(path, newline='') as fh:
        for r in csv.DictReader(fh):
            key = (round(float(r['egain_vol_pct']), 1), round(float(r['frequency_hz']), 1))
            rows.setdefault(key, []).append((float(r['t_s']), float(r['curvature_per_m'])))
    out = {}
    for key, vals in rows.items():
        arr = np.array(sorted(vals))
        out[key] = (arr[:, 0], arr[:, 1])
    return out


def _logistic(t, c1, c2, c3, c4):
    z = np.clip(-c2 * (t - c3), -700.0, 700.0)
    return c1 / (1.0 + np.exp(z)) + c4


@dataclass(frozen=True)
class CurvatureProfile:
    """Fitted eq. 9 model of one (EGaIn, frequency) profile.

    Attributes
    ----------
    egain_vol_pct, frequency_hz : float
    coefficients : tuple of 8 float
        C1a, C2a, C3a, C4a, C1d, C2d, C3d, C4d (1/m, 1/s, s, 1/m).
    switch_time : float
        t0 [s], end of the actuation phase.
    cycle_time : float
        1 / frequency [s].
    rms_error : float
        RMS of the fit over the measured cycle [1/m].
    """

    egain_vol_pct: float
    frequency_hz: float
    coefficients: tuple
    switch_time: float
    cycle_time: float
    rms_error: float
    #: ((egain, frequency, weight), ...) of the measured profiles an interpolated one is made of
    interpolated_from: tuple = ()

    def curvature(self, time_since_fire) -> np.ndarray:
        """Curvature [1/m] at ``time_since_fire`` [s] (array-like; negative = never fired)."""
        tau = np.asarray(time_since_fire, dtype=float)
        c = self.coefficients
        act = _logistic(tau, *c[:4])
        deact = _logistic(np.minimum(tau, self.cycle_time), *c[4:])
        out = np.where(tau < self.switch_time, act, deact)
        return np.where(tau < 0, self.relaxed_curvature, out)

    @property
    def relaxed_curvature(self) -> float:
        """Curvature of a limb that has not been fired for a whole cycle [1/m]."""
        return float(_logistic(self.cycle_time, *self.coefficients[4:]))

    def as_row(self) -> np.ndarray:
        """Numba row: 8 coefficients, switch time, cycle time."""
        return np.array(list(self.coefficients) + [self.switch_time, self.cycle_time])


def fit_profile(t: np.ndarray, kappa: np.ndarray, egain: float, frequency: float) -> CurvatureProfile:
    """Fit eq. 9 to one measured profile (scipy ``curve_fit`` on each phase).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Time since firing [s].
    kappa : ndarray, shape (n,)
        Mean curvature [1/m].

    Returns
    -------
    CurvatureProfile
    """
    smooth = np.convolve(kappa, np.ones(5) / 5.0, mode='same')
    smooth[:2] = kappa[:2]
    smooth[-2:] = kappa[-2:]
    i_min = int(np.argmin(smooth))
    t_switch = float(t[i_min])
    cycle = 1.0 / frequency
    k_start, k_min, k_end = float(kappa[0]), float(kappa[i_min]), float(kappa[-1])
    ta, ka = t[:i_min + 1], kappa[:i_min + 1]
    td, kd = t[i_min:], kappa[i_min:]
    p0a = [k_min - k_start, 60.0, 0.5 * t_switch, k_start]
    p0d = [k_end - k_min, 10.0, t_switch + 0.3 * (cycle - t_switch), k_min]
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        try:
            pa, _ = curve_fit(_logistic, ta, ka, p0=p0a, maxfev=20000)
        except RuntimeError:
            pa = np.array(p0a)
        try:
            pd, _ = curve_fit(_logistic, td, kd, p0=p0d, maxfev=20000)
        except RuntimeError:
            pd = np.array(p0d)
    prof = CurvatureProfile(float(egain), float(frequency), tuple(float(v) for v in (*pa, *pd)),
                            t_switch, cycle, 0.0)
    rms = float(np.sqrt(np.mean((prof.curvature(t) - kappa) ** 2)))
    return CurvatureProfile(prof.egain_vol_pct, prof.frequency_hz, prof.coefficients,
                            t_switch, cycle, rms)


class ActuationLibrary:
    """All fitted profiles, loaded from the cache or fitted on first use.

    Examples
    --------
    >>> lib = ActuationLibrary.load()                      # doctest: +SKIP
    >>> lib.profile(10, 1.0).relaxed_curvature             # doctest: +SKIP
    127.3...
    """

    def __init__(self, profiles: dict, source: dict):
        self.profiles = profiles
        self.source = source

    @classmethod
    def load(cls, data_path: Path | str | None = None, use_cache: bool = True,
             refit: bool | None = None) -> 'ActuationLibrary':
        """The eq. 9 fit to use: the shipped one, or a refit of the measurements at hand.

        Parameters
        ----------
        data_path : path, optional
            A profile CSV to fit (always fitted, cached by its sha256).
        use_cache : bool
            Read/write refits in :func:`cache_dir`.
        refit : bool, optional
            Refit from the measurements (``$FROG_DATA_DIR`` / ancestor ``shared/data/frog``)
            even if they match the shipped fit. Default: ``$FROG_SIM_REFIT == '1'``.

        Raises
        ------
        FileNotFoundError
            If a refit is asked for without data, or the shipped fit is missing and no
            data are at hand.

        Warns
        -----
        StaleFitWarning
            If the measurements at hand differ from those of the shipped fit (then they
            are refitted and used).
        """
        if data_path is not None:
            return cls.fit_file(data_path, use_cache=use_cache)
        if refit is None:
            refit = os.environ.get('FROG_SIM_REFIT', '') == '1'
        data_dir = optional_data_dir()
        if refit:
            return cls.fit_file(find_data_dir() / DATA_FILE_NAME, use_cache=use_cache)
        shipped = None
        shipped_path = package_fit_path()
        try:
            shipped = cls._from_json(json.loads(shipped_path.read_text()))
        except FileNotFoundError:
            pass
        except (ValueError, KeyError, TypeError) as exc:
            warnings.warn(f'shipped eq. 9 fit {shipped_path} is unreadable ({exc}); refitting',
                          StaleFitWarning, stacklevel=2)
        if data_dir is None:
            if shipped is None:
                raise FileNotFoundError(
                    f'the shipped eq. 9 fit {shipped_path} is missing and {DATA_FILE_NAME} is not '
                    'at hand to refit it; set FROG_DATA_DIR to the folder with the frog '
                    'measurements (shared/data/frog)')
            shipped.source.update(loaded_from=str(shipped_path), verified=False)
            return shipped
        data_file = data_dir / DATA_FILE_NAME
        digest = file_sha256(data_file)
        if shipped is not None and shipped.source.get('data_sha256') == digest:
            shipped.source.update(loaded_from=str(shipped_path), verified=True)
            return shipped
        if shipped is not None:
            warnings.warn(f'{data_file} (sha256 {digest[:12]}) differs from the data of the shipped '
                          f'eq. 9 fit (sha256 {str(shipped.source.get("data_sha256"))[:12]}); using a '
                          'refit of the measurements. Regenerate the shipped fit with '
                          '`frog-sim fit --write-package-data`.', StaleFitWarning, stacklevel=2)
        return cls.fit_file(data_file, use_cache=use_cache)

    @classmethod
    def fit_file(cls, path: Path | str, use_cache: bool = True) -> 'ActuationLibrary':
        """Fit eq. 9 to every profile of one CSV (cached in :func:`cache_dir` by sha256)."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f'{path} not found (measured limb curvature profiles)')
        digest = file_sha256(path)
        cache_file = cache_dir() / f'actuation_fit_v{FIT_VERSION}_{digest[:16]}.json' if use_cache else None
        if cache_file is not None and cache_file.is_file():
            try:
                lib = cls._from_json(json.loads(cache_file.read_text()))
                lib.source.update(loaded_from=str(cache_file), verified=True)
                return lib
            except (ValueError, KeyError, TypeError):
                pass  # corrupt cache: refit
        data = read_curvature_profiles(path)
        profiles = {key: fit_profile(t, k, *key) for key, (t, k) in sorted(data.items())}
        source = {'data_file': path.name, 'data_sha256': digest, 'fit_version': FIT_VERSION,
                  'code_version': code_version('frog_sim'),
                  'created_utc': time.strftime('%Y-%m-%dT%H:%M:%SZ', time.gmtime()),
                  'model': 'paper eq. 9 piecewise logistic, curve_fit per phase',
                  'units': {'coefficients': 'C1,C4 [1/m]; C2 [1/s]; C3 [s]',
                            'switch_time': 's', 'cycle_time': 's', 'rms_error': '1/m'}}
        lib = cls(profiles, source)
        if cache_file is not None:
            lib.write_json(cache_file)
        lib.source.update(loaded_from=str(path), verified=True)
        return lib

    def write_json(self, path: Path | str) -> Path:
        """Write the fit as JSON (atomically); run-time keys of ``source`` are dropped."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        obj = self._to_json()
        for key in ('loaded_from', 'verified', 'cache_file'):
            obj['source'].pop(key, None)
        tmp = path.with_suffix('.tmp')
        tmp.write_text(json.dumps(obj, indent=1) + '\n')
        tmp.replace(path)
        return path

    def _to_json(self) -> dict:
        return {'source': dict(self.source), 'profiles': [
            {'egain_vol_pct': p.egain_vol_pct, 'frequency_hz': p.frequency_hz,
             'coefficients': list(p.coefficients), 'switch_time': p.switch_time,
             'cycle_time': p.cycle_time, 'rms_error': p.rms_error}
            for p in self.profiles.values()]}

    @classmethod
    def _from_json(cls, obj: dict) -> 'ActuationLibrary':
        profiles = {}
        for p in obj['profiles']:
            prof = CurvatureProfile(p['egain_vol_pct'], p['frequency_hz'], tuple(p['coefficients']),
                                    p['switch_time'], p['cycle_time'], p['rms_error'])
            profiles[(round(prof.egain_vol_pct, 1), round(prof.frequency_hz, 1))] = prof
        if not profiles:
            raise ValueError('no profiles')
        return cls(profiles, dict(obj['source']))

    def frequencies(self, egain_vol_pct: float) -> list[float]:
        """Measured frequencies [Hz] for one EGaIn fraction."""
        return sorted(f for e, f in self.profiles if e == round(float(egain_vol_pct), 1))

    def profile(self, egain_vol_pct: float, frequency_hz: float,
                tolerance_hz: float = 0.005, interpolate: bool = True) -> CurvatureProfile:
        """Profile measured at ``frequency_hz`` (within ``tolerance_hz``), else interpolated.

        A design that was not measured (an EGaIn fraction or a frequency between measured
        ones) gets the eq. 9 coefficients interpolated by :meth:`interpolated_profile`.

        Raises
        ------
        ValueError
            If the design lies outside the hull of the measured designs (or, with
            ``interpolate=False``, was not measured); the message names the measured range.
        """
        egains = sorted({e for e, _ in self.profiles})
        e = round(float(egain_vol_pct), 1)
        if e in egains:
            freqs = self.frequencies(e)
            f = min(freqs, key=lambda q: abs(q - frequency_hz))
            if abs(f - frequency_hz) <= tolerance_hz:
                return self.profiles[(e, f)]
            if not interpolate:
                raise ValueError(f'frequency {frequency_hz} Hz was not measured for EGaIn {e} %; '
                                 f'measured: {freqs} Hz')
        elif not interpolate:
            raise ValueError(f'EGaIn {egain_vol_pct} % has no measured profile; expected one of {egains}')
        return self.interpolated_profile(egain_vol_pct, frequency_hz)

    #: Scales that make the measured design grid square for the triangulation (10 %, 0.1 Hz).
    INTERPOLATION_SCALES = (10.0, 0.1)

    def interpolated_profile(self, egain_vol_pct: float, frequency_hz: float) -> CurvatureProfile:
        """eq. 9 coefficients interpolated linearly between measured designs.

        Method: the measured (EGaIn, frequency) designs, scaled by 10 % and 0.1 Hz so
        their grid is square, are triangulated (Delaunay); a design inside a triangle gets
        the barycentric average of its three corners' coefficients C1a-C4d and switch time
        t0 (on a measured EGaIn line between two measured frequencies this is linear
        interpolation in frequency between them). The cycle time is 1/f; ``rms_error`` is
        the weighted RMS of the corners' fits (the fit error, not the interpolation error:
        the leave-one-out test measures that). Outside the hull a ValueError names the
        measured frequency range at the nearest measured EGaIn.
        """
        from scipy.spatial import Delaunay
        keys = sorted(self.profiles)
        if getattr(self, '_tri_keys', None) != keys:
            se, sf = self.INTERPOLATION_SCALES
            self._tri = Delaunay(np.array([(k[0] / se, k[1] / sf) for k in keys]))
            self._tri_keys = keys
        se, sf = self.INTERPOLATION_SCALES
        q = np.array([float(egain_vol_pct) / se, float(frequency_hz) / sf])
        simplex = int(self._tri.find_simplex(q, tol=1e-9))
        if simplex < 0 or not (np.isfinite(egain_vol_pct) and np.isfinite(frequency_hz) and frequency_hz > 0):
            egains = sorted({e for e, _ in keys})
            near = min(egains, key=lambda v: abs(v - float(egain_vol_pct)))
            fr = self.frequencies(near)
            raise ValueError(f'EGaIn {egain_vol_pct} % at {frequency_hz} Hz is outside the measured designs '
                             f'(EGaIn {egains[0]:g}-{egains[-1]:g} %; at {near:g} % measured {fr[0]:g}-{fr[-1]:g} Hz); '
                             'no profile is extrapolated')
        t = self._tri.transform[simplex]
        b = t[:2] @ (q - t[2])
        weights = np.array([b[0], b[1], 1.0 - b.sum()])
        corners = [keys[i] for i in self._tri.simplices[simplex]]
        profs = [self.profiles[k] for k in corners]
        coef = sum(w * np.array(p.coefficients) for w, p in zip(weights, profs))
        switch = float(sum(w * p.switch_time for w, p in zip(weights, profs)))
        rms = float(np.sqrt(sum(w * p.rms_error ** 2 for w, p in zip(weights, profs))))
        used = tuple((float(k[0]), float(k[1]), float(w)) for k, w in zip(corners, weights) if w > 1e-9)
        return CurvatureProfile(float(egain_vol_pct), float(frequency_hz), tuple(float(c) for c in coef),
                                switch, 1.0 / float(frequency_hz), rms, used)

    def nearest_profile(self, egain_vol_pct: float, frequency_hz: float) -> CurvatureProfile:
        """Profile at the measured frequency nearest to ``frequency_hz`` (no tolerance)."""
        return self.profile(egain_vol_pct, frequency_hz, tolerance_hz=np.inf)

    def fit_report(self) -> list[tuple[float, float, float]]:
        """Rows ``(egain %, frequency Hz, RMS fit error 1/m)``."""
        return [(p.egain_vol_pct, p.frequency_hz, p.rms_error) for p in self.profiles.values()]


@dataclass
class ActuatorArrays:
    """Flat arrays that let the numba stepper update limb properties at any time.

    Attributes
    ----------
    limb_profile : ndarray, shape (L, 10)
        :meth:`CurvatureProfile.as_row` of each limb.
    limb_young : ndarray, shape (L, 2)
        (E_0, E_max) [Pa].
    activation_times : ndarray, shape (K,)
        Sorted firing times of all limbs, limb after limb [s].
    activation_offsets : ndarray of int, shape (L + 1,)
        Limb ``l`` owns ``activation_times[offsets[l]:offsets[l+1]]``.
    bend_index, bend_limb : ndarray of int, shape (Ba,)
        Actuated bending elements and their limb.
    bend_sign : ndarray, shape (Ba,)
        +1 / -1: orientation of the limb's curl (kappa0 = sign * kappa(t)).
    bend_second_moment : ndarray, shape (Ba,)
        I [m^4] (EI = E(t) I).
    edge_index, edge_limb : ndarray of int, shape (Ea,)
    edge_area : ndarray, shape (Ea,)
        A [m^2] (EA = E(t) A).
    root_index, root_limb : ndarray of int, shape (R,)
        Root bends (body side edge -> first limb edge) and their limb.
    root_sign : ndarray, shape (R,)
    root_base_angle : ndarray, shape (R,)
        Turning angle of the root bend for a straight limb [rad].
    root_half_edge : ndarray, shape (R,)
        Half of the first limb edge [m]: the root bend carries the limb curvature of
        this half cell, so the whole limb length is curved (dl-consistent):
        ``kappa0 = 2 tan((base + sign atan(kappa dl / 2)) / 2) / root_length``.
    root_length : ndarray, shape (R,)
        Voronoi length of the root bend [m].
    root_second_moment : ndarray, shape (R,)
        Effective I of the root bend [m^4] (EI = E(t) I): 2 I_limb, since only the limb
        half of the root cell bends (the body half is rigid; springs in series).
    """

    limb_profile: np.ndarray
    limb_young: np.ndarray
    activation_times: np.ndarray
    activation_offsets: np.ndarray
    bend_index: np.ndarray
    bend_limb: np.ndarray
    bend_sign: np.ndarray
    bend_second_moment: np.ndarray
    edge_index: np.ndarray
    edge_limb: np.ndarray
    edge_area: np.ndarray
    root_index: np.ndarray = None
    root_limb: np.ndarray = None
    root_sign: np.ndarray = None
    root_base_angle: np.ndarray = None
    root_half_edge: np.ndarray = None
    root_length: np.ndarray = None
    root_second_moment: np.ndarray = None

    def __post_init__(self):
        if self.root_index is None:
            self.root_index = np.zeros(0, dtype=np.int64)
            self.root_limb = np.zeros(0, dtype=np.int64)
            self.root_sign = np.zeros(0)
            self.root_base_angle = np.zeros(0)
            self.root_half_edge = np.zeros(0)
            self.root_length = np.zeros(0)
            self.root_second_moment = np.zeros(0)

    @classmethod
    def empty(cls) -> 'ActuatorArrays':
        """No actuated limbs."""
        zi = np.zeros(0, dtype=np.int64)
        zf = np.zeros(0)
        return cls(np.zeros((0, 10)), np.zeros((0, 2)), zf, np.zeros(1, dtype=np.int64),
                   zi, zi.copy(), zf.copy(), zf.copy(), zi.copy(), zi.copy(), zf.copy())

    def set_activation_times(self, times_per_limb) -> None:
        """Replace the firing times: ``times_per_limb[l]`` is a 1-D array for limb ``l``."""
        arrays = [np.sort(np.asarray(t, dtype=float).ravel()) for t in times_per_limb]
        if len(arrays) != self.limb_profile.shape[0]:
            raise ValueError(f'got firing times for {len(arrays)} limbs, expected '
                             f'{self.limb_profile.shape[0]}')
        self.activation_offsets = np.concatenate([[0], np.cumsum([len(a) for a in arrays])]).astype(np.int64)
        self.activation_times = np.concatenate(arrays) if arrays else np.zeros(0)

    def as_tuple(self):
        """Arguments of :func:`apply_actuation` after ``t``."""
        return (self.limb_profile, self.limb_young, self.activation_times, self.activation_offsets,
                self.bend_index, self.bend_limb, self.bend_sign, self.bend_second_moment,
                self.edge_index, self.edge_limb, self.edge_area, self.root_index, self.root_limb,
                self.root_sign, self.root_base_angle, self.root_half_edge, self.root_length,
                self.root_second_moment)


@njit(cache=True, error_model='numpy')
def _logistic_scalar(t, c1, c2, c3, c4):
    z = -c2 * (t - c3)
    if z > 700.0:
        z = 700.0
    elif z < -700.0:
        z = -700.0
    return c1 / (1.0 + np.exp(z)) + c4


@njit(cache=True, error_model='numpy')
def profile_value(row, tau):
    """eq. 9 for one numba profile row at time ``tau`` since firing (< 0: never fired)."""
    if tau < 0.0:
        return _logistic_scalar(row[9], row[4], row[5], row[6], row[7])
    if tau < row[8]:
        return _logistic_scalar(tau, row[0], row[1], row[2], row[3])
    if tau > row[9]:
        tau = row[9]
    return _logistic_scalar(tau, row[4], row[5], row[6], row[7])


@njit(cache=True, error_model='numpy')
def apply_actuation(t, limb_profile, limb_young, activation_times, activation_offsets,
                    bend_index, bend_limb, bend_sign, bend_second_moment, edge_index, edge_limb,
                    edge_area, root_index, root_limb, root_sign, root_base_angle, root_half_edge,
                    root_length, root_second_moment, kappa0, ei, ea):
    """Write the natural curvature and stiffness of actuated elements at time ``t`` [s]."""
    update_actuators(t, (limb_profile, limb_young, activation_times, activation_offsets,
                         bend_index, bend_limb, bend_sign, bend_second_moment, edge_index,
                         edge_limb, edge_area, root_index, root_limb, root_sign, root_base_angle,
                         root_half_edge, root_length, root_second_moment), kappa0, ei, ea)


@njit(cache=True, error_model='numpy')
def update_actuators(t, actuator, kappa0, ei, ea):
    """:func:`apply_actuation` with the actuator arrays packed as ``ActuatorArrays.as_tuple()``."""
    (limb_profile, limb_young, activation_times, activation_offsets, bend_index, bend_limb,
     bend_sign, bend_second_moment, edge_index, edge_limb, edge_area, root_index, root_limb,
     root_sign, root_base_angle, root_half_edge, root_length, root_second_moment) = actuator
    n_limbs = limb_profile.shape[0]
    kap = np.empty(n_limbs)
    young = np.empty(n_limbs)
    for limb in range(n_limbs):
        lo = activation_offsets[limb]
        hi = activation_offsets[limb + 1]
        tau = -1.0
        if hi > lo:
            k = np.searchsorted(activation_times[lo:hi], t, side='right')
            if k > 0:
                tau = t - activation_times[lo + k - 1]
        kap[limb] = profile_value(limb_profile[limb], tau)
        heated = tau >= 0.0 and tau < limb_profile[limb, 8]
        young[limb] = limb_young[limb, 1] if heated else limb_young[limb, 0]
    for m in range(bend_index.shape[0]):
        limb = bend_limb[m]
        kappa0[bend_index[m]] = bend_sign[m] * kap[limb]
        ei[bend_index[m]] = young[limb] * bend_second_moment[m]
    for m in range(edge_index.shape[0]):
        ea[edge_index[m]] = young[edge_limb[m]] * edge_area[m]
    for m in range(root_index.shape[0]):
        half = np.arctan(0.5 * kap[root_limb[m]] * 2.0 * root_half_edge[m])
        kappa0[root_index[m]] = 2.0 * np.tan(0.5 * (root_base_angle[m] + root_sign[m] * half)) / root_length[m]
        ei[root_index[m]] = young[root_limb[m]] * root_second_moment[m]
