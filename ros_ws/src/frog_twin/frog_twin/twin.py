"""``frog-twin``: the digital twin, closed: camera -> tracker -> planner -> bridge -> robot -> simulator.

Each node is a separate process on an isolated ROS domain, all on the simulator's clock
(``/clock``), so the twin runs faster than real time with ``--real-time-factor`` and a slow
machine slows it down instead of breaking it::

    sim_node (world, /clock) -> camera_sim -> tracker_node -> planner_node -> bridge_node
        -> pty -> robot_emulator -> frog/limb_activation -> sim_node;   recorder; image_preview

Nothing in the loop reads the simulator's ground truth except the camera renderer and, after
the run, the metrics. Per path it writes into the run folder: ``<path>.png`` (true, tracked
and reference paths, distance, cost terms, vision error), ``<path>.mp4`` (the rendered
camera with the path, the tracked pose and the chosen primitive), ``<path>.json``, the MCAP
recording (``<path>/recording/``) and every node's log; then ``metrics.json`` and a table
beside the real robot's figures.

Examples
--------
frog-twin                                    # line, sine, ellipse -> runs/main_<time>/
frog-twin --path sine --real-time-factor 2 --seed 3
frog-twin --path line --no-vision            # ground-truth odometry instead of camera + tracker
frog-twin --path ellipse --direct            # planner -> simulator without the serial link
frog-twin --path line --depth 2 --w-heading 150 --duration 60

Faults: inject them at simulated times after the planner's start; a crashed node is
restarted with back-off; the run ends completed, stopped cleanly (with the reason) or failed, and
says how many limb firings were made on stale state and what the recorder lost (both must be 0):

frog-twin --path line --faults "camera_freeze@4+5;kill:tracker_node@12"
frog-twin --path sine --faults "unplug@5+2;sigstop:planner_node@9+4;emergency@14"
frog-twin --fault-campaign                          # every fault x 3 moments x 3 seeds x line, sine
frog-twin --fault-campaign --fault-classes --campaign-paths line   # reduced: one run per fault class
frog-twin --fault-campaign --out runs/faults --campaign-shard 1/2 &  # two processes share one campaign
frog-twin --fault-campaign --out runs/faults --campaign-shard 2/2    # (4+ cores); rerun either to resume

Hardware replay: re-run one of the real robot's closed-loop experiments (the authors' logs,
shared/data/frog/hardware_runs/) from its logged start pose (tag offset applied), at its
fitted decision period, along its reference path as waypoints; the real and the twin's
trajectories overlaid on the path (<run>_replay.png), a table real vs twin (mean / max
distance, signed mean lateral offset + left of the path, time, primitives, speed) and a JSON.
--paper-cost runs the paper's planner in the robot's own loop (the authors' code: their library
search, decisions on 0.63 s mean states, raw frame-difference tracking), --ideal-loop the same cost
on the project's loop; otherwise the project's settings:

frog-twin --replay ../shared/data/frog/hardware_runs/sin1.csv --paper-cost          # whole chain + MP4
frog-twin --replay-all ../shared/data/frog/hardware_runs --paper-cost --ideal-loop --seeds 3
frog-twin --replay RUN.csv --path RUN_path.csv --no-vision --direct --duration 20   # fast, simulator only
frog-twin --replay-all ../shared/data/frog/hardware_runs --no-vision --direct --paper-cost
frog-twin --replay-all DIR --no-vision --direct --seeds 3 --out runs/replay3        # pooled over seeds
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

from frog_planner.core.settings import PathSettings, PlannerSettings, add_arguments, from_arguments
from frog_common.state_age import MAX_STATE_AGE_S
from soft_robot_common.graph import GraphError, load_graph
from soft_robot_common.graph_watch import GraphWatch
from soft_robot_common.processes import NodeProcess
from soft_robot_common.tool_signals import stop_on_signals

from frog_twin.core import twin_report
from frog_twin.core.cases import PATH_NAMES, path_start_pose, placed_path_settings
from frog_twin.core.replay import REPLAY_SEEDS
from frog_twin.core.faults import FaultSpecError, check_against_graph, fault_report, parse_faults
# the realism defaults of the twin (each switchable; see --help)
from frog_twin.core.realism import (HARDWARE_PERIOD_S, KICK_STRENGTH_SD, LIMB_STRENGTH_SD, YAW_DISTURBANCE_SD,
                                    YAW_DISTURBANCE_TAU_S)
from frog_twin.core.state_audit import complete_intervals
from frog_twin.core.twin_recording import (read_pulse_ages, read_twin_recording, readable_files, recorded_stamps,
                                            recordings, run_files)
from frog_twin.fault_injection import CHECKED_TOPICS, FaultInjector, RunObserver
from frog_twin.supervised_run import SupervisedGraph, graph_liveness, parse_budgets, run_domain

def repo_root() -> Path:
    """The repository (for runs/); the current folder when installed elsewhere."""
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / "dev").is_file() and (parent / "ros_ws").is_dir():
            return parent
    return Path.cwd()


def ensure_library(path: Path, states: int, horizon: float = 3.0) -> Path:
    """Generate the default motion library on first use (frog-library, with progress).

    A library made with another robot model than today's defaults (an older calibration)
    is regenerated: the planner would otherwise plan with transitions the twin's frog no
    longer has.
    """
    if path.exists():
        stale = _library_model_differs(path)
        if not stale:
            return path
        print(f"the default motion library {path} was made with another frog model ({stale}); regenerating",
              flush=True)
        path.replace(path.with_suffix(".old.npz"))
    print(f"generating the default motion library on first use: {states} states x 9 primitives -> {path}",
          flush=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    proc = NodeProcess(["frog-library", "generate", "--states", str(states), "--horizon", str(horizon),
                        "--out", str(path)], dict(os.environ), path.with_suffix(".log"), "library")
    while proc.running():
        time.sleep(2.0)
    if proc.proc.returncode != 0 or not path.exists():
        raise RuntimeError(f"library generation failed:\n{proc.log_text()[-3000:]}")
    return path


def _library_model_differs(path: Path) -> str:
    """'' if the library's robot model is today's default, else the first differing parameter."""
    from frog_sim.core.model_parameters import FrogParameters
    from frog_common.motion_library_file import load_motion_library
    try:
        robot = load_motion_library(path).metadata.get("robot", {})
    except Exception as exc:      # unreadable: regenerate rather than fail the run
        return f"unreadable: {exc}"
    for name, value in FrogParameters().as_dict().items():
        if robot.get(name) != value:
            return f"{name} = {robot.get(name)!r}, now {value!r}"
    return ""


class PlannerWatch(GraphWatch):
    """The run's graph watch: starts the planner and follows its status and the odometry."""

    def __init__(self, domain):
        from nav_msgs.msg import Odometry
        from soft_robot_interfaces.msg import PlannerStatus
        from std_srvs.srv import Trigger
        super().__init__(domain, "twin_watch")
        self.Trigger, self.Status = Trigger, PlannerStatus
        self.last = None
        self.odom_count = 0
        self.node.create_subscription(PlannerStatus, "/frog/planner/status", self._on_status, 10)
        self.node.create_subscription(Odometry, "/frog/odom", self._on_odom, 10)
        self.start_client = self.node.create_client(Trigger, "/planner_node/start")

    def _on_status(self, msg) -> None:
        self.last = msg

    def _on_odom(self, msg) -> None:
        self.odom_count += 1

    def publish_stop(self) -> None:
        """The run's one stop (frog/stop): the planner stops deciding, the bridge cancels every pulse."""
        from std_msgs.msg import Empty
        if not hasattr(self, "stop_pub"):
            self.stop_pub = self.node.create_publisher(Empty, "/frog/stop", 10)
            self.spin(0.3)
        self.stop_pub.publish(Empty())

    def spin(self, seconds: float) -> None:
        self.spin_for(seconds)

    def wait(self, predicate, timeout: float, what: str, procs=()) -> None:
        self.spin_until(predicate, timeout, what, procs)

    def start_planner(self) -> str:
        self.wait(self.start_client.service_is_ready, 60, "planner_node/start service")
        reply = self.call(self.start_client, self.Trigger.Request(), timeout=30)
        if not reply.success:
            raise RuntimeError(f"planner_node refused to start: {reply.message}")
        return reply.message

    @property
    def state(self):
        return None if self.last is None else self.last.state


#: The frog's node graph (package data; also installed as share/frog_twin/config/frog_graph.yaml).
GRAPH_FILE = Path(__file__).resolve().parent / "config" / "frog_graph.yaml"
VISION_NODES = ("camera_sim", "tracker_node", "image_preview")
#: not restarted after a crash: the simulated world (a new one would start from the initial pose)
#: and the robot; the run stops instead
ESSENTIAL_NODES = ("sim_node", "robot_emulator")
#: The planner starts only once rollout_node serves (transitions simulator): a run started before
#: made every decision a library fallback while numba compiled the rollouts (about a minute, once).
ROLLOUTS_READY_S = 600.0
#: topics every twin run has (the bridge's are absent with --direct): the recorder's subscriptions to them
PLANNER_TOPICS = ("/frog/primitive", "/frog/planner/status")
SERIAL_NODES = ("robot_emulator", "bridge_node")


def transitions_choice(args) -> tuple[dict, tuple]:
    """planner_node's ``transitions`` override and the nodes to leave out: rollout_node runs only
    when the planner asks the simulator (``--transitions simulator``)."""
    transitions = getattr(args, "transitions", "library") or "library"
    return {"transitions": transitions}, (() if transitions == "simulator" else ("rollout_node",))


def twin_graph(args, name: str, out: Path, path_settings, settings, start_pose, graph_file=GRAPH_FILE):
    """The twin's processes for one run: the graph file's sim mode with this run's values."""
    x0, y0, h0 = start_pose
    tag_yaw = float(getattr(args, "tag_yaw", 0.0))      # the tag as mounted (a hardware replay sets it)
    overrides = {
        "recorder": {"output_dir": str(out / "recording"), "file_prefix": name},
        "sim_node": {"real_time_factor": args.real_time_factor, "initial_x": x0, "initial_y": y0,
                     "initial_heading": h0, "execute_primitives": args.direct,
                     "odom_alias_topic": "frog/odom" if args.no_vision else "",
                     "odom_alias_yaw": tag_yaw if args.no_vision else 0.0,
                     "limb_strength_sd": args.limb_strength_sd, "kick_strength_sd": args.kick_strength_sd,
                     "yaw_disturbance_sd": args.yaw_disturbance_sd, "yaw_disturbance_tau_s": args.yaw_disturbance_tau,
                     "seed": args.seed},
        "planner_node": {"library_file": str(args.library), **settings.as_dict(), **path_settings.as_dict(),
                         **transitions_choice(args)[0]},
    }
    if not args.no_vision:
        overrides["camera_sim"] = {"seed": args.seed, "tag_yaw": tag_yaw}
        # best effort in the twin: a reliable 0.9 MB-frame reader beside the tracker slows the
        # camera's delivery to the tracker on 2 cores (12.5 instead of > 15 Hz tracked); the
        # preview only needs 5 of the 30 frames a second
        overrides["image_preview"] = {"rate_hz": args.video_rate,
                                      "qos_overrides./camera/image_raw.subscription.reliability": "best_effort"}
    if not args.direct:
        overrides["robot_emulator"] = {"link_path": str(out / "robot_tty"), "seed": args.seed,
                                       "command_log": str(out / "robot_commands.csv")}
        overrides["bridge_node"] = {"port": str(out / "robot_tty")}
    if args.no_vision:          # the simulator's odometry is its own measurement: no tracker state to pair
        overrides["planner_node"]["state_topic"] = ""
    exclude = (*(VISION_NODES if args.no_vision else ()), *(SERIAL_NODES if args.direct else ()),
               *transitions_choice(args)[1])
    for node, values in getattr(args, "node_params", {}).items():     # --node-param, last
        overrides.setdefault(node, {}).update(values)
    return load_graph(graph_file, "sim", overrides, exclude=exclude)


def _restarter(node, domain, out: Path, watch):
    """start(label) for the supervisor: the node's command line again; a planner resumes where it was."""
    def start(label: str) -> NodeProcess:
        if node.name == "planner_node" and watch.last is not None:
            # a restarted planner must not start the path over, nor wait for ~/start again
            node.parameters.update(autostart=True, initial_progress=float(min(1.0, max(0.0,
                                                                                   watch.last.path_progress))))
        return node.start(domain.env, out, label)
    return start


def parse_node_params(items) -> dict:
    """``["tracker_node:frozen_frames=5", ...]`` -> ``{"tracker_node": {"frozen_frames": 5}}`` (YAML values)."""
    import yaml
    out: dict = {}
    for item in items:
        node, colon, rest = item.partition(":")
        name, eq, value = rest.partition("=")
        if not (colon and eq and node and name):
            raise ValueError(f"--node-param {item!r}: expected NODE:NAME=VALUE, e.g. tracker_node:frozen_frames=5")
        try:
            out.setdefault(node, {})[name] = yaml.safe_load(value)
        except yaml.YAMLError as exc:
            raise ValueError(f"--node-param {item!r}: value {value!r} is not YAML ({exc})") from None
    return out


def twin_report_faults(rep: dict) -> str:
    """A few lines on a run under faults: outcome, what the injector did, recovery, the two zero counts."""
    lines = [f"  outcome: {rep['outcome']}" + (f" ({rep['stop_reason']})" if rep["stop_reason"] else "")]
    lines += [f"    t = {t:6.1f} s  {what}" for t, what in rep["actions"]]
    for pf in rep["per_fault"]:
        rec = "not recovered" if pf["recovery_s"] is None else f"recovered in {pf['recovery_s']:.1f} s"
        lines.append(f"  {pf['fault']}: {rec}")
    ages = rep["pulse_ages"]
    oldest = ages["published"]["max"] if ages["published"] else float("nan")
    lines.append(f"  pulses on a state older than {rep['state_bound_s']:g} s: {len(rep['stale_pulses'])} of "
                 f"{ages['pulses']} (oldest {oldest:.3f} s); messages lost by the recorder while up: "
                 f"{rep['recorder_lost']}")
    if rep["injector_failures"]:
        lines.append("  injector actions refused: " + "; ".join(rep["injector_failures"]))
    return "\n".join(lines)


def run_path(args, name: str, out: Path, path_settings=None, start_pose=None, settings=None, duration=None,
             faults=()) -> dict:
    """One closed-loop run of the twin on path ``name``; returns its metrics (see :func:`run_twin`)."""
    return run_twin(args, name, out, path_settings, start_pose, settings, duration, faults)[1]


def run_twin(args, name: str, out: Path, path_settings=None, start_pose=None, settings=None, duration=None,
             faults=()):
    """One closed-loop run of the twin; returns (its recording, its metrics).

    By default the path is the paper's path ``name`` placed in the camera's view, the start
    is on it (``--lateral-offset``) and the planner's settings are ``args.settings``;
    ``path_settings`` (a :class:`PathSettings`), ``start_pose`` (x, y, heading) and
    ``settings`` (a :class:`PlannerSettings`) replace them (the hardware replay), and
    ``duration`` [s simulated] replaces ``args.duration``. ``faults``
    (:class:`frog_twin.core.faults.Fault`) are injected during the run; a crashed node is
    restarted with back-off (the world, sim_node, and the robot are not: the run stops), and
    the graph file's liveness contracts restart a deaf node or stop the run with a reason.
    """
    out.mkdir(parents=True, exist_ok=True)
    earlier = recordings(out / "recording")
    if earlier:
        print(f"  {name}: {len(earlier)} earlier recording(s) in {out / 'recording'} are left as they are and "
              f"not read", flush=True)
    path_settings = path_settings or placed_path_settings(args.path_settings, name)
    settings = settings or args.settings
    x0, y0, h0 = start_pose or path_start_pose(path_settings, args.lateral_offset)
    graph = twin_graph(args, name, out, path_settings, settings, (x0, y0, h0))
    if faults:
        check_against_graph(faults, graph.names())
        if any(f.kind == "unplug" for f in faults):     # the injector plugs back in (~/replug)
            graph["robot_emulator"].parameters["unplug_duration_s"] = 0.0
    liveness = graph_liveness(GRAPH_FILE, "sim", graph.names(), getattr(args, "budgets", None))
    domain = run_domain(getattr(args, "domain", None))
    watch = PlannerWatch(domain)
    run = SupervisedGraph(graph, liveness, domain.env, out, lambda node: _restarter(node, domain, out, watch),
                          lambda: observer.sim_now, essential=ESSENTIAL_NODES,
                          log=lambda s: print("  " + s, flush=True),
                          on_restart=lambda n: observer.node_restarted(n))
    observer = RunObserver(watch.node, run.monitor)
    injector = None
    try:
        sim_start = _start_twin(run, watch, observer, graph)
        injector = FaultInjector(watch.node, faults, run.supervisor, log=lambda s: print("  " + s, flush=True))
        limit = duration or args.duration
        print(f"  {name}: following (at most {limit:.0f} s simulated, real-time factor {args.real_time_factor:g})"
              + (f"; faults: {'; '.join(f.label() for f in faults)}" if faults else ""), flush=True)
        stop_reason, goal, wall = _follow(run, watch, observer, injector, sim_start, limit, args.real_time_factor,
                                          name)
        # the run ends here (the time limit exactly): the world runs on while the nodes stop
        run_end = sim_start + limit if stop_reason and stop_reason.startswith("time limit") else observer.sim_now
        if stop_reason and not stop_reason.startswith("time limit"):
            print(f"  {name}: stopping: {stop_reason}", flush=True)
            watch.publish_stop()
        watch.spin(1.0)
        observer.close_recorder_interval("recorder" in run.supervisor.names() and not run.supervisor.down("recorder"))
    finally:
        if injector is not None:
            injector.finish()
        run.supervisor.stop_all()
        watch.close()
        domain.release()
    files = run_files(out / "recording", earlier)     # not an earlier run's files in the same folder
    if not files:
        raise RuntimeError(f"no recording in {out / 'recording'}; see {out}/recorder.log")
    files = readable_files(files, out / "recovered")    # a killed recorder's file, recovered
    rec = read_twin_recording(files)
    metrics = twin_report.run_metrics(rec, name, end_time=run_end)
    metrics.update(wall_time_s=wall, goal_reached=goal, stop_reason=None if goal else stop_reason,
                   supervision=run.supervisor.summary(), liveness_verdicts=run.verdicts,
                   unclean_stops=run.supervisor.unclean_stops())
    # the design's bound, not the run's: a run that raises its nodes' bound is audited against it too
    ages = read_pulse_ages(files, MAX_STATE_AGE_S)
    # the recorded poses judge a pulse only where the recording is complete
    ages.complete = complete_intervals(observer.recorder_up, observer.pose_gaps())
    metrics["pulse_ages"] = ages.summary()
    metrics["stale_pulses"] = ages.stale()
    if faults:
        metrics["faults"] = fault_report(faults, observer, sim_start, injector,
                                         recorded_stamps(files, CHECKED_TOPICS), ages, goal, stop_reason,
                                         metrics["unclean_stops"])
    metrics["recording"] = [str(f) for f in files]
    metrics["settings"] = {"planner": settings.as_dict(), "path": path_settings.as_dict(),
                           "start_pose": [x0, y0, h0], "real_time_factor": args.real_time_factor,
                           "seed": args.seed, "vision": not args.no_vision, "serial": not args.direct,
                           "limb_strength_sd": args.limb_strength_sd, "kick_strength_sd": args.kick_strength_sd,
                           "yaw_disturbance_sd": args.yaw_disturbance_sd,
                           "yaw_disturbance_tau_s": args.yaw_disturbance_tau,
                           "liveness_budgets": dataclasses.asdict(liveness.budgets)}
    metrics["feasibility"] = twin_report.feasibility(args.library, settings, rec.path, path_settings.goal_tolerance)
    w = settings.weights
    twin_report.plot_run(rec, metrics, out.parent / f"{name}.png", weights=(w.distance, w.heading, w.progress))
    metrics["plot"] = str(out.parent / f"{name}.png")
    project = None if args.no_vision else _projector(rec)
    frames = twin_report.write_video(rec, out.parent / f"{name}.mp4", project)
    metrics["video"] = str(out.parent / f"{name}.mp4") if frames else None
    (out.parent / f"{name}.json").write_text(json.dumps(metrics, indent=1, default=float) + "\n")
    return rec, metrics


def _start_twin(run: SupervisedGraph, watch, observer, graph) -> float:
    """Start the graph and wait until the loop runs; the simulated time the planner started at."""
    def device(node):
        if node.name == "robot_emulator":
            link = Path(node.parameters["link_path"])
            watch.wait(lambda: link.exists(), 60, "the robot emulator's serial device", run.supervisor.processes())
    run.start(device)
    procs = run.supervisor.processes()
    watch.wait(lambda: watch.odom_count >= 5, 120, "odometry on /frog/odom (camera + tracker running)", procs)
    if "rollout_node" in run.supervisor.names():       # compiled on first use: minutes on a fresh clone
        watch.wait(lambda: run.monitor.ready("rollout_node"), ROLLOUTS_READY_S,
                   "rollout_node ready (the rollouts are compiled on first use)", procs)
    # the metrics start at the planner's first decision: the recorder must hear it
    recorded = ("/frog/sim/odom", *PLANNER_TOPICS)     # (no bridge topics with --direct)
    watch.wait(lambda: watch.subscribed("recorder", recorded), 60,
               f"the recorder subscribed to {', '.join(recorded)}", procs)
    watch.wait(lambda: observer.sim_now is not None, 30, "/clock", procs)
    # the idle planner publishes I every period: once the watch has one, it hears every decision
    watch.wait(lambda: observer.obs.decisions, 60, "the idle planner's primitive I on /frog/primitive", procs)
    watch.start_planner()
    run.monitor.restart(time.monotonic(), observer.sim_now)      # the start-up does not count as silence
    return observer.sim_now


def _follow(run: SupervisedGraph, watch, observer, injector, sim_start: float, limit: float, rtf: float,
            name: str):
    """Poll the run until it ends: (stop reason or None, goal reached, wall seconds)."""
    t_start = time.monotonic()

    def verdict(v):
        if v.node == "recorder" and v.action == "restart":     # what it missed is not a loss while up
            observer.recorder_went_deaf(run.edge_topic(v.rule), v.since_sim)

    while True:
        watch.spin(0.2)
        injector.tick(observer.sim_now - sim_start, observer.sim_now)
        held = set(injector.held) | ({"sim_node"} if injector.clock_paused else set())
        reason = run.poll(held, verdict)
        if reason:
            return reason, False, time.monotonic() - t_start
        recorder_up = "recorder" in run.supervisor.names() and not run.supervisor.down("recorder")
        observer.watch_recorder(recorder_up and watch.subscribed("recorder", PLANNER_TOPICS),
                                ready=run.monitor.ready("recorder"))
        observer.watch_recorder_subscriptions()
        if watch.state == watch.Status.STATE_GOAL_REACHED:
            return None, True, time.monotonic() - t_start
        if observer.sim_now - sim_start > limit:
            return f"time limit ({limit:g} s simulated)", False, time.monotonic() - t_start
        if time.monotonic() - t_start > 10 * limit / rtf + 60:
            raise RuntimeError(f"{name}: the twin made too little progress in wall time (machine overloaded?)")


def _projector(rec):
    """tank points -> preview pixels with the simulated camera's model and pose (frog_vision core)."""
    if rec.camera_info is None or not rec.preview:
        return None
    import cv2
    import numpy as np
    from frog_vision.core.camera_model import CameraModel
    from frog_vision.core.tank_calibration import CameraPose
    info = rec.camera_info
    camera = CameraModel.from_camera_info({"width": info.width, "height": info.height, "k": list(info.k),
                                           "d": list(info.d), "distortion_model": info.distortion_model})
    pose = CameraPose.overhead(0.8)   # camera_sim's default pose (frog_vision.nodes.common)
    h = cv2.imdecode(np.frombuffer(rec.preview[0][1], np.uint8), cv2.IMREAD_COLOR).shape[0]
    scale = h / info.height
    return lambda pts: pose.project(camera, pts) * scale


def _prepare_real(ap, args):
    """Check the real mode's options and read the tag offset file; an exit code to return, or None."""
    args.mode = "real"
    if args.replay is not None or args.replay_all is not None or args.no_vision or args.direct:
        ap.error("--robot-port / --camera (the real robot) go without --replay, --replay-all, --no-vision, --direct")
    if not args.print_graph and (args.robot_port is None or args.camera is None):
        ap.error("the real robot needs both --robot-port and --camera")
    for f, opt in ((args.camera_info, "--camera-info"), (args.tank_calibration, "--tank-calibration"),
                   (args.tag_offset, "--tag-offset")):
        if f is not None and not f.is_file():
            ap.error(f"{opt} {f} does not exist")
    if not (args.camera_fps > 0 and args.start_tolerance > 0):
        ap.error("--camera-fps and --start-tolerance must be > 0")
    try:
        args.budgets = parse_budgets(args.budget)
        if args.tag_lost_timeout is not None:
            args.budgets["tag_lost_after_s"] = args.tag_lost_timeout
        graph_liveness(GRAPH_FILE, "real", (), args.budgets)        # checks names, values and their order
    except ValueError as exc:
        ap.error(str(exc))
    args.tag_offset_params = None
    if args.tag_offset is not None:
        from frog_vision.core.tag_offset import read_tag_offset
        try:
            args.tag_offset_params = read_tag_offset(args.tag_offset)
        except ValueError as exc:
            ap.error(str(exc))
    elif not args.print_graph:
        print("frog-twin: warning: no --tag-offset file: the tracker uses its default tag-to-body offset (the "
              "simulator's centre of mass, not a measurement); measure it with 'frog-vision tag-offset'",
              file=sys.stderr, flush=True)
    if args.path == "all":
        ap.error("the real robot follows one path: --path line, sine or ellipse")
    return None


def main_real(ap, args) -> int:
    """The real robot: one path, pre-flight, run, stop, report."""
    from frog_twin.real import PreflightError, run_real
    args.path = args.path or "line"
    if args.path not in PATH_NAMES:
        ap.error(f"--path {args.path!r}: expected one of {', '.join(PATH_NAMES)}")
    if args.duration is None:
        args.duration = 150.0
    try:
        args.settings = from_arguments(PlannerSettings, args)
        args.path_settings = from_arguments(PathSettings, args, path_type="line")
    except ValueError as exc:
        ap.error(str(exc))
    if args.library is None:
        args.library = ensure_library(repo_root() / "runs" / "library" / "frog_default.npz", args.library_states)
    elif not args.library.exists():
        ap.error(f"library {args.library} does not exist (frog-library generate --out ...)")
    out = args.out or repo_root() / "runs" / time.strftime("real_%Y%m%d_%H%M%S")
    print(f"real robot: {args.path} path, port {args.robot_port}, camera {args.camera} -> {out}", flush=True)
    try:
        m = run_real(args, args.path, out / args.path, placed_path_settings(args.path_settings, args.path),
                     args.settings)
    except PreflightError as exc:
        print(f"frog-twin: {exc}", file=sys.stderr)
        return 2
    except (GraphError, OSError, ValueError) as exc:
        print(f"frog-twin: error: {exc}", file=sys.stderr)
        return 2
    (out / "metrics.json").write_text(json.dumps([m], indent=1, default=float) + "\n")
    print()
    print(twin_report.summary_table([m]))
    print(f"stopped: {m['stop_reason']}; plots, video, metrics: {out}")
    return 0


def print_graph(args) -> int:
    """``--print-graph``: the mode's nodes as ``ros2 run`` lines, with this run's values."""
    mode = args.mode or "sim"
    args.path = args.path if args.path in PATH_NAMES else "line"
    try:
        args.settings = from_arguments(PlannerSettings, args)
        args.path_settings = from_arguments(PathSettings, args, path_type="line")
    except ValueError as exc:
        print(f"frog-twin: error: {exc}", file=sys.stderr)
        return 2
    out = args.out or Path("runs") / ("main" if mode == "sim" else "real")
    args.library = args.library or Path("runs") / "library" / "frog_default.npz"
    path_settings = placed_path_settings(args.path_settings, args.path)
    try:
        if mode == "sim":
            graph = twin_graph(args, args.path, out / args.path, path_settings, args.settings,
                               path_start_pose(path_settings, args.lateral_offset))
        else:
            from frog_twin.real import real_graph
            graph = real_graph(args, args.path, out / args.path, path_settings, args.settings)
    except GraphError as exc:
        print(f"frog-twin: error: {exc}", file=sys.stderr)
        return 2
    print(f"# {graph.robot} graph, {mode} mode, from {GRAPH_FILE}; run each line in its own terminal")
    print(f"# (every node also reads its section with: --ros-args --params-file {GRAPH_FILE})")
    for line in graph.ros2_run_lines():
        print(line)
    print("# planner_node then waits for: ros2 service call /planner_node/start std_srvs/srv/Trigger"
          + ("" if mode == "sim" else "   (stop: ros2 topic pub --once /frog/stop std_msgs/msg/Empty)"))
    return 0


def main(argv=None) -> int:
    """``frog-twin``; SIGTERM and SIGHUP stop it as Ctrl-C does, the nodes it started first."""
    from soft_robot_common.graph_watch import exit_status
    restore = stop_on_signals()
    try:
        code = _main(argv)
    except KeyboardInterrupt as exc:
        print(f"frog-twin: stopped ({exc.args[0] if exc.args else 'Ctrl-C'}); its nodes are stopped",
              file=sys.stderr, flush=True)
        code = 130
    finally:
        restore()
    return exit_status(code)


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="frog-twin", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--path", default=None,
                    help=f"path(s) to follow: {', '.join(PATH_NAMES)} or all (default); with --replay the run's "
                         "reference path CSV (default: <run>_path.csv beside RUN.csv)")
    rg = ap.add_argument_group("hardware replay")
    what = rg.add_mutually_exclusive_group()
    what.add_argument("--replay", type=Path, metavar="RUN.csv",
                      help="re-run this hardware log (authors' format) in the twin, beside the real trajectory")
    what.add_argument("--replay-all", type=Path, metavar="DIR",
                      help="replay every <run>.csv of DIR that has a <run>_path.csv; one summary table")
    rg.add_argument("--paper-cost", action="store_true",
                    help="the paper's planner, as the robot ran it: eq. 19 at the leaf, depth 1, weights 500/50/300, "
                         "tangent heading, relative metric (overrides the depth, weight, look-ahead and correction "
                         "options)")
    rg.add_argument("--seeds", type=int, default=None,
                    help="twin runs per log with seeds --seed, --seed+1, ... (pooled in the summary; default 5); "
                         "also per case of --fault-campaign and --planner-compare (default 1; 3 for a full "
                         "--fault-campaign)")
    rg.add_argument("--tag-offset-deg", type=float, default=None,
                    help="body heading - tag theta [deg] (default: estimated on the folder's line runs)")
    rg.add_argument("--ideal-loop", action="store_true",
                    help="with --paper-cost: the paper's cost on the project's loop (Kalman-filtered tracker, a "
                         "decision at each tick on the newest pose); default: the robot's own loop, decisions on "
                         "the mean of the last 0.63 s of raw poses and frame-difference velocities, the newest "
                         "sent each period (planner_node replan_interval, tracker_node estimator)")
    rg.add_argument("--aligned-tag", action="store_true",
                    help="draw the twin's tag aligned with the body (the planner then sees the true heading); "
                         "default: turned by -offset as on the robot, whose planner saw the tag's heading")
    ap.add_argument("--real-time-factor", type=float, default=1.0,
                    help="simulated seconds per wall second (all nodes follow /clock)")
    ap.add_argument("--seed", type=int, default=1, help="seed of every random element (noise, BLE jitter, limbs)")
    cg = ap.add_argument_group("planner comparison")
    cg.add_argument("--planner-compare", action="store_true",
                    help="run the paper's planner, the project's, and the simulator in the loop at depth 1 and 2 "
                         "on each path with --seeds seeds; one table (compare.md) and one figure per path; "
                         "stopped (Ctrl-C, SIGTERM), the same command with the same --out resumes it")
    cg.add_argument("--compare-planners", default="paper,project,sim-d1,sim-d2",
                    help="planners compared (comma-separated of paper, project, sim-d1, sim-d2, sim-paper: the "
                         "paper's cost on the simulator's predictions)")
    cg.add_argument("--compare-beam", type=int, default=3, choices=range(0, 10), metavar="K",
                    help="sim-d2 rolls out the K first primitives the library ranks best (0 = all 9; default 3)")
    cg.add_argument("--compare-paths", default="all",
                    help="the paper's paths compared (comma-separated; all; none: only --compare-runs)")
    cg.add_argument("--compare-runs", type=Path, default=None, metavar="DIR",
                    help="also each hardware run's reference path in DIR (<run>.csv + <run>_path.csv), from its "
                         "logged start pose at its fitted period")
    ap.add_argument("--transitions", choices=("library", "simulator"), default="library",
                    help="the planner's predictions: the motion library (the paper) or the DER simulator itself "
                         "(rollout_node; depth 1-2; --node-param planner_node:decision_deadline=0.7, beam_width=3)")
    ap.add_argument("--duration", type=float, default=None,
                    help="simulated seconds at most per path (default 150; replays: twice the real run + 15)")
    ap.add_argument("--no-vision", action="store_true", help="ground-truth odometry instead of camera + tracker")
    ap.add_argument("--direct", action="store_true", help="planner -> simulator without bridge, pty and emulator")
    ap.add_argument("--kick-strength-sd", type=float, default=KICK_STRENGTH_SD,
                    help="relative spread of each firing's kick, drawn per firing (0 = every kick alike)")
    ap.add_argument("--limb-strength-sd", type=float, default=LIMB_STRENGTH_SD,
                    help="relative spread of the limbs' kick strengths, drawn per limb from the seed (0 = nominal)")
    ap.add_argument("--yaw-disturbance-sd", type=float, default=YAW_DISTURBANCE_SD,
                    help="stationary sd of the tank's slowly varying yaw torque [N m] (0 = none)")
    ap.add_argument("--yaw-disturbance-tau", type=float, default=YAW_DISTURBANCE_TAU_S,
                    help="its time constant [s]")
    ap.add_argument("--lateral-offset", type=float, default=0.0, help="start left of the path [m]")
    ap.add_argument("--video-rate", type=float, default=5.0, help="frames per simulated second in the video")
    ap.add_argument("--library", type=Path, default=None,
                    help="motion library (default runs/library/frog_default.npz, generated on first use)")
    ap.add_argument("--library-states", type=int, default=200, help="size of the default library if generated")
    ap.add_argument("--out", type=Path, default=None, help="run folder (default runs/main_<time>)")
    rr = ap.add_argument_group("the real robot: the same graph with the real camera and port")
    rr.add_argument("--robot-port", type=Path, default=None, help="serial device of the BLE relay (e.g. /dev/ttyACM0)")
    rr.add_argument("--camera", default=None, help="camera_node source: a device (/dev/video0), an index, a video file")
    rr.add_argument("--camera-info", type=Path, default=None, help="the camera's camera_calibration YAML")
    rr.add_argument("--camera-fps", type=float, default=30.0,
                    help="the camera's frame rate [Hz] (pre-flight checks it)")
    rr.add_argument("--tank-calibration", type=Path, default=None,
                    help="tank calibration YAML (frog-vision calibrate-tank)")
    rr.add_argument("--tag-offset", type=Path, default=None,
                    help="tag-to-body offset file (frog-vision tag-offset); without it the tracker's default, warned")
    rr.add_argument("--start-tolerance", type=float, default=0.05,
                    help="pre-flight: largest distance from the robot to the path's start [m]")
    rr.add_argument("--reference-sim", action="store_true",
                    help="run sim_node beside the robot as a reference prediction (from the tracked start pose, "
                         "executing the planner's primitives; never in the loop)")
    rr.add_argument("--preflight-timeout", type=float, default=20.0, help="longest wait of each pre-flight check [s]")
    rr.add_argument("--tag-lost-timeout", type=float, default=None,
                    help="stop when the tag is not seen for this long [s] (the budget tag_lost_after_s, default 3)")
    gg = ap.add_argument_group("the graph (frog_twin/config/frog_graph.yaml)")
    gg.add_argument("--print-graph", action="store_true",
                    help="print the equivalent 'ros2 run' command lines of --mode and exit (nothing is started)")
    gg.add_argument("--mode", choices=("sim", "real"), default=None,
                    help="with --print-graph: the twin's graph (sim, default) or the real robot's (real; implied by "
                         "--robot-port / --camera)")
    fg = ap.add_argument_group("faults")
    fg.add_argument("--faults", metavar="SPEC", default=None,
                    help="inject faults: ';'-separated KIND[:NODE]@AT[+DURATION][,key=value], AT in simulated s after "
                         "the planner's start; kinds: camera_freeze, camera_stop, occlude, frame_drop (rate=), "
                         "ble_loss (rate=), unplug, emergency, kill:NODE (restart=yes|no), clock_stall, sigstop:NODE "
                         "(the last two in wall s). E.g. 'camera_freeze@5+5;kill:tracker_node@12'")
    fg.add_argument("--fault-campaign", action="store_true",
                    help="every fault of the campaign at --moments moments x --seeds seeds on --campaign-paths; one "
                         "summary table (runs/faults_<time>/campaign.md)")
    fg.add_argument("--fault-classes", action="store_true",
                    help="with --fault-campaign: the reduced form, one run per fault class with several faults")
    fg.add_argument("--campaign-paths", default="line,sine", help="paths of the campaign (comma-separated)")
    fg.add_argument("--campaign-faults", default=None, metavar="SPEC",
                    help="the campaign's faults instead of its default list (their times are replaced by the moments)")
    fg.add_argument("--campaign-shard", default=None, metavar="K/N",
                    help="with --fault-campaign: only every N-th run from the K-th, so that N processes share a "
                         "campaign (same --out; a twin needs about 1.5 cores: on 2 cores run one, docs/faults.md); "
                         "runs already done in --out are skipped, so the same command resumes an interrupted "
                         "campaign")
    fg.add_argument("--moments", type=int, default=3, choices=(1, 2, 3),
                    help="moments of the path per fault: 3 = 0.2, 0.45, 0.7 of its nominal time; 2 = 0.2, 0.7; "
                         "1 = 0.45")
    ap.add_argument("--node-param", action="append", default=[], metavar="NODE:NAME=VALUE",
                    help="set a node's parameter for this run (YAML value; repeatable), e.g. "
                         "--node-param tracker_node:frozen_frames=5 --node-param planner_node:max_state_age_s=0.4")
    ap.add_argument("--domain", type=int, default=None, choices=range(0, 233), metavar="ID",
                    help="ROS domain id of the run, to watch it with ros2 topic echo (default: one no other run on "
                         "this machine holds)")
    ap.add_argument("--budget", action="append", default=[], metavar="NAME=SECONDS",
                    help="replace a liveness budget of the graph file for this run (repeatable; their order is "
                         "checked), e.g. --budget deaf_after_s=6 --budget stuck_after_s=30: restart_backoff_s, "
                         "restart_backoff_max_s, max_restarts, restart_grace_s, deaf_after_s (0 = off), "
                         "world_stall_s (0 = off), stuck_after_s, tag_lost_after_s")
    add_arguments(ap, PlannerSettings)
    add_arguments(ap, PathSettings, exclude=("path_type", "path_start_x", "path_start_y", "path_heading",
                                             "waypoint_file"))
    ap.set_defaults(period=HARDWARE_PERIOD_S)
    args = ap.parse_args(argv)
    real = args.robot_port is not None or args.camera is not None or args.mode == "real"
    if real:
        prepared = _prepare_real(ap, args)
        if prepared is not None:
            return prepared
    if args.print_graph:
        return print_graph(args)
    if real:
        return main_real(ap, args)
    replaying = args.replay is not None or args.replay_all is not None
    if args.seeds is None:         # the campaign: every fault x 3 moments x 3 seeds
        args.seeds = 3 if args.fault_campaign and not args.fault_classes else REPLAY_SEEDS if replaying else 1
    if args.duration is None and not replaying:
        args.duration = 150.0
    if not (args.real_time_factor > 0 and (args.duration is None or args.duration > 0)
            and 0 <= args.limb_strength_sd < 1 and 0 <= args.kick_strength_sd <= 0.5 and args.seeds >= 1
            and 0 <= args.yaw_disturbance_sd <= 1e-3 and 0.05 <= args.yaw_disturbance_tau <= 100):
        ap.error("--real-time-factor and --duration must be > 0, --limb-strength-sd in [0, 1), "
                 "--kick-strength-sd in [0, 0.5], --seeds >= 1, --yaw-disturbance-sd in [0, 1e-3] N m, "
                 "--yaw-disturbance-tau in [0.05, 100] s")
    if replaying:
        if args.path is not None and args.replay is None:
            ap.error("--path (a path CSV) goes with --replay; --replay-all finds <run>_path.csv itself")
        args.path = Path(args.path) if args.path is not None else None
        for f, what in ((args.replay, "log"), (args.path, "path file")):
            if f is not None and not f.is_file():
                ap.error(f"--replay {what} {f} does not exist")
        if args.replay_all is not None and not args.replay_all.is_dir():
            ap.error(f"--replay-all {args.replay_all} is not a folder")
        if args.ideal_loop and not args.paper_cost:
            ap.error("--ideal-loop goes with --paper-cost (the project's planner always runs the project's loop)")
    else:
        args.path = args.path or "all"
        if args.path not in (*PATH_NAMES, "all"):
            ap.error(f"--path {args.path!r}: expected one of {', '.join(PATH_NAMES)}, all (or --replay RUN.csv)")
        if (args.paper_cost or args.tag_offset_deg is not None or args.aligned_tag or args.ideal_loop
                or (args.seeds != 1 and not (args.fault_campaign or args.planner_compare))):
            ap.error("--paper-cost, --tag-offset-deg, --aligned-tag and --ideal-loop go with --replay / --replay-all, "
                     "--seeds "
                     "also with --fault-campaign")
    try:
        args.node_params = parse_node_params(args.node_param)
        args.budgets = parse_budgets(args.budget)
        graph_liveness(GRAPH_FILE, "sim", (), args.budgets)         # checks names, values and their order
    except ValueError as exc:
        ap.error(str(exc))
    args.fault_list = ()
    if args.faults is not None:
        if replaying or args.fault_campaign:
            ap.error("--faults goes with a path run (not with --replay or --fault-campaign)")
        try:
            args.fault_list = parse_faults(args.faults)
        except FaultSpecError as exc:
            ap.error(str(exc))
    if args.fault_campaign:
        if replaying:
            ap.error("--fault-campaign goes without --replay")
        bad = [p for p in args.campaign_paths.split(",") if p.strip() not in PATH_NAMES]
        if bad:
            ap.error(f"--campaign-paths {', '.join(bad)}: expected of {', '.join(PATH_NAMES)}")
        if args.campaign_faults is not None:
            try:
                parse_faults(args.campaign_faults)
            except FaultSpecError as exc:
                ap.error(str(exc))
        if args.campaign_shard is not None:
            k, _, n = args.campaign_shard.partition("/")
            if not (k.isdigit() and n.isdigit() and 1 <= int(k) <= int(n)):
                ap.error(f"--campaign-shard {args.campaign_shard}: expected K/N with 1 <= K <= N, e.g. 1/2")
    elif args.fault_classes or args.campaign_faults is not None or args.campaign_shard is not None:
        ap.error("--fault-classes, --campaign-faults and --campaign-shard go with --fault-campaign")
    try:
        args.settings = from_arguments(PlannerSettings, args)
        args.path_settings = from_arguments(PathSettings, args, path_type="line")
    except ValueError as exc:
        ap.error(str(exc))
    root = repo_root()
    default_library = root / "runs" / "library" / "frog_default.npz"
    if args.library is None:
        args.library = ensure_library(default_library, args.library_states)
    elif not args.library.exists():
        ap.error(f"library {args.library} does not exist (frog-library generate --out ...)")
    if replaying:
        from frog_twin.replay_cli import main_replay
        try:
            return main_replay(args, root)
        except (OSError, ValueError) as exc:
            print(f"frog-twin: error: {exc}", file=sys.stderr)
            return 2
    if args.fault_campaign:
        from frog_twin.campaign import main_campaign
        return main_campaign(args, root)
    if args.planner_compare:
        from frog_twin.planner_compare import PLANNERS, ResumeMismatch, main_compare
        bad = [k for k in args.compare_planners.split(",") if k.strip() not in PLANNERS]
        bad_paths = [p for p in args.compare_paths.split(",") if p not in (*PATH_NAMES, "all", "none")]
        if bad_paths:
            ap.error(f"--compare-paths {', '.join(bad_paths)}: expected of {', '.join(PATH_NAMES)}, all, none")
        if bad or (args.compare_runs is not None and not args.compare_runs.is_dir()):
            ap.error(f"--compare-planners {', '.join(bad)}: expected of {', '.join(PLANNERS)}" if bad
                     else f"--compare-runs {args.compare_runs} is not a folder")
        try:
            return main_compare(args, root)
        except ResumeMismatch as exc:
            print(f"frog-twin: error: {exc}", file=sys.stderr)
            return 2
    out = args.out or root / "runs" / time.strftime("main_%Y%m%d_%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    names = PATH_NAMES if args.path == "all" else (args.path,)
    results = []
    for name in names:
        print(f"twin: {name} path -> {out}", flush=True)
        try:
            results.append(run_path(args, name, out / name, faults=args.fault_list))
        except (FaultSpecError, GraphError) as exc:
            print(f"frog-twin: error: {exc}", file=sys.stderr)
            return 2
        if args.fault_list:
            print(twin_report_faults(results[-1]["faults"]), flush=True)
    (out / "metrics.json").write_text(json.dumps(results, indent=1, default=float) + "\n")
    print()
    print(twin_report.summary_table(results))
    print("\nwall time per path: " + ", ".join(f"{m['path']} {m['wall_time_s']:.0f} s" for m in results))
    print(f"plots, videos, metrics: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
