"""Hardware replay: one of the real robot's closed-loop experiments, set up for the twin.

From an authors' log (``<run>.csv``, ``shared/data/frog/hardware_runs/README.md``) and its
reference path (``<run>_path.csv``), through :mod:`frog_sim.core.hardware_runs` (which
drops the start-up burst, fits the decision period and estimates the tag offset):

- the path as waypoints (x, y of the path file, in the log's world frame);
- the start pose: the local fit of the tag pose at the first decision, heading = theta +
  tag offset (the robot's body heading; the tag is taken to sit at the centre of mass);
- the decision period ``P`` fitted to the action changes (the planner's period);
- the real trajectory from the first decision on (body pose) and its primitive per
  decision (the action shown 0.25 s after each ``T0 + k P``).

The real robot and the twin are scored by the same function, :func:`replay_metrics`
(:mod:`frog_twin.core.metrics`: distance and signed lateral offset against the polyline,
finish time by geometry), so the table compares like with like.

Tag offset: given, or estimated (:func:`~frog_sim.core.hardware_runs.estimate_tag_offset`,
travel direction under B) on the straight-line runs ``line*.csv`` beside the log (as
``frog-sim fidelity`` does), else on the run itself, else the README's -6 deg.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from frog_sim.core import hardware_runs as hr

from .metrics import finish_time, tracking_metrics
from frog_common.se2 import wrap_angle

#: A run counts in the pooled signed-lateral ratio when the real robot's |signed mean
#: lateral offset| exceeds this [m] (a ratio of offsets near 0 says nothing).
POOL_MIN_REAL_OFFSET_M = 0.01
#: Goal tolerance of the geometric finish (the planner's default goal_tolerance) [m].
GOAL_TOLERANCE_M = 0.03
#: Half-width of the finish line [m]: a run that crosses the normal at the path's end within
#: this distance of the end has reached the end and ends there, as the robot's experiments did
#: (the operator stopped them at the end of the path), even when it missed the goal tolerance;
#: the twin's planner stops there too (its ``goal_lateral_tolerance`` in a replay).
FINISH_LINE_HALF_WIDTH_M = 0.10
#: Seeds per replay unless given: enough to say where the real run falls in the twin's spread.
REPLAY_SEEDS = 5


@dataclass
class ReplaySetup:
    """What the twin needs to re-run one hardware experiment, and the real run to compare with.

    Attributes
    ----------
    name : str
        Run name (the log's stem).
    log_file, path_file : Path
    path : ndarray, shape (M, 2)
        Reference path [m] (log world frame).
    start_pose : tuple of float
        (x [m], y [m], body heading [rad], wrapped to [-pi, pi)) at the first decision.
    period : float
        Fitted decision period [s].
    tag_offset : float
        Body heading - tag theta [rad]; ``tag_offset_source`` says where it came from.
    time : ndarray, shape (T,)
        Real frames from the first decision on [s since the first decision].
    pose : ndarray, shape (T, 3)
        Real body pose (x, y, heading unwrapped) at those frames.
    decision_times : ndarray
        Real decisions [s since the first decision]; ``primitives`` their primitive names.
    fit : dict
        The decision fit (t0 in log time, period, residuals, number of changes, dropped burst rows).
    """

    name: str
    log_file: Path
    path_file: Path
    path: np.ndarray
    start_pose: tuple
    period: float
    tag_offset: float
    tag_offset_source: str
    time: np.ndarray
    pose: np.ndarray
    decision_times: np.ndarray
    primitives: list
    fit: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """The setup as plain numbers (JSON)."""
        x, y, h = self.start_pose
        return {"run": self.name, "log_file": str(self.log_file), "path_file": str(self.path_file),
                "start_x_m": x, "start_y_m": y, "start_heading_rad": h, "period_s": self.period,
                "tag_offset_rad": self.tag_offset, "tag_offset_deg": math.degrees(self.tag_offset),
                "tag_offset_source": self.tag_offset_source, "real_duration_s": float(self.time[-1]),
                "real_decisions": len(self.primitives), "decision_fit": self.fit}


def default_path_file(run_csv: Path | str) -> Path:
    """``<run>_path.csv`` beside ``<run>.csv``."""
    run_csv = Path(run_csv)
    return run_csv.with_name(f"{run_csv.stem}_path.csv")


def read_path_file(path_csv: Path | str) -> np.ndarray:
    """The reference path (M, 2) [m] of an authors' ``<run>_path.csv`` (rows ``x, y, heading, -``,
    no header) or of a waypoint CSV with a header naming ``x`` and ``y``.

    Raises
    ------
    FileNotFoundError, ValueError
        A missing file; fewer than 2 rows or a non-numeric value (the line is named).
    """
    path_csv = Path(path_csv)
    rows, ix, iy = [], 0, 1
    with open(path_csv, newline="") as fh:
        for lineno, row in enumerate(csv.reader(fh), start=1):
            if not row or all(not c.strip() for c in row):
                continue
            if lineno == 1:
                names = [c.strip().lower() for c in row]
                if "x" in names and "y" in names:
                    ix, iy = names.index("x"), names.index("y")
                    continue
            try:
                x, y = float(row[ix]), float(row[iy])
            except (IndexError, ValueError):
                raise ValueError(f"{path_csv}: line {lineno} {row} has no numeric x, y (m)") from None
            if not (math.isfinite(x) and math.isfinite(y)):
                raise ValueError(f"{path_csv}: line {lineno} has x={x}, y={y}; expected finite metres")
            rows.append((x, y))
    if len(rows) < 2:
        raise ValueError(f"{path_csv}: {len(rows)} path point(s); expected at least 2")
    return np.array(rows)


def write_waypoints(points, file: Path | str) -> Path:
    """Write ``points`` (M, 2) as the planner's waypoint CSV (header ``x,y``, metres)."""
    file = Path(file)
    with open(file, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x", "y"])
        for x, y in np.asarray(points, dtype=float):
            w.writerow([repr(float(x)), repr(float(y))])
    return file


def find_runs(folder: Path | str) -> list[tuple[Path, Path]]:
    """Every ``<run>.csv`` of ``folder`` with a matching ``<run>_path.csv``, sorted by name."""
    folder = Path(folder)
    out = []
    for f in sorted(folder.glob("*.csv")):
        if f.stem.endswith("_path"):
            continue
        p = default_path_file(f)
        if p.exists():
            out.append((f, p))
    return out


def tag_offset_for(log: hr.HardwareLog, folder: Path | str, tag_offset: float | None = None) -> tuple[float, str]:
    """(offset [rad], source) for ``log``: given; else estimated on ``folder``'s ``line*.csv``
    runs; else on ``log`` itself; else :data:`~frog_sim.core.hardware_runs.DEFAULT_TAG_OFFSET`."""
    if tag_offset is not None:
        return float(tag_offset), "given"
    lines = [f for f in sorted(Path(folder).glob("line*.csv")) if not f.stem.endswith("_path")]
    attempts = []
    if lines:
        attempts.append((lambda: [hr.read_hardware_log(f) for f in lines],
                         "estimated on " + ", ".join(f.stem for f in lines)))
    attempts.append((lambda: [log], f"estimated on {log.name}"))
    for logs, source in attempts:
        try:
            mean, sd, n = hr.estimate_tag_offset(logs())
        except ValueError:
            continue
        return mean, f"{source} (B decisions: {n}, sd {math.degrees(sd):.1f} deg)"
    return float(hr.DEFAULT_TAG_OFFSET), "default (no B decision to estimate it from)"


def replay_setup(run_csv: Path | str, path_csv: Path | str | None = None,
                 tag_offset: float | None = None) -> ReplaySetup:
    """Read one hardware run and its path into a :class:`ReplaySetup` (see module doc).

    Raises
    ------
    FileNotFoundError
        If the log or the path file is missing (the message names it).
    ValueError
        If the log is malformed or has too few action changes to fit the period.
    """
    run_csv = Path(run_csv)
    path_csv = Path(path_csv) if path_csv is not None else default_path_file(run_csv)
    for f, what in ((run_csv, "hardware log"), (path_csv, "reference path")):
        if not f.is_file():
            raise FileNotFoundError(f"{what} {f} does not exist")
    log = hr.read_hardware_log(run_csv)
    fit = hr.fit_decision_times(log)
    offset, source = tag_offset_for(log, run_csv.parent, tag_offset)
    t_start = max(fit.t0, float(log.time[0]))
    p0 = hr.local_pose(log, t_start, offset)
    heading0 = wrap_angle(p0.heading)
    keep = log.time >= t_start - 1e-9
    time = log.time[keep] - t_start
    pose = np.c_[log.x[keep], log.y[keep], log.theta[keep] + offset]
    decisions = fit.decision_times(t_end=float(log.time[-1]) - 0.25, t_start=t_start)
    prims = [hr.action_at(log, t + 0.25) for t in decisions]
    return ReplaySetup(name=run_csv.stem, log_file=run_csv, path_file=path_csv, path=read_path_file(path_csv),
                       start_pose=(p0.x, p0.y, heading0), period=float(fit.period), tag_offset=offset,
                       tag_offset_source=source, time=time, pose=pose, decision_times=decisions - t_start,
                       primitives=prims,
                       fit={"t0_log_s": fit.t0, "period_s": fit.period, "residual_rms_s": fit.residual_rms,
                            "residual_max_s": fit.residual_max, "changes": int(len(fit.change_times)),
                            "frame_interval_s": fit.frame_interval, "dropped_burst_rows": int(log.dropped_rows)})


def replay_metrics(time, positions, path, decision_times, primitives,
                   goal_tolerance: float = GOAL_TOLERANCE_M,
                   finish_line: float | None = FINISH_LINE_HALF_WIDTH_M) -> dict:
    """The replay table's figures of one trajectory, real or simulated (SI units).

    ``time`` [s] from the first decision, ``positions`` (N, 2) the body (centre of mass)
    positions, ``decision_times``/``primitives`` the decisions. The run ends at the
    geometric finish (:func:`~frog_twin.core.metrics.finish_time`: within ``goal_tolerance`` of
    the end, or across the finish line within ``finish_line`` of the end; None: anywhere) or
    at its last sample; the primitives counted are those decided before the end.

    Returns
    -------
    dict
        :func:`~frog_twin.core.metrics.tracking_metrics` (``mean_distance_m``,
        ``max_distance_m``, ``mean_signed_lateral_m``, ``completion_time_s``, ...) plus
        ``finished``, ``decisions`` and ``duration_s`` (time of the last sample).
    """
    t = np.asarray(time, dtype=float)
    xy = np.asarray(positions, dtype=float).reshape(-1, 2)
    goal = finish_time(t, xy, path, goal_tolerance, finish_line)
    end = goal if goal is not None else float(t[-1])
    prims = [p for td, p in zip(decision_times, primitives) if td < end - 1e-9]
    m = tracking_metrics(t, xy, path, goal_time=goal, primitives=prims)
    m["finished"] = goal is not None
    m["decisions"] = len(prims)
    m["duration_s"] = float(t[-1] - t[0])
    return m


def real_metrics(setup: ReplaySetup, goal_tolerance: float = GOAL_TOLERANCE_M,
                 finish_line: float | None = FINISH_LINE_HALF_WIDTH_M) -> dict:
    """:func:`replay_metrics` of the real robot's run."""
    return replay_metrics(setup.time, setup.pose[:, :2], setup.path, setup.decision_times, setup.primitives,
                          goal_tolerance, finish_line)


# ------------------------------------------------------------------ tables
def _fmt(v, scale=1.0, spec="7.2f", signed=False):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        align = spec[0] if spec[:1] in "<>^" else ">"            # the spec's alignment, right by default
        return format("-", f"{align}{int(spec.lstrip('<>^').split('.')[0])}")
    return format(v * scale, ("+" if signed else "") + spec)


def _hist(prims: dict) -> str:
    return " ".join(f"{k}{v}" for k, v in sorted(prims.items())) or "-"


def comparison_rows(name: str, real: dict, twins: list[dict]) -> list[dict]:
    """Rows (real, then one per twin run) of the replay table, as plain dicts (CSV/JSON)."""
    rows = []
    for who, m in [("real", real)] + [(f"twin s{m.get('seed', i)}", m) for i, m in enumerate(twins)]:
        rows.append({"run": name, "who": who, "finished": m["finished"], "time_s": m["completion_time_s"],
                     "mean_distance_cm": 100 * m["mean_distance_m"], "max_distance_cm": 100 * m["max_distance_m"],
                     "signed_lateral_cm": 100 * m["mean_signed_lateral_m"],
                     "mean_speed_cm_per_s": 100 * m["mean_speed_along_path_m_per_s"],
                     "decisions": m["decisions"], "primitives": _hist(m["primitives_used"])})
    return rows


def format_rows(rows: list[dict]) -> str:
    """The text table of :func:`comparison_rows` rows."""
    head = (f"{'run':8s} {'who':8s} {'finish':>6} {'time s':>7} {'mean cm':>8} {'max cm':>7} {'lateral cm':>10} "
            f"{'cm/s':>5} {'decis.':>6}  primitives")
    out = [head, "-" * len(head)]
    for r in rows:
        out.append(f"{r['run']:8s} {r['who']:8s} {'yes' if r['finished'] else 'no':>6} "
                   f"{_fmt(r['time_s'], 1, '7.1f')} {_fmt(r['mean_distance_cm'], 1, '8.2f')} "
                   f"{_fmt(r['max_distance_cm'], 1, '7.2f')} {_fmt(r['signed_lateral_cm'], 1, '10.2f', True)} "
                   f"{_fmt(r['mean_speed_cm_per_s'], 1, '5.2f')} {r['decisions']:6d}  {r['primitives']}")
    return "\n".join(out)


def pooled(results: list[dict], min_real_offset: float = POOL_MIN_REAL_OFFSET_M) -> dict:
    """Pooled twin/real ratios over runs (and seeds) of ``[{"run", "real", "twins": [...]}]``.

    - mean distance: (mean over runs of the seed-mean twin distance) / (mean over runs of the
      real distance); every run weighs the same, whatever its number of seeds;
      ``mean_distance_ratio_se`` is its standard error from the seed spread, as below;
    - signed lateral offset: over the runs whose real |signed mean lateral offset| exceeds
      ``min_real_offset``, sum of (seed-mean twin offset x sign of the real one) / sum of
      |real offset|: 1 = the twin is off to the same side by as much; < 0 = the other side.
      ``signed_lateral_ratio_se`` is its standard error from the twin's seed-to-seed spread,
      sqrt(sum of s_i^2 / n_i) / sum of |real offset| (s_i the sample sd over run i's n_i seeds;
      None below 2 seeds a run): the robot ran each path once, so that is all the spread known;
    - mean speed along the path: (mean over runs of the seed-mean twin speed) / (mean over runs
      of the real speed), ``mean_speed_ratio_twin_over_real``;
    - ``per_seed``: the same three ratios with each run's k-th seed alone (k up to the fewest
      seeds of a run), and ``spread``: their median, range and the real run's rank among them
      (:func:`seed_spread`; the real pooled figure is 1 by definition).
    """
    real_d = [r["real"]["mean_distance_m"] for r in results]
    twin_d = [float(np.mean([t["mean_distance_m"] for t in r["twins"]])) for r in results]
    sel = [r for r in results if abs(r["real"]["mean_signed_lateral_m"]) > min_real_offset]
    num = sum(float(np.mean([t["mean_signed_lateral_m"] for t in r["twins"]]))
              * math.copysign(1.0, r["real"]["mean_signed_lateral_m"]) for r in sel)
    den = sum(abs(r["real"]["mean_signed_lateral_m"]) for r in sel)
    se = _ratio_se([[t["mean_signed_lateral_m"] for t in r["twins"]] for r in sel], den)
    se_d = _ratio_se([[t["mean_distance_m"] for t in r["twins"]] for r in results], float(np.sum(real_d)))
    speed = "mean_speed_along_path_m_per_s"
    real_v = [r["real"][speed] for r in results]
    twin_v = [float(np.mean([t[speed] for t in r["twins"]])) for r in results]
    per_seed = {"mean_distance_ratio": [], "signed_lateral_ratio": [], "mean_speed_ratio": []}
    for k in range(min((len(r["twins"]) for r in results), default=0)):
        per_seed["mean_distance_ratio"].append(sum(r["twins"][k]["mean_distance_m"] for r in results)
                                               / float(np.sum(real_d)))
        if den > 0:
            per_seed["signed_lateral_ratio"].append(
                sum(r["twins"][k]["mean_signed_lateral_m"] * math.copysign(1.0, r["real"]["mean_signed_lateral_m"])
                    for r in sel) / den)
        per_seed["mean_speed_ratio"].append(sum(r["twins"][k][speed] for r in results) / float(np.sum(real_v)))
    return {"runs": len(results), "run_names": [r["run"] for r in results],
            "seeds_per_run": [len(r["twins"]) for r in results],
            "mean_distance_real_m": float(np.mean(real_d)) if real_d else None,
            "mean_distance_twin_m": float(np.mean(twin_d)) if twin_d else None,
            "mean_distance_ratio_twin_over_real": float(np.sum(twin_d) / np.sum(real_d)) if real_d else None,
            "mean_distance_ratio_se": se_d,
            "lateral_runs": [r["run"] for r in sel], "lateral_min_real_offset_m": min_real_offset,
            "signed_lateral_ratio_twin_over_real": num / den if den > 0 else None,
            "signed_lateral_ratio_se": se,
            "mean_speed_real_m_per_s": float(np.mean(real_v)) if real_v else None,
            "mean_speed_twin_m_per_s": float(np.mean(twin_v)) if twin_v else None,
            "mean_speed_ratio_twin_over_real": float(np.sum(twin_v) / np.sum(real_v)) if real_v else None,
            "per_seed": per_seed,
            "spread": {k: seed_spread(v, 1.0) for k, v in per_seed.items() if v}}


def seed_spread(values, real: float) -> dict:
    """The twin's seeds beside the real figure: median, range and the real one's rank.

    ``rank`` is 1 + the number of seeds below ``real`` (ties count as not below), out of
    ``of`` = seeds + 1: 1 = the real run lies at or below every seed, ``of`` = above all.

    Examples
    --------
    >>> seed_spread([1.0, 3.0, 2.0, 5.0, 4.0], 3.5)["rank"]
    4
    """
    v = np.asarray(list(values), dtype=float)
    if v.size == 0:
        raise ValueError("seed_spread needs at least one seed's value")
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max()),
            "rank": int(np.sum(v < real)) + 1, "of": int(v.size) + 1, "n": int(v.size)}


def run_kind(name: str) -> str:
    """The kind of path a run name says (``ellipse3`` -> ``ellipse``, ``sin4`` -> ``sin``)."""
    return name.rstrip("0123456789_-") or name


def pooled_groups(results: list[dict], min_real_offset: float = POOL_MIN_REAL_OFFSET_M) -> dict:
    """:func:`pooled` over all runs (``"all"``) and over the runs of each kind (:func:`run_kind`)."""
    out = {"all": pooled(results, min_real_offset)}
    for kind in sorted({run_kind(r["run"]) for r in results}):
        sub = [r for r in results if run_kind(r["run"]) == kind]
        if len(sub) < len(results):
            out[kind] = pooled(sub, min_real_offset)
    return out


def _ratio_se(seeds: list[list[float]], den: float) -> float | None:
    """Standard error of sum_i mean(seeds_i) / den from the seeds' sample spread."""
    if den <= 0 or not seeds or any(len(s) < 2 for s in seeds):
        return None
    return math.sqrt(sum(float(np.var(s, ddof=1)) / len(s) for s in seeds)) / den


def summary_rows(results: list[dict]) -> list[dict]:
    """One row per run for ``--replay-all``: the real figure beside the twin's seed mean, and for
    the mean distance, the signed lateral offset and the mean speed along the path the seeds'
    median, range and the real run's rank among them (:func:`seed_spread`)."""
    rows = []
    for r in results:
        tw = r["twins"]
        mean = lambda key: float(np.mean([t[key] for t in tw]))   # noqa: E731
        times = [t["completion_time_s"] for t in tw if t["completion_time_s"] is not None]
        real = r["real"]
        row = {
            "run": r["run"], "seeds": len(tw), "period_s": r["setup"]["period_s"],
            "real_mean_cm": 100 * real["mean_distance_m"], "twin_mean_cm": 100 * mean("mean_distance_m"),
            "mean_ratio": mean("mean_distance_m") / real["mean_distance_m"],
            "real_max_cm": 100 * real["max_distance_m"], "twin_max_cm": 100 * mean("max_distance_m"),
            "real_lateral_cm": 100 * real["mean_signed_lateral_m"],
            "twin_lateral_cm": 100 * mean("mean_signed_lateral_m"),
            "lateral_ratio": (mean("mean_signed_lateral_m") / real["mean_signed_lateral_m"]
                              if real["mean_signed_lateral_m"] != 0 else None),
            "real_time_s": real["completion_time_s"],
            "twin_time_s": float(np.mean(times)) if len(times) == len(tw) else None,
            "real_finished": real["finished"],
            "twin_finished": f"{sum(t['finished'] for t in tw)}/{len(tw)}",
            "real_speed_cm_per_s": 100 * real["mean_speed_along_path_m_per_s"],
            "twin_speed_cm_per_s": 100 * mean("mean_speed_along_path_m_per_s"),
            "speed_ratio": (mean("mean_speed_along_path_m_per_s") / real["mean_speed_along_path_m_per_s"]
                            if real["mean_speed_along_path_m_per_s"] > 0 else None),
            "real_primitives": _hist(real["primitives_used"]),
            "twin_primitives": _hist(_sum_hist([t["primitives_used"] for t in tw])),
        }
        for name, key, scale in (("mean", "mean_distance_m", 100), ("lateral", "mean_signed_lateral_m", 100),
                                 ("speed", "mean_speed_along_path_m_per_s", 100)):
            sp = seed_spread([scale * t[key] for t in tw], scale * real[key])
            row.update({f"twin_{name}_median": sp["median"], f"twin_{name}_min": sp["min"],
                        f"twin_{name}_max": sp["max"], f"real_{name}_rank": sp["rank"]})
        rows.append(row)
    return rows


def pooled_row(rows: list[dict], pool: dict, label: str = "pooled") -> dict:
    """The pooled figures as one more row of :func:`summary_rows` (CSV); other columns empty."""
    row = {k: None for k in rows[0]}
    row.update(run=label, seeds=sum(pool["seeds_per_run"]),
               real_mean_cm=100 * pool["mean_distance_real_m"], twin_mean_cm=100 * pool["mean_distance_twin_m"],
               mean_ratio=pool["mean_distance_ratio_twin_over_real"],
               lateral_ratio=pool["signed_lateral_ratio_twin_over_real"],
               real_speed_cm_per_s=100 * pool["mean_speed_real_m_per_s"],
               twin_speed_cm_per_s=100 * pool["mean_speed_twin_m_per_s"],
               speed_ratio=pool["mean_speed_ratio_twin_over_real"])
    return row


def _sum_hist(hists) -> dict:
    total: dict = {}
    for h in hists:
        for k, v in h.items():
            total[k] = total.get(k, 0) + v
    return total


def _pm(se: float | None, note: str = "") -> str:
    """`` +- se`` for a known standard error, else nothing."""
    return "" if se is None else f" +- {se:.2f}{note}"


def _spread_text(median, lo, hi, rank, of, spec=".2f") -> str:
    return f"{median:{spec}} [{lo:{spec}}, {hi:{spec}}] {rank}/{of}"


def format_summary(rows: list[dict], pool: dict, groups: dict | None = None) -> str:
    """Text of the ``--replay-all`` table: per run the real figure, the twin's seed median
    [range] and the real run's rank among the seeds (1 = below every seed), the seed-mean
    ratio; then the pooled ratios (all runs, and per kind of path in ``groups``) with the
    per-seed pooled ratios' median [range] and where 1 (the real) ranks among them."""
    head = (f"{'run':8s} {'P s':>5} {'seeds':>5} | {'mean cm: real':>13} {'twin med [range] rank':>24} {'ratio':>5} | "
            f"{'lateral cm: real':>16} {'twin med [range] rank':>26} {'ratio':>5} | "
            f"{'cm/s: real':>10} {'twin med [range] rank':>22} {'ratio':>5} | {'time s real/twin':>16} "
            f"{'finished real/twin':>18}  primitives real | twin")
    out = [head, "-" * len(head)]
    for r in rows:
        def spread(name, spec=".2f"):
            return _spread_text(r[f"twin_{name}_median"], r[f"twin_{name}_min"], r[f"twin_{name}_max"],
                                r[f"real_{name}_rank"], r["seeds"] + 1, spec)
        out.append(
            f"{r['run']:8s} {r['period_s']:5.3f} {r['seeds']:5d} | {r['real_mean_cm']:13.2f} "
            f"{spread('mean'):>24} {r['mean_ratio']:5.2f} | {r['real_lateral_cm']:+16.2f} "
            f"{spread('lateral', '+.2f'):>26} "
            f"{_fmt(r['lateral_ratio'], 1, '5.2f')} | {r['real_speed_cm_per_s']:10.2f} "
            f"{spread('speed'):>22} "
            f"{_fmt(r['speed_ratio'], 1, '5.2f')} | "
            f"{_fmt(r['real_time_s'], 1, '7.1f')}/{_fmt(r['twin_time_s'], 1, '<8.1f')} "
            f"{'yes' if r.get('real_finished', True) else 'no':>12}/{r['twin_finished']:<5}  "
            f"{r['real_primitives']} | {r['twin_primitives']}")
    out.append("-" * len(head))
    for label, p in ((("all", pool),) if groups is None else tuple(groups.items())):
        out.extend(format_pooled(p, label))
    return "\n".join(out)


def format_pooled(pool: dict, label: str = "all") -> list[str]:
    """Lines of one pooled block (see :func:`format_summary`)."""
    spread = pool.get("spread", {})

    def sp(key):
        x = spread.get(key)
        return "" if not x else (f"; per seed {x['median']:.2f} [{x['min']:.2f}, {x['max']:.2f}], "
                                 f"real (1) ranks {x['rank']}/{x['of']}")
    ratio = pool["mean_distance_ratio_twin_over_real"]
    lat = pool["signed_lateral_ratio_twin_over_real"]
    name = f"pooled {label} ({pool['runs']} runs)"
    return [f"{name}: mean distance real {_fmt(pool['mean_distance_real_m'], 100, '.2f')} cm, "
            f"twin {_fmt(pool['mean_distance_twin_m'], 100, '.2f')} cm, twin/real {_fmt(ratio, 1, '.2f')}"
            f"{_pm(pool.get('mean_distance_ratio_se'))}{sp('mean_distance_ratio')}",
            f"{'':{len(name)}}  signed lateral offset twin/real {_fmt(lat, 1, '.2f')}"
            f"{_pm(pool.get('signed_lateral_ratio_se'), ' (se, seed spread)')} over "
            f"{', '.join(pool['lateral_runs']) or 'no run'} (real |offset| > "
            f"{100 * pool['lateral_min_real_offset_m']:.0f} cm){sp('signed_lateral_ratio')}",
            f"{'':{len(name)}}  mean speed along the path real {_fmt(pool.get('mean_speed_real_m_per_s'), 100, '.2f')} "
            f"cm/s, twin {_fmt(pool.get('mean_speed_twin_m_per_s'), 100, '.2f')} cm/s, twin/real "
            f"{_fmt(pool.get('mean_speed_ratio_twin_over_real'), 1, '.2f')}{sp('mean_speed_ratio')}"]


# ------------------------------------------------------------------ plot
def plot_replay(setup: ReplaySetup, twins: list[tuple[str, np.ndarray]], real: dict, twin_metrics: list[dict],
                png: Path | str) -> None:
    """Real and simulated trajectories on the path, and the signed lateral offset over time.

    ``twins``: (label, array (N, 3) of t [s from the first decision], x, y) per twin run.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .metrics import signed_lateral_offset
    def split(t, m):
        """Indices up to the finish (the metrics' window) and after it."""
        end = m["completion_time_s"]
        n = len(t) if end is None else int(np.searchsorted(t, end + 1e-9))
        return slice(0, max(n, 1)), slice(max(n - 1, 0), len(t))

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(14, 6.5), gridspec_kw={"width_ratios": [1, 1.3]})
    p = setup.path * 100
    ax.plot(p[:, 0], p[:, 1], "k--", lw=1.3, label="reference path")
    shown, lat_shown = [p], [np.zeros(1)]
    lines = [("real robot", np.c_[setup.time, setup.pose[:, :2]], real, "tab:red")]
    colors = plt.cm.Blues(np.linspace(0.55, 0.95, max(len(twins), 1)))
    lines += [(label, tr, m, c) for (label, tr), m, c in zip(twins, twin_metrics, colors)]
    for label, tr, m, c in lines:
        before, after = split(tr[:, 0], m)
        ax.plot(tr[before, 1] * 100, tr[before, 2] * 100, color=c, lw=1.7,
                label=f"{label} (mean {100 * m['mean_distance_m']:.2f} cm)")
        ax.plot(tr[after, 1] * 100, tr[after, 2] * 100, ":", color=c, lw=1.0)
        shown.append(tr[before, 1:3] * 100)
        lat = signed_lateral_offset(tr[:, 1:3], setup.path) * 100
        ax2.plot(tr[before, 0], lat[before], color=c, lw=1.5, label=label)
        lat_shown.append(lat[before])
        ax2.plot(tr[after, 0], lat[after], ":", color=c, lw=1.0)
    x0, y0, h0 = setup.start_pose
    ax.annotate("", xy=(100 * x0 + 4 * math.cos(h0), 100 * y0 + 4 * math.sin(h0)), xytext=(100 * x0, 100 * y0),
                arrowprops={"arrowstyle": "->", "color": "k"})
    ax.plot(*p[-1], "r*", ms=13, label="goal")
    box = np.vstack(shown)
    lo, hi = box.min(axis=0) - 4.0, box.max(axis=0) + 4.0          # up to the finish, 4 cm margin
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set(xlabel="x [cm] (log frame)", ylabel="y [cm]",
           title=f"{setup.name}: real vs twin (P = {setup.period:.3f} s, start heading {math.degrees(h0):.0f} deg)")
    ax.legend(fontsize=8, title="dotted: after the finish", title_fontsize=7)
    for t in setup.decision_times:
        ax2.axvline(t, color="0.9", lw=0.6, zorder=0)
    ax2.axhline(0.0, color="k", lw=0.8)
    ends = [tr[split(tr[:, 0], m)[0], 0][-1] for _, tr, m, _ in lines]
    ax2.set_xlim(0.0, max(ends) + 2.0)
    lat_all = np.concatenate(lat_shown)
    ax2.set_ylim(lat_all.min() - 1.0, lat_all.max() + 1.0)
    ax2.set(xlabel="time since the first decision [s]", ylabel="signed lateral offset [cm] (+ left of the path)",
            title=f"mean signed offset: real {100 * real['mean_signed_lateral_m']:+.2f} cm, twin "
                  + ", ".join(f"{100 * m['mean_signed_lateral_m']:+.2f}" for m in twin_metrics) + " cm")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
