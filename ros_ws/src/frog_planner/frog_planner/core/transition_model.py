"""Library-backed transition model: nearest initial state -> the nine primitives' transitions.

Paper seed 000, Algorithm 1 steps 5-9 and eq. 14. All velocities are SI: forward and lateral
in m/s, yaw rate in rad/s (the authors' code mixed deg/s and rad/s; this module never does).

Two neighbour metrics over the library's initial body velocities v_k = (u_k, v_k, w_k):

- ``"euclidean"`` (default): || (v - v_k) / scale || on a scipy cKDTree, ``scale`` per
  component (default: the sampled range of each component, so each spans about 1).
- ``"relative"``: Algorithm 1 step 6, d_k = || (v - v_k) / v ||, with each denominator
  guarded as max(|v_i|, relative_floor * scale_i) so a near-zero velocity does not divide by 0.

With ``k > 1`` the transitions of the k nearest states are averaged (heading as a circular mean).

``lookup="authors_code"`` searches the neighbours as the authors' published planner did
(``control_code/src/planner.py`` of softmachineslab/frog; the library's layout in
``control_code/data/load_simfrog_data.py``): their library stored the initial velocities in
the simulator's frame, x to the robot's right and y forward, and the initial yaw rate in deg/s,
and the planner compared the robot's (forward, left, rad/s) with those columns unchanged. In
this module's SI body frame that is a search over the states mapped by :data:`AUTHORS_LOOKUP`.
Only the choice of the neighbour changes; its transitions are applied as usual. It exists to
replay the authors' experiments with the planner they ran.
"""

import itertools

import numpy as np
from scipy.spatial import cKDTree

from frog_common.motion_library_file import load_motion_library

METRICS = ("euclidean", "relative")
LOOKUPS = ("si", "authors_code")
#: (forward, left, yaw rate rad/s) -> the authors' library columns (xdot0 = right = -left,
#: ydot0 = forward, tdot0 in deg/s), which their planner compared with the robot's state as is.
AUTHORS_LOOKUP = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 180.0 / np.pi]])
_RELATIVE_PROBES = 7       # extra Euclidean neighbours probed to bound the relative distance
_RELATIVE_MAX_BALL = 0.3   # scaled radius above which a query is ranked against all states


class TransitionModel:
    """Transitions after one period T from the nearest library initial state(s).

    Parameters
    ----------
    initial_states : array_like, shape (N, 3)
        Initial body velocities (m/s, m/s, rad/s).
    transitions : array_like, shape (P, N, 6)
        State after T from each initial state under each primitive: x, y m and heading rad in
        the start body frame; forward, lateral m/s and yaw rate rad/s in the body frame at T.
        Rows with any non-finite value (failed simulations) drop that initial state.
    primitive_names : sequence of str, length P
    primitive_bits : sequence of str, length P, optional
    period : float, optional
        T in s (informational; the transitions already are for T).
    metric : {"euclidean", "relative"}
    k : int
        Number of neighbours averaged, 1 <= k <= N.
    scale : array_like, shape (3,), optional
        Per-component scale (m/s, m/s, rad/s); default: range of each component of the
        initial states (1 where a component is constant).
    relative_floor : float
        Floor of the relative metric's denominators, as a fraction of ``scale``.
    source : str
        Where the model came from (for messages).
    lookup : {"si", "authors_code"}
        Compare queries with the initial states (default), or with the authors' library columns
        of them (see the module docstring).
    gradient_correction : bool
        False (the paper): a query gets its nearest state's transitions unchanged. True: they
        are corrected to first order for the difference between the query and that state,
        t(q) = t(s) + J (q - s), with J (per primitive, 3 x 6) the least-squares slope of the
        transitions over the initial states of the whole library. The frog's transitions
        are close to linear in its initial velocities (velocities persist for seconds), so
        this removes most of the error of a sparse library (a nearest neighbour can be
        ~10 deg/s of yaw rate away) at the cost of one small matrix product. The evaluator
        CLI, planner_node and the main job switch it on by default.

    Raises
    ------
    ValueError
        On bad shapes, an unknown metric, k out of range, non-positive scale, or when no
        initial state has a finite transition for every primitive.
    """

    def __init__(self, initial_states, transitions, primitive_names, primitive_bits=None, period=None,
                 metric="euclidean", k=1, scale=None, relative_floor=0.05, source="",
                 gradient_correction=False, lookup="si"):
        init = np.asarray(initial_states, dtype=float)
        trans = np.asarray(transitions, dtype=float)
        if init.ndim != 2 or init.shape[1] != 3:
            raise ValueError(f"initial_states has shape {init.shape}; expected (N, 3)")
        if trans.ndim != 3 or trans.shape[1:] != (init.shape[0], 6):
            raise ValueError(f"transitions has shape {trans.shape}; expected (P, {init.shape[0]}, 6)")
        names = [str(n) for n in primitive_names]
        if len(names) != trans.shape[0]:
            raise ValueError(f"{len(names)} primitive names for {trans.shape[0]} primitives")
        if metric not in METRICS:
            raise ValueError(f"metric {metric!r} is unknown; expected one of {list(METRICS)}")
        if lookup not in LOOKUPS:
            raise ValueError(f"lookup {lookup!r} is unknown; expected one of {list(LOOKUPS)}")
        usable = np.all(np.isfinite(trans), axis=(0, 2)) & np.all(np.isfinite(init), axis=1)
        if not np.any(usable):
            raise ValueError(f"{source or 'library'}: no initial state has a finite transition for every primitive")
        self.dropped_states = int(np.count_nonzero(~usable))
        self.initial_states = init[usable]
        self.transitions = np.ascontiguousarray(trans[:, usable, :])
        n = self.initial_states.shape[0]
        if not 1 <= int(k) <= n:
            raise ValueError(f"k {k} is out of range; expected 1 <= k <= {n} (usable initial states)")
        self.lookup_mode = lookup
        # the states the neighbour search compares queries with (the initial states, or the
        # authors' columns of them); scale, tree and metric work on these
        self._search = self.initial_states @ AUTHORS_LOOKUP.T if lookup == "authors_code" else self.initial_states
        if scale is None:
            scale = np.ptp(self._search, axis=0)
            scale = np.where(scale > 0.0, scale, 1.0)
        scale = np.asarray(scale, dtype=float)
        if scale.shape != (3,) or not np.all(scale > 0.0):
            raise ValueError(f"scale {scale.tolist()} must be 3 positive values (m/s, m/s, rad/s)")
        if not relative_floor > 0.0:
            raise ValueError(f"relative_floor {relative_floor} must be > 0")
        self.primitive_names = names
        self.primitive_bits = None if primitive_bits is None else [str(b) for b in primitive_bits]
        self.period = None if period is None else float(period)
        self.metric = metric
        self.k = int(k)
        self.scale = scale
        self.relative_floor = float(relative_floor)
        self.source = str(source)
        self._tree = cKDTree(self._search / scale)
        # Primitive-major -> state-major copy so one gather returns all P transitions of a state.
        self._by_state = np.ascontiguousarray(np.transpose(self.transitions, (1, 0, 2)))  # (N, P, 6)
        self.gradient_correction = bool(gradient_correction)
        self.jacobian = self._fit_jacobian() if self.gradient_correction else None   # (P, 3, 6)

    def _fit_jacobian(self):
        """Least-squares slopes d(transition)/d(initial velocity), one (3, 6) matrix per primitive."""
        n = self.n_states
        if n < 4:
            raise ValueError(f"gradient_correction needs at least 4 usable initial states; the library has {n}")
        design = np.column_stack([self.initial_states, np.ones(n)])                        # (N, 4)
        coef, *_ = np.linalg.lstsq(design, self.transitions.transpose(1, 0, 2).reshape(n, -1), rcond=None)
        return np.ascontiguousarray(coef[:3].reshape(3, self.n_primitives, 6).transpose(1, 0, 2))

    @classmethod
    def load(cls, path, period=1.5, metric="euclidean", k=1, scale=None, relative_floor=0.05,
             gradient_correction=False, lookup="si"):
        """Transition model from a library file for period T (see :func:`load_motion_library`).

        Parameters
        ----------
        path : str or os.PathLike
        period : float
            T in s; any multiple of the file's sample interval up to its horizon.
        metric, k, scale, relative_floor, gradient_correction
            As for :class:`TransitionModel`.

        Raises
        ------
        FileNotFoundError, LibraryFormatError, ValueError
        """
        return cls.from_library(load_motion_library(path), period, metric, k, scale, relative_floor,
                                gradient_correction, lookup)

    @classmethod
    def from_library(cls, library, period=1.5, metric="euclidean", k=1, scale=None, relative_floor=0.05,
                     gradient_correction=False, lookup="si"):
        """Transition model from a :class:`MotionLibrary` for period T in s.

        Initial states with a failed simulation (``converged`` False) for any primitive are dropped.
        """
        transitions = library.transitions_at(period)
        transitions[~library.converged] = np.nan
        return cls(library.initial_states, transitions, library.primitive_names,
                   library.primitive_bits, period, metric, k, scale, relative_floor, library.source,
                   gradient_correction, lookup)

    @property
    def n_primitives(self):
        """Number of primitives P."""
        return self.transitions.shape[0]

    @property
    def n_states(self):
        """Number of usable initial states N."""
        return self.initial_states.shape[0]

    def primitive_id(self, name):
        """Id (index) of a primitive name; raises ValueError naming the known ones."""
        try:
            return self.primitive_names.index(str(name))
        except ValueError:
            raise ValueError(f"primitive {name!r} is unknown; expected one of {self.primitive_names}") from None

    def nearest(self, body_velocities):
        """Indices of the k nearest initial states (Algorithm 1 steps 6-7).

        Parameters
        ----------
        body_velocities : array_like, shape (M, 3) or (3,)
            Query body velocities (forward m/s, lateral m/s, yaw rate rad/s).

        Returns
        -------
        indices : numpy.ndarray, shape (M, k), int
            Into ``initial_states``, nearest first.
        distances : numpy.ndarray, shape (M, k)
            Metric values (dimensionless).
        """
        q = np.atleast_2d(np.asarray(body_velocities, dtype=float))
        if q.shape[-1] != 3:
            raise ValueError(f"body velocities have shape {q.shape}; expected (M, 3)")
        if self.metric == "euclidean":
            dist, idx = self._tree.query(q / self.scale, k=self.k)
            return idx.reshape(len(q), self.k), dist.reshape(len(q), self.k)
        return self._nearest_relative(q)

    def _nearest_relative(self, q):
        """Algorithm 1 step 6 (guarded), exact, with KD-tree pruning.

        In the tree's scaled coordinates q' = q / scale the relative metric is a weighted
        Euclidean one, d_rel^2 = sum_c alpha_c^2 (q'_c - s'_c)^2 with alpha_c = scale_c / den_c,
        so d_rel >= min(alpha) * d'. A few Euclidean-nearest states give an upper bound D on the
        k-th smallest d_rel; every state that can beat it lies within D / min(alpha) of q' and is
        fetched with a ball query, then ranked exactly (ties to the lower index, like brute force).
        Queries whose ball would be large are ranked against all states instead.
        """
        n_q, k = len(q), self.k
        floor = self.relative_floor * self.scale
        den = np.maximum(np.abs(q), floor)                                   # guarded v_i
        scaled = q / self.scale
        n_probe = min(self.n_states, k + _RELATIVE_PROBES)
        _, probe = self._tree.query(scaled, k=n_probe)
        probe = probe.reshape(n_q, n_probe)
        d_probe = np.sqrt(np.sum(((q[:, None, :] - self._search[probe]) / den[:, None, :]) ** 2, axis=-1))
        bound = np.partition(d_probe, k - 1, axis=1)[:, k - 1]
        radius = bound / np.min(self.scale / den, axis=1) * (1.0 + 1e-9) + 1e-12
        idx = np.empty((n_q, k), dtype=np.intp)
        dist = np.empty((n_q, k))
        wide = radius > _RELATIVE_MAX_BALL
        if np.any(wide):                                                     # brute force over all states
            w = np.flatnonzero(wide)
            d = np.sqrt(np.sum(((q[w, None, :] - self._search[None]) / den[w, None, :]) ** 2, axis=-1))
            if k == 1:
                part = np.argmin(d, axis=1)[:, None]
            else:
                part = np.argpartition(d, k - 1, axis=1)[:, :k]
                rows = np.arange(len(w))[:, None]
                part = np.take_along_axis(part, np.lexsort((part, d[rows, part]), axis=1), axis=1)
            idx[w] = part
            dist[w] = np.take_along_axis(d, part, axis=1)
        narrow = np.flatnonzero(~wide)
        if len(narrow):
            lists = self._tree.query_ball_point(scaled[narrow], radius[narrow])
            lengths = np.fromiter((len(c) for c in lists), dtype=np.intp, count=len(narrow))
            cand = np.fromiter(itertools.chain.from_iterable(lists), dtype=np.intp, count=int(lengths.sum()))
            owner = np.repeat(narrow, lengths)
            d = np.sqrt(np.sum(((q[owner] - self._search[cand]) / den[owner]) ** 2, axis=1))
            order = np.lexsort((cand, d, owner))                 # by query, then distance, then index
            starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
            pick = order[starts[:, None] + np.arange(k)]         # each ball holds the k probes that set D
            idx[narrow] = cand[pick]
            dist[narrow] = d[pick]
        return idx, dist

    def lookup(self, body_velocities):
        """Transitions of every primitive from the nearest initial state(s) (Algorithm 1 step 9).

        Parameters
        ----------
        body_velocities : array_like, shape (M, 3) or (3,)

        Returns
        -------
        numpy.ndarray, shape (M, P, 6)
            Mean over the k neighbours (each first-order corrected with ``gradient_correction``);
            heading (column 2) as a circular mean.
        """
        idx, _ = self.nearest(body_velocities)
        if self.gradient_correction:
            q = np.atleast_2d(np.asarray(body_velocities, dtype=float))
            dq = q[:, None, :] - self.initial_states[idx]                     # (M, k, 3)
            rows = self._by_state[idx] + np.einsum("mkc,pco->mkpo", dq, self.jacobian)
            if self.k == 1:
                return rows[:, 0]
        elif self.k == 1:
            return self._by_state[idx[:, 0]]
        else:
            rows = self._by_state[idx]                                       # (M, k, P, 6)
        out = rows.mean(axis=1)
        out[..., 2] = np.arctan2(np.sin(rows[..., 2]).mean(axis=1), np.cos(rows[..., 2]).mean(axis=1))
        return out
