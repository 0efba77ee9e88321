"""frog-twin's real mode end to end on emulated devices (issue 20).

The "camera" is a real camera_node playing a video the project's renderer made of the robot
at the line path's start; the "robot" is robot_emulator behind a pty opened as a device
path. Pre-flight passes, the planner decides, 'h' lines reach the port, /frog/stop ends the
run within one period, the report is written. Each pre-flight check is broken once.
"""

import csv
import json
import re
import math
import os
import subprocess
import time

import pytest
import yaml

pytestmark = [pytest.mark.system, pytest.mark.usefixtures("one_twin")]
FPS = 15.0
PERIOD = 1.43
#: the emulated robot's IMU reports the heading the tracker sees (there is no simulator here)
EMULATED_IMU = {"frog/sim/odom": "frog/odom"}


def _render(folder, y_of_t, duration, x=0.0):
    folder.mkdir(parents=True, exist_ok=True)
    traj = folder / "traj.csv"
    with open(traj, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x", "y", "heading"])
        for i in range(int(duration * 10) + 1):
            t = i / 10
            w.writerow([t, x, y_of_t(t), math.pi / 2])
    r = subprocess.run(["frog-vision", "render", "--trajectory", str(traj), "--fps", str(FPS), "--noise", "1",
                        "-o", str(folder)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return folder


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    # the line path's start (frog-twin places it at x 0, y -0.233, heading +y); slow swim along it.
    # 90 s: a tracker stopped twice, then wedged once after its restart, is back about 60 s after
    # the camera started on a loaded machine (45 s ran out before its third restart, 2026-12-05)
    return _render(tmp_path_factory.mktemp("video"), lambda t: -0.233 + 0.004 * t, 90.0)


def _frog_twin(args, env, timeout):
    return subprocess.Popen(["frog-twin", *map(str, args)], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _real_args(video, port, library, out, domain, duration=40, **extra):
    args = ["--robot-port", port, "--camera", video / "frames.mp4", "--camera-info", video / "camera_info.yaml",
            "--tank-calibration", video / "tank_calibration.yaml", "--camera-fps", FPS, "--path", "line",
            "--library", library, "--out", out, "--domain", domain, "--duration", duration]
    for k, v in extra.items():
        args += [f"--{k.replace('_', '-')}", v]
    return args


def _wait_for_link(link, proc=None):
    deadline = time.monotonic() + 60
    while not link.exists():
        assert time.monotonic() < deadline, "the emulator's pty did not appear"
        assert proc is None or proc.running(), proc.log_text()[-2000:]
        time.sleep(0.1)


def test_real_mode_on_emulated_devices(video, library, launch, ros_domain, probe, tmp_path):
    from std_msgs.msg import Empty
    link = tmp_path / "robot_tty"
    commands = tmp_path / "robot_commands.csv"
    emu = launch("robot_emulator", params={"link_path": str(link), "command_log": str(commands), "seed": 3},
                 remap=EMULATED_IMU)
    _wait_for_link(link, emu)
    out = tmp_path / "real"
    proc = _frog_twin(_real_args(video, link, library, out, ros_domain.domain_id), ros_domain.env, 400)
    pub = probe.node.create_publisher(Empty, "/frog/stop", 10)
    try:
        # decisions are made and 'h' lines reach the port
        deadline = time.monotonic() + 240
        h_lines = []
        while len(h_lines) < 6:          # at most two lines (front, rear) per decision: >= 3 decisions
            if proc.poll() is not None:
                so, se = proc.communicate()
                pytest.fail(f"frog-twin ended early ({proc.returncode}):\n{so[-3000:]}\n{se[-3000:]}")
            assert time.monotonic() < deadline, "fewer than 6 'h' lines reached the port"
            probe.spin_for(0.5)
            if commands.exists():
                with open(commands) as fh:
                    h_lines = [r for r in csv.DictReader(fh) if r["line"].startswith("h ")]
        # the stop reaches frog-twin, the planner and the bridge (DDS-matched before it is sent)
        probe.spin_until(lambda: pub.get_subscription_count() >= 3, 30, "/frog/stop matched by 3 subscribers")
        t_stop = time.time()
        for _ in range(5):
            pub.publish(Empty())
            probe.spin_for(0.05)
        stdout, stderr = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    (tmp_path / "frog_twin.out").write_text(stdout + "\n--- stderr ---\n" + stderr)
    assert proc.returncode == 0, stdout[-3000:] + stderr[-3000:]
    assert "no --tag-offset file" in stderr
    assert "stopped (stop received on /frog/stop)" in stdout, stdout[-2000:]
    for name in ("camera", "calibration", "tag", "link", "library", "start"):
        assert f"pre-flight {name}" in stdout, stdout
    # nothing was heated after the stop, beyond one period
    with open(commands) as fh:
        rows = list(csv.DictReader(fh))
    h_after = [float(r["wall_time_s"]) for r in rows if r["line"].startswith("h ")
               and float(r["wall_time_s"]) > t_stop + PERIOD]
    assert not h_after, (t_stop, h_after)
    (m,) = json.loads((out / "metrics.json").read_text())
    assert m["mode"] == "real" and m["stop_reason"] == "stop received on /frog/stop"
    assert m["decisions"] >= 3 and m["latency_decision_to_serial"]["n"] >= 3, m
    assert all(c["ok"] for c in m["preflight"])
    for f, size in (("line.png", 20_000), ("line.mp4", 10_000), ("line.json", 1000)):
        assert (out / f).stat().st_size > size, f
    assert list((out / "line" / "recording").glob("*.mcap"))


def _preflight_failure(args, env):
    r = subprocess.run(["frog-twin", *map(str, args)], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stdout[-2000:] + r.stderr[-2000:]
    assert "pre-flight failed, nothing was actuated" in r.stderr, r.stderr[-2000:]
    print(r.stdout + r.stderr)            # shown with -s: the messages a user sees
    return r.stderr


def test_preflight_no_tag(library, launch, ros_domain, probe, tmp_path):
    from nav_msgs.msg import Odometry
    empty = _render(tmp_path / "empty", lambda t: 0.0, 12.0, x=3.0)     # the robot far outside the view
    link = tmp_path / "robot_tty"
    # without a tag there is no frog/odom: the emulated IMU gets a heading of its own, so only the tag is broken
    launch("robot_emulator", params={"link_path": str(link)}, remap={"frog/sim/odom": "/test/heading"})
    pub = probe.node.create_publisher(Odometry, "/test/heading", 10)
    _wait_for_link(link)
    # the tag never comes, so the pre-flight waits its whole timeout; the other checks must pass
    # within it: 8 s was too short for planner_node's first status on a loaded machine
    proc = _frog_twin(_real_args(empty, link, library, tmp_path / "o", ros_domain.domain_id, preflight_timeout=30),
                      ros_domain.env, 300)
    odom = Odometry()
    odom.pose.pose.orientation.w = 1.0
    deadline = time.monotonic() + 240
    while proc.poll() is None and time.monotonic() < deadline:
        pub.publish(odom)
        probe.spin_for(0.1)
    stdout, stderr = proc.communicate(timeout=60)
    print(stdout + stderr)
    assert proc.returncode == 2 and "pre-flight failed, nothing was actuated" in stderr, stdout + stderr
    failed = [ln for ln in stderr.splitlines() if ln.startswith("  - ")]
    assert len(failed) == 1 and "tag not detected" in failed[0], stderr


def test_preflight_wrong_image_size(video, library, launch, ros_domain, tmp_path):
    tank = yaml.safe_load((video / "tank_calibration.yaml").read_text())
    tank["image_size"] = [1280, 720]
    bad = tmp_path / "video"
    bad.mkdir()
    for f in ("frames.mp4", "camera_info.yaml"):
        os.symlink(video / f, bad / f)
    (bad / "tank_calibration.yaml").write_text(yaml.safe_dump(tank))
    link = _start_emulator(launch, tmp_path)
    err = _preflight_failure(_real_args(bad, link, library, tmp_path / "o", ros_domain.domain_id,
                                        preflight_timeout=30), ros_domain.env)    # (all but one check pass: no wait)
    assert "is for 1280x720 images but the camera delivers 640x480 frames" in err
    # everything else passed, and still nothing was heated: the port heard only the pulse length
    lines = [r["line"] for r in csv.DictReader(open(tmp_path / "commands.csv"))]
    assert lines and not [ln for ln in lines if ln.startswith("h ")], lines


def test_preflight_silent_port(video, library, ros_domain, serial_pair, tmp_path):
    _, device = serial_pair                 # a pty nobody answers on
    err = _preflight_failure(_real_args(video, device, library, tmp_path / "o", ros_domain.domain_id,
                                        preflight_timeout=8), ros_domain.env)
    assert "'Central: Q' line(s)" in err or "link to" in err


def test_print_graph_shows_both_modes_ros2_run_lines(tmp_path):
    sim = subprocess.run(["frog-twin", "--print-graph", "--path", "line", "--library", "lib.npz"],
                         capture_output=True, text=True, timeout=120)
    assert sim.returncode == 0, sim.stderr
    lines = [ln for ln in sim.stdout.splitlines() if ln.startswith("ros2 run")]
    assert [ln.split()[2:4] for ln in lines] == [
        ["frog_logger", "recorder"], ["frog_sim", "sim_node"], ["frog_vision", "camera_sim"],
        ["frog_vision", "tracker_node"], ["frog_twin", "image_preview"], ["frog_bridge", "robot_emulator"],
        ["frog_bridge", "bridge_node"], ["frog_planner", "planner_node"]]
    assert all("use_sim_time:=true" in ln for ln in lines if " sim_node " not in ln)
    offset = tmp_path / "tag_offset.yaml"
    offset.write_text("offset_x: 0.0031\noffset_y: -0.0004\noffset_yaw: 0.0977\n")
    real = subprocess.run(["frog-twin", "--print-graph", "--robot-port", "/dev/ttyACM0", "--camera", "/dev/video0",
                           "--tag-offset", str(offset), "--path", "sine", "--library", "lib.npz"],
                          capture_output=True, text=True, timeout=120)
    assert real.returncode == 0, real.stderr
    lines = [ln for ln in real.stdout.splitlines() if ln.startswith("ros2 run")]
    assert [ln.split()[3] for ln in lines] == ["recorder", "camera_node", "tracker_node", "image_preview",
                                               "bridge_node", "planner_node"]
    assert not any("use_sim_time" in ln for ln in lines)
    tracker = next(ln for ln in lines if " tracker_node " in ln)
    assert "-p offset_yaw:=0.0977" in tracker and "-p offset_y:=-0.0004" in tracker
    assert "-p port:=/dev/ttyACM0" in next(ln for ln in lines if " bridge_node " in ln)
    assert "-p path_type:=sine" in lines[-1]
    bad = tmp_path / "bad.yaml"
    bad.write_text("offset_yaw: 9\n")
    r = subprocess.run(["frog-twin", "--print-graph", "--robot-port", "/dev/ttyACM0", "--camera", "/dev/video0",
                        "--tag-offset", str(bad)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "needs offset_x, offset_y, offset_yaw" in r.stderr, r.stderr


def _start_emulator(launch, tmp_path):
    link = tmp_path / "robot_tty"
    emu = launch("robot_emulator", params={"link_path": str(link), "command_log": str(tmp_path / "commands.csv")},
                 remap=EMULATED_IMU)
    _wait_for_link(link, emu)
    return link


def _node_pid(executable, domain_id):
    """The pid of the ``executable`` node process running on ROS domain ``domain_id`` (held by this test)."""
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            argv = open(f"/proc/{d}/cmdline", "rb").read().split(b"\0")
            env = open(f"/proc/{d}/environ", "rb").read().split(b"\0")
        except OSError:
            continue
        if any(os.path.basename(a) == executable.encode() for a in argv[:2]) and \
                f"ROS_DOMAIN_ID={domain_id}".encode() in env:
            return int(d)
    return None


def test_lost_tag_stops_the_run_and_reports(video, library, launch, ros_domain, probe, tmp_path):
    """Also runs sim_node beside as the reference prediction (--reference-sim), outside the loop."""
    import signal
    from nav_msgs.msg import Odometry
    from soft_robot_interfaces.msg import PlannerStatus
    from std_msgs.msg import Empty
    # The camera stops once the run has followed for 3 simulated seconds of the reference sim:
    # camera_node is frozen (SIGSTOP) until frog-twin sends its stop. (The end of a 16 s video
    # did this before, on the wall clock from camera_node's start: the pre-flight and the start-up
    # took 5 s of it on a quiet machine and all of it on a loaded one, 2 reference poses.) The
    # reference sim drifts from the filmed robot, which does not obey: the window stays short.
    link = _start_emulator(launch, tmp_path)
    out = tmp_path / "real"
    ref_odom, following, stops = [], [], []
    probe.node.create_subscription(Odometry, "/frog/sim/odom", ref_odom.append, 100)
    probe.node.create_subscription(
        PlannerStatus, "/frog/planner/status",
        lambda m: following.append(m) if m.state == PlannerStatus.STATE_FOLLOWING else None, 10)
    probe.node.create_subscription(Empty, "/frog/stop", stops.append, 10)
    args = _real_args(video, link, library, out, ros_domain.domain_id, duration=120,
                      tag_lost_timeout=2) + ["--reference-sim"]
    with open(tmp_path / "frog_twin.err", "w") as err:
        proc = subprocess.Popen(["frog-twin", *map(str, args)], env=ros_domain.env, stdout=subprocess.PIPE,
                                stderr=err, text=True)
        camera = None
        try:
            probe.spin_until(lambda: following or proc.poll() is not None, 240, "the planner following")
            assert proc.poll() is None, proc.communicate()[0][-3000:]
            n = len(ref_odom)
            probe.spin_until(lambda: len(ref_odom) >= n + 150 or proc.poll() is not None, 120,
                             "3 s of the reference sim while following")
            camera = _node_pid("camera_node", ros_domain.domain_id)
            assert camera is not None and proc.poll() is None
            os.kill(camera, signal.SIGSTOP)
            probe.spin_until(lambda: stops or proc.poll() is not None, 60, "frog-twin's stop")
            os.kill(camera, signal.SIGCONT)
            camera = None
            stdout, _ = proc.communicate(timeout=180)
        finally:
            if camera is not None:
                os.kill(camera, signal.SIGCONT)
            if proc.poll() is None:
                proc.kill()
    stderr = (tmp_path / "frog_twin.err").read_text()
    assert proc.returncode == 0, stdout[-3000:] + stderr[-3000:]
    # the camera's edge in the graph file's liveness section: its frame count stands still in real mode
    assert re.search(r"stopped \(camera_node published nothing on camera/image_raw \(camera frames\) for 2\.\d s\)",
                     stdout), stdout[-2000:]
    (m,) = json.loads((out / "metrics.json").read_text())
    assert m["stop_reason"].startswith("camera_node published nothing") and (out / "line.png").exists()
    assert [v["rule"] for v in m["supervision"]["liveness_verdicts"]] == ["camera_real"]
    ref = m["reference_prediction"]
    assert ref["n"] > 50 and ref["mean_distance_to_tracked_m"] < 0.2, ref


@pytest.mark.parametrize("sig, reason", [("SIGINT", "Ctrl-C"), ("SIGTERM", "SIGTERM")])
def test_ctrl_c_or_sigterm_stops_the_run_and_reports(sig, reason, video, library, launch, ros_domain, tmp_path):
    import signal
    link = _start_emulator(launch, tmp_path)
    out = tmp_path / "real"
    proc = _frog_twin(_real_args(video, link, library, out, ros_domain.domain_id), ros_domain.env, 300)
    try:
        deadline = time.monotonic() + 200
        while not (tmp_path / "commands.csv").exists() or "h " not in (tmp_path / "commands.csv").read_text():
            assert proc.poll() is None and time.monotonic() < deadline, "no 'h' line reached the port"
            time.sleep(0.2)
        t_stop = time.time()
        proc.send_signal(getattr(signal, sig))
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stdout[-3000:] + stderr[-3000:]
    assert f"stopped ({reason})" in stdout
    with open(tmp_path / "commands.csv") as fh:
        late = [r for r in csv.DictReader(fh) if r["line"].startswith("h ")
                and float(r["wall_time_s"]) > t_stop + PERIOD]
    assert not late, late
    assert json.loads((out / "metrics.json").read_text())[0]["stop_reason"] == reason


def test_ctrl_c_during_preflight_ends_at_once_without_actuation(video, library, ros_domain, probe, serial_pair,
                                                                 tmp_path):
    import signal
    from geometry_msgs.msg import PoseStamped
    _, device = serial_pair                 # a silent port: the link check would wait the whole timeout
    proc = _frog_twin(_real_args(video, device, library, tmp_path / "o", ros_domain.domain_id,
                                 preflight_timeout=120), ros_domain.env, 300)
    poses = []
    probe.node.create_subscription(PoseStamped, "/frog/pose", poses.append, 10)
    try:
        assert proc.stdout.readline().startswith("real robot:")
        # the pre-flight is under way, every node up: the tag is tracked (the camera and tag
        # checks can pass), the bridge and planner are on the graph; the link check waits
        probe.spin_until(lambda: len(poses) >= 3 or proc.poll() is not None, 120, "the tag tracked")
        assert proc.poll() is None, proc.communicate()
        for node in ("/bridge_node", "/planner_node"):
            probe.wait_for_node(node, timeout=60)
        t_int = time.monotonic()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 2 and "interrupted (Ctrl-C) during the pre-flight" in stderr, stdout + stderr
    assert time.monotonic() - t_int < 40, "the pre-flight did not end at Ctrl-C"


@pytest.mark.parametrize("sig", ["SIGKILL", "SIGSTOP", "SIGSTOP-twice"])
def test_killed_tracker_is_restarted_and_the_run_goes_on(sig, video, library, launch, ros_domain, probe, tmp_path):
    """Supervision in real mode: SIGKILL of tracker_node while following, or SIGSTOP (a tracker alive but
    deaf, as when the middleware blocks it); frog-twin restarts it (a deaf one once its frame count has stood
    still for deaf_after_s while the camera's rose), poses come back, the planner follows again, and
    /frog/stop then ends the run with the restart in the report."""
    import signal
    import warnings
    from geometry_msgs.msg import PoseStamped
    from soft_robot_interfaces.msg import PlannerStatus
    from std_msgs.msg import Empty
    link = _start_emulator(launch, tmp_path)
    out = tmp_path / "real"
    poses, following = [], []
    probe.node.create_subscription(PoseStamped, "/frog/pose", lambda m: poses.append(time.monotonic()), 10)
    probe.node.create_subscription(
        PlannerStatus, "/frog/planner/status",
        lambda m: following.append(time.monotonic()) if m.state == PlannerStatus.STATE_FOLLOWING else None, 10)
    pub = probe.node.create_publisher(Empty, "/frog/stop", 10)
    # tag-lost timeout 5 s: the camera's frames reached no one for 2.1 s once beside two busy processes
    # (series of 2026-12-06, docs/faults.md), and no pose with no frames is a lost tag (the run stops)
    args = _real_args(video, link, library, out, ros_domain.domain_id, duration=150, tag_lost_timeout=5)
    log = tmp_path / "frog_twin.out"
    with open(log, "w") as fh:
        proc = subprocess.Popen(["frog-twin", *map(str, args)], env=ros_domain.env, stdout=fh,
                                stderr=subprocess.STDOUT, text=True)
        try:
            probe.spin_until(lambda: following or proc.poll() is not None, 240, "the planner following")
            assert proc.poll() is None, log.read_text()[-3000:]
            tracker = _node_pid("tracker_node", ros_domain.domain_id)
            assert tracker is not None
            os.kill(tracker, getattr(signal, sig.split("-")[0]))
            t_kill = time.monotonic()
            probe.spin_until(lambda: "supervisor: tracker_node restarted" in log.read_text()
                             or proc.poll() is not None, 60, "the tracker's restart")
            assert proc.poll() is None, log.read_text()[-3000:]
            if sig == "SIGSTOP-twice":      # the restarted tracker stuck once it says it tracks
                again = _node_pid("tracker_node", ros_domain.domain_id)
                assert again not in (None, tracker), (again, tracker)
                first_log = out / "line" / "tracker_node.1.log"
                probe.spin_until(lambda: first_log.exists() and "tag tracking" in first_log.read_text()
                                 or proc.poll() is not None, 60, "the restarted tracker tracking")
                os.kill(again, signal.SIGSTOP)
                probe.spin_until(lambda: log.read_text().count("supervisor: tracker_node restarted") >= 2
                                 or proc.poll() is not None, 90, "the second restart")
                assert proc.poll() is None, log.read_text()[-3000:]
            # the restarted tracker tracks (more than the 5 s tag-lost timeout after the kill on a loaded
            # machine: its downtime is not the tag lost), and the planner follows on its poses
            probe.spin_until(lambda: len([t for t in poses if t > t_kill]) >= 5 or proc.poll() is not None,
                             90, "poses from the restarted tracker")
            t_back = min(t for t in poses if t > t_kill)
            probe.spin_until(lambda: any(t > t_back for t in following) or proc.poll() is not None, 60,
                             "the planner following again")
            assert proc.poll() is None, log.read_text()[-3000:]
            probe.spin_until(lambda: pub.get_subscription_count() >= 3, 30, "/frog/stop matched")
            for _ in range(5):
                pub.publish(Empty())
                probe.spin_for(0.05)
            proc.wait(timeout=180)
        finally:
            if proc.poll() is None:
                proc.kill()
    text = log.read_text()
    assert proc.returncode == 0, text[-3000:]
    assert "stopped (stop received on /frog/stop)" in text, text[-2000:]
    (m,) = json.loads((out / "metrics.json").read_text())
    assert m["stop_reason"] == "stop received on /frog/stop"
    hung = [e for e in m["supervision"]["events"] if e["what"] == "hung"]
    assert {e["node"] for e in hung} <= {"tracker_node"}, m["supervision"]["events"]
    if sig == "SIGKILL":
        assert "supervisor: tracker_node exited (SIGKILL): restart 1 in 1.0 s" in text, text[-3000:]
    else:   # the stopped tracker itself was found deaf and killed
        assert hung and "tracker_node received nothing on camera/image_raw" in hung[0]["detail"], \
            m["supervision"]["events"]
    if sig == "SIGSTOP-twice":   # and the restarted one: deaf, or never ready within its grace
        assert len(hung) >= 2 and hung[1]["detail"].startswith(("tracker_node received nothing", "not ready")), hung
    # a restarted tracker the middleware blocks after its restart (docs/faults.md) is found deaf and
    # restarted again: one more restart each
    expected = {"SIGKILL": 0, "SIGSTOP": 1, "SIGSTOP-twice": 2}[sig]
    if len(hung) > expected:
        warnings.warn(f"a restarted tracker was deaf and restarted again ({len(hung)} hung events, docs/faults.md)")
    restarts = m["supervision"]["restarts"]
    assert restarts["tracker_node"] == 1 + len(hung) - min(expected, 1), m["supervision"]
    assert sum(restarts.values()) == restarts["tracker_node"], m["supervision"]
    assert (out / "line" / "tracker_node.1.log").exists()
