"""The kinematics service's model: one robot, its solver, warm starts and request checks.

:class:`RobotKinematics` wraps a :class:`~softkin_fk.core.forward.ForwardSolver` for the
kinematics node (and the twin): forward kinematics of an actuation, inverse kinematics of a
marker target warm started from a previous solution or the nearest configuration-space sample
(Algorithm 3's seeding), trajectories (Algorithm 3), and the checks that turn a bad request
into a reason instead of a solve. It is not thread-safe: one thread owns it (the node's
solver worker).

Cable actuators also have a *pull* (m): how far the cable is drawn in from rest,
``(1 - s_j) L_j`` (eq. 6's ratio s_j times the cable length L_j), which is what a tendon
motor sets.

A cable at rest (s = 1) admits a slack and a taut equilibrium, and the core leaves it slack
even where bending of the proximal knuckles stretches its slots beyond the cable (up to ~3 %
at s = (0.906, 0.887, 1): the tip then lies 0.76 mm from the taut equilibrium).
``hold_rest_cables=True`` (``ForwardSolver.hold_rest_cables``) makes such a cable taut, as a
motor holding it would; the built-in curves were placed without it, and with it the first
waypoint of 'L' lies 0.40 mm outside the workspace.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Optional

import numpy as np
from frog_common.settings import Settings, setting

from .forward import FKResult, ForwardSolver
from .inverse import IKResult, solve_ik
from .mesh import SoftMesh
from .trajectory import CURVES, TrajectoryResult, follow_trajectory, sample_configuration_space


class RequestError(ValueError):
    """A request the model refuses (bad shape, not finite, out of bounds, absurd target)."""


#: Accepted error thresholds lambda [m] (the node's ``tolerance`` parameter has the same range).
LAM_RANGE = (1e-6, 0.01)
#: Largest iteration limit a request may ask for.
MAX_ITERATIONS = 1000
#: Most waypoints one trajectory may have (a built-in curve's samples or given points).
MAX_WAYPOINTS = 10_000


def check_tolerance(lam: float, default: float) -> float:
    """A request's threshold lambda [m]: 0 means ``default``; NaN, inf or out of range is refused."""
    lam = float(lam)
    if lam == 0.0:
        return default
    # NaN compares False with everything: "error <= nan" would report every waypoint missed
    # but the setpoints would still be sent
    if not np.isfinite(lam) or not LAM_RANGE[0] <= lam <= LAM_RANGE[1]:
        raise RequestError(f"tolerance {lam!r} m is not finite in [{LAM_RANGE[0]:g}, {LAM_RANGE[1]:g}] m "
                           f"(0 = the node's default {default:g} m)")
    return lam


def check_iterations(i_max: int, default: int) -> int:
    """A request's iteration limit: 0 means ``default``; above :data:`MAX_ITERATIONS` is refused."""
    i_max = int(i_max)
    if i_max == 0:
        return default
    if not 1 <= i_max <= MAX_ITERATIONS:
        raise RequestError(f"max_iterations {i_max} is not in 1-{MAX_ITERATIONS} (0 = the node's default {default})")
    return i_max


@dataclasses.dataclass(frozen=True)
class IKSettings(Settings):
    """Inverse-kinematics settings (Algorithm 2); kinematics_node's parameters of the names given."""

    jacobian: str = setting('implicit', "IK Jacobian: implicit-function sensitivity (fast) or the paper's central "
                            "differences", choices=('implicit', 'central'))
    direction: str = setting('gauss-newton', "IK search direction", choices=('gauss-newton', 'gradient'))
    lam: float = setting(0.2e-3, "IK error threshold lambda (0.2 mm in the paper)", min=LAM_RANGE[0],
                         max=LAM_RANGE[1], unit="m", live=True, param="tolerance")
    i_max: int = setting(30, "IK iteration limit i_max", min=1, max=MAX_ITERATIONS, live=True,
                         param="max_iterations")
    fk_tol: float = setting(1e-7, "forward-kinematics tolerance", min=1e-10, max=1e-4, unit="m",
                            param="fk_tolerance")


def load_robot(model: str = 'finger', resolution: int = 0, mesh_file: str = '', spec_file: str = '') -> SoftMesh:
    """The robot mesh: a built-in model, or a user mesh with its JSON spec (as the ``softkin`` CLI).

    Parameters
    ----------
    model : {'finger', 'pneumatic', 'dea'}
        Built-in model (ignored with ``mesh_file``).
    resolution : int
        Mesh resolution of the built-in model; 0 = its default.
    mesh_file, spec_file : str
        A volume mesh (meshio formats or TetGen) and its spec (``core.mesh_spec``).

    Raises
    ------
    RequestError
        On an unknown model, a mesh without spec or a spec error (the message names it).
    """
    from . import models
    if mesh_file or spec_file:
        from .mesh_spec import MeshSpecError, load_mesh_with_spec
        if not (mesh_file and spec_file):
            raise RequestError("a user mesh needs both mesh_file and spec_file (units, fixed vertices, actuators, "
                               "markers: see examples/finger_mm.json)")
        try:
            return load_mesh_with_spec(mesh_file, spec_file)
        except (MeshSpecError, FileNotFoundError, OSError) as exc:
            raise RequestError(str(exc)) from None
    if model == 'finger':
        return models.build_tendon_finger(resolution=resolution or models.DEFAULT_FINGER_RESOLUTION)
    if model == 'pneumatic':
        return models.build_pneumatic_actuator(resolution=resolution or 1)
    if model == 'dea':
        return models.build_dea_crawler(resolution=resolution or 1)
    raise RequestError(f"unknown model {model!r}; expected finger, pneumatic or dea (or a mesh_file + spec_file)")


class RobotKinematics:
    """FK, IK and trajectories of one robot with warm starts (see module docstring).

    Parameters
    ----------
    mesh : SoftMesh
    marker : str
        The tracked marker (end effector).
    config_samples : int
        Configuration-space samples per actuator (``n ** n_a`` FK solves at start-up) that seed
        IK far from the previous solution; 0 = none (start from rest).
    settings : IKSettings, optional
    max_target_distance : float
        Targets farther than this from the rest mesh's bounding box are refused as absurd [m];
        0 = the box diagonal.
    progress : callable, optional
        Called with 1 per configuration sample (a tqdm ``update``).
    hold_rest_cables : bool
        A stretched cable at rest length goes taut (see module docstring).
    """

    def __init__(self, mesh: SoftMesh, marker: str = 'tip', config_samples: int = 5,
                 settings: Optional[IKSettings] = None, max_target_distance: float = 0.0,
                 progress: Optional[Callable] = None, hold_rest_cables: bool = False):
        if marker not in mesh.markers:
            raise RequestError(f"the mesh has no marker {marker!r}; markers: {sorted(mesh.markers) or 'none'}")
        if not mesh.actuators:
            raise RequestError("the mesh has no actuators: nothing to solve for")
        self.mesh = mesh
        self.marker = marker
        self.settings = settings or IKSettings()
        self.solver = ForwardSolver(mesh)
        self.solver.hold_rest_cables = hold_rest_cables
        self.lower = np.array([a.bounds[0] for a in mesh.actuators], float)
        self.upper = np.array([a.bounds[1] for a in mesh.actuators], float)
        self.names = [a.name for a in mesh.actuators]
        self.is_cable = np.array([mesh.groups[[g.name for g in mesh.groups].index(a.group)].kind == 'cable'
                                  for a in mesh.actuators])
        self.lengths = np.array([a.total_length for a in mesh.actuators], float)
        lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
        self.box = (lo, hi)
        self.max_target_distance = max_target_distance or float(np.linalg.norm(hi - lo))
        self.rest = self.solver.solve(np.minimum(np.ones(len(self.names)), self.upper), tol=self.settings.fk_tol)
        self.config_space = (sample_configuration_space(self.solver, config_samples, marker=marker, progress=progress)
                             if config_samples >= 2 else None)
        self.faces = mesh.boundary_faces()
        self.last: Optional[IKResult] = None   #: last commanded solution (targets, trajectories)
        #: a previous solution whose tip is this close to a new target seeds it (else the nearer
        #: of it and the nearest configuration sample) [m]
        self.warm_radius = 3e-3

    # --- checks -------------------------------------------------------------------------
    @property
    def all_cables(self) -> bool:
        return bool(np.all(self.is_cable))

    def check_actuation(self, actuation) -> np.ndarray:
        """The actuation as an array, or RequestError naming what is wrong with it."""
        a = np.asarray(actuation, float).ravel()
        if a.shape != (len(self.names),):
            raise RequestError(f"actuation has {a.size} values, expected {len(self.names)} ({', '.join(self.names)})")
        if not np.all(np.isfinite(a)):
            raise RequestError(f"actuation {a.tolist()} is not finite")
        bad = np.flatnonzero((a < self.lower - 1e-12) | (a > self.upper + 1e-12))
        if bad.size:
            i = int(bad[0])
            raise RequestError(f"actuation {self.names[i]} = {a[i]:.6g} is outside its range "
                               f"[{self.lower[i]:.6g}, {self.upper[i]:.6g}]")
        return a

    def check_target(self, point) -> np.ndarray:
        """A target (3,) in metres, or RequestError for NaN/inf or an absurdly distant point."""
        p = np.asarray(point, float).ravel()
        if p.shape != (3,):
            raise RequestError(f"target has {p.size} coordinates, expected 3")
        if not np.all(np.isfinite(p)):
            raise RequestError(f"target {p.tolist()} is not finite")
        lo, hi = self.box
        d = float(np.linalg.norm(p - np.clip(p, lo, hi)))
        if d > self.max_target_distance:
            raise RequestError(f"target ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m is {d:.3g} m from the robot, beyond "
                               f"max_target_distance {self.max_target_distance:.3g} m (units must be metres)")
        return p

    # --- conversions ---------------------------------------------------------------------
    def pulls(self, actuation) -> np.ndarray:
        """Cable pull from rest (m) per actuator, ``(1 - s) L`` (cables only; NaN otherwise)."""
        a = np.asarray(actuation, float)
        return np.where(self.is_cable, (1.0 - a) * self.lengths, np.nan)

    def actuation_from_pulls(self, pulls) -> np.ndarray:
        """Cable ratios s = 1 - pull / L for cable pulls (m)."""
        return 1.0 - np.asarray(pulls, float) / self.lengths

    def max_pulls(self) -> np.ndarray:
        """The largest pull of each cable the model allows (m): (1 - lower bound) L."""
        return np.where(self.is_cable, (1.0 - self.lower) * self.lengths, np.nan)

    # --- solves --------------------------------------------------------------------------
    def forward(self, actuation, warm: Optional[FKResult] = None) -> FKResult:
        """Forward kinematics (Algorithm 1) of a checked actuation, warm started if given."""
        a = self.check_actuation(actuation)
        x0, active0 = (warm.positions, warm.active) if warm is not None else (None, None)
        return self.solver.solve(a, x0=x0, active0=active0, tol=self.settings.fk_tol)

    def _start(self, target: np.ndarray, warm: Optional[IKResult]):
        """Seed for IK: the previous solution if within ``warm_radius``, else it or the nearest
        configuration sample, whichever is closer."""
        cands = []
        if warm is not None:
            d = float(np.linalg.norm(warm.reached[0] - target))
            if d <= self.warm_radius:    # continuity: a near previous solution wins over a sample
                return warm.actuation, warm.fk
            cands.append((d, warm.actuation, warm.fk))
        if self.config_space is not None:
            k = self.config_space.nearest(target)
            cands.append((float(np.linalg.norm(self.config_space.points[k] - target)),
                          self.config_space.actuations[k], self.config_space.results[k]))
        if not cands:
            return None, self.rest
        _, c, fk = min(cands, key=lambda t: t[0])
        return c, fk

    def inverse(self, target, initial=None, warm: Optional[IKResult] = None, lam: float = 0.0,
                i_max: int = 0) -> IKResult:
        """Inverse kinematics (Algorithm 2) of the tracked marker.

        Parameters
        ----------
        target : array_like, shape (3,)
            Marker target (m), checked by :meth:`check_target`.
        initial : array_like, optional
            Start actuation (checked); default: ``warm`` or the nearest sample (the closer).
        warm : IKResult, optional
            A previous solution to warm start from.
        lam, i_max : float, int
            Threshold (m) and iteration limit; 0 = the settings' values.

        Returns
        -------
        IKResult
            ``success`` False: the target is out of reach and ``reached`` is the nearest point
            found. A failed warm start is retried once from the nearest sample.
        """
        s = self.settings
        p = self.check_target(target)
        lam, i_max = check_tolerance(lam, s.lam), check_iterations(i_max, s.i_max)
        kw = dict(markers=(self.marker,), lam=lam, i_max=i_max, jacobian=s.jacobian, direction=s.direction,
                  fk_tol=s.fk_tol)
        if initial is not None and len(initial):
            c = self.check_actuation(initial)
            return solve_ik(self.solver, p, initial=c, initial_fk=self.forward(c), **kw)
        c, fk = self._start(p, warm)
        if c is not None:
            guess = self._predict(p, fk, lam)
            if guess is not None and guess.success:
                return guess
            if guess is not None and guess.error < np.linalg.norm(fk.marker(self.mesh, self.marker) - p):
                c, fk = guess.actuation, guess.fk
        r = solve_ik(self.solver, p, initial=c, initial_fk=fk, **kw)
        if not r.success and self.config_space is not None:
            k = self.config_space.nearest(p)
            retry = solve_ik(self.solver, p, initial=self.config_space.actuations[k],
                             initial_fk=self.config_space.results[k], **kw)
            r = retry if retry.error < r.error else r
        return r

    def _predict(self, target: np.ndarray, b: FKResult, lam: float) -> Optional[IKResult]:
        """One Gauss-Newton step from a solved shape ``b`` with its exact (implicit) Jacobian.

        For a target near the previous one (a streamed target, a service walk) the step lands
        within lambda, so a single FK solve (warm started along the sensitivity) replaces the
        line search's trials; its result is an exact FK solve like any IK iterate. None when
        the implicit Jacobian does not apply.
        """
        if self.settings.jacobian != 'implicit' or not self.solver.newton_applicable():
            return None
        dx = self.solver.sensitivity(b)
        m = self.mesh.markers[self.marker]
        K = dx[m]                                        # (3, n_a): d tip / d actuation
        r = b.positions[m] - target
        KtK = K.T @ K
        mu = 1e-3 * np.trace(KtK) / len(self.names) + 1e-12   # as solve_ik's Levenberg-Marquardt damping
        c = np.clip(b.actuation - np.linalg.solve(KtK + mu * np.eye(len(self.names)), K.T @ r), self.lower, self.upper)
        x0 = b.positions + dx @ (c - b.actuation)
        fk = self.solver.solve(c, x0=x0, active0=b.active, tol=self.settings.fk_tol)
        reached = fk.positions[m][None].copy()
        err = float(np.linalg.norm(reached[0] - target))
        return IKResult(actuation=c, reached=reached, target=target[None].copy(), error=err, iterations=1,
                        fk_solves=1, success=err <= lam, out_of_reach=err > lam, fk=fk,
                        history=np.array([float(np.linalg.norm(r)), err]))

    def waypoints(self, curve: str = '', n: int = 0, points=None) -> np.ndarray:
        """Waypoints (N, 3) of a built-in curve (``n`` samples, 0 = default) or checked points."""
        if n and not 2 <= n <= MAX_WAYPOINTS:      # a count out of bounds is refused whatever the mode
            raise RequestError(f"n_waypoints {n} must be 0 (default) or in 2-{MAX_WAYPOINTS}")
        if curve:
            if curve not in CURVES:
                raise RequestError(f"unknown curve {curve!r}; built-in curves: {', '.join(sorted(CURVES))}")
            if self.mesh.info.get('model') != 'tendon_finger':
                raise RequestError("the built-in curves lie in the finger's workspace; give waypoints for this robot")
            return CURVES[curve](n) if n else CURVES[curve]()
        P = np.asarray(points if points is not None else [], float).reshape(-1, 3)
        if len(P) == 0:
            raise RequestError("no curve name and no waypoints given")
        if len(P) > MAX_WAYPOINTS:
            raise RequestError(f"{len(P)} waypoints given; at most {MAX_WAYPOINTS}")
        for i, p in enumerate(P):
            try:
                self.check_target(p)
            except RequestError as exc:
                raise RequestError(f"waypoint {i}: {exc}") from None
        return P

    def follow(self, waypoints, lam: float = 0.0,
               on_waypoint: Optional[Callable[[int, IKResult], Optional[bool]]] = None) -> TrajectoryResult:
        """Algorithm 3 on checked waypoints; ``on_waypoint`` may return False to stop (cancel)."""
        s = self.settings
        return follow_trajectory(self.solver, waypoints, self.config_space, marker=self.marker,
                                 on_waypoint=on_waypoint, lam=check_tolerance(lam, s.lam), i_max=s.i_max,
                                 jacobian=s.jacobian, direction=s.direction, fk_tol=s.fk_tol)
