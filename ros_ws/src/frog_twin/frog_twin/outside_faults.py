"""``frog-outside-faults``: signals sent to a running twin from outside its process tree.

The fault injector acts from inside ``frog-twin``; a user, a scheduler or the kernel does not.
This tool starts ``frog-twin`` as a child on a ROS domain it holds, watches the planner's status
and ``/clock`` on that domain, and at simulated moments after the planner starts sends plain
signals to the twin's node processes (found by the parent pid each node's environment names):
``kill:NODE@AT`` (SIGKILL) and ``sigstop:NODE@AT+SECONDS`` (SIGSTOP, then SIGCONT that many
wall seconds later). After the run it audits the recording itself
(:mod:`frog_twin.core.state_audit`): every limb pulse against the newest measured pose published
before it, and the bridge's own record. A run completes, or stops with a reason, and no pulse
rests on a state older than ``max_state_age_s``; the campaign (``--campaign``) sends each signal at
three moments of the line and the sine and writes one table.

Examples
--------
frog-outside-faults --path line --plan "kill:tracker_node@6" --out runs/outside1
frog-outside-faults --path sine --plan "sigstop:planner_node@4+5;sigstop:sim_node@12+3"
frog-outside-faults --campaign --out runs/outside_campaign      # 7 signals x 3 moments x line, sine
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from frog_twin.core.faults import CAMPAIGN_MOMENTS, FaultSpecError, parse_faults

#: the signals of the campaign: every node of the vision-to-decision chain killed and stopped 5 s,
#: and the world stopped 3 s
SIGNALS = ("kill:tracker_node@0", "sigstop:tracker_node@0+5", "kill:camera_sim@0", "sigstop:camera_sim@0+5",
           "kill:planner_node@0", "sigstop:planner_node@0+5", "sigstop:sim_node@0+3")
#: the paths' nominal times [s simulated] (frog_twin.campaign), for the moments
NOMINAL_TIME_S = {"line": 15.7, "sine": 14.3, "ellipse": 24.3}


def parse_plan(spec: str) -> list:
    """The signals of ``spec`` (``kill:NODE@AT``, ``sigstop:NODE@AT+S``; ';'-separated), in time order."""
    plan = parse_faults(spec)
    for f in plan:
        if f.kind not in ("kill", "sigstop"):
            raise FaultSpecError(f"{f.label()}: only kill and sigstop are signals (the injector has the rest: "
                                 f"frog-twin --faults)")
    return plan


def node_pid(parent: int, executable: str) -> int | None:
    """The running process of ``executable`` that process ``parent`` started (its environment names it)."""
    from soft_robot_common.processes import PARENT_PID_ENV
    mark = f"{PARENT_PID_ENV}={parent}".encode()
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if mark in (d / "environ").read_bytes().split(b"\0") and any(
                    a.endswith(b"/" + executable.encode()) for a in (d / "cmdline").read_bytes().split(b"\0")[:2]):
                return int(d.name)
        except OSError:
            continue
    return None


class _Watch:
    """The tool's node on the twin's domain: the planner's state and /clock."""

    def __init__(self, domain_id: int):
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock
        from soft_robot_common.graph_watch import GraphWatch
        from soft_robot_interfaces.msg import PlannerStatus
        self.graph = GraphWatch(domain_id, "outside_faults")
        self.Status = PlannerStatus
        self.state, self.sim = None, None
        self.graph.node.create_subscription(PlannerStatus, "/frog/planner/status",
                                            lambda m: setattr(self, "state", m.state), 10)
        self.graph.node.create_subscription(Clock, "/clock", lambda m: setattr(
            self, "sim", m.clock.sec + m.clock.nanosec * 1e-9), QoSProfile(depth=1,
                                                                          reliability=ReliabilityPolicy.BEST_EFFORT))

    def spin(self, seconds: float) -> None:
        self.graph.spin_for(seconds)


def run_with_signals(path: str, plan, out: Path, library: Path, seed: int = 1, extra=(), log=print) -> dict:
    """One ``frog-twin`` run on ``path`` with the signals of ``plan`` sent from here; its record."""
    from soft_robot_common.processes import acquire_domain

    out.mkdir(parents=True, exist_ok=True)
    domain = acquire_domain()
    cmd = [sys.executable, "-m", "frog_twin.twin", "--path", path, "--library", str(library), "--seed", str(seed),
           "--domain", str(domain.domain_id), "--out", str(out), *extra]
    sent, stopped = [], []
    watch = None
    with open(out / "twin.log", "w") as f:
        p = subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=domain.env)
    try:
        watch = _Watch(domain.domain_id)
        deadline = time.monotonic() + 600
        while watch.state != watch.Status.STATE_FOLLOWING and p.poll() is None and time.monotonic() < deadline:
            watch.spin(0.05)
        start = watch.sim
        pending = sorted(plan, key=lambda f: f.at)
        while p.poll() is None and (pending or stopped):
            watch.spin(0.02)
            now = time.monotonic()
            for pid, t_cont in [s for s in stopped if s[1] <= now]:
                os.kill(pid, signal.SIGCONT)
                stopped.remove((pid, t_cont))
            if pending and start is not None and watch.sim is not None and watch.sim - start >= pending[0].at:
                f = pending.pop(0)
                pid = node_pid(p.pid, f.target)
                if pid is None:
                    sent.append({"signal": f.label(), "sim_s": watch.sim - start, "pid": None})
                    continue
                os.kill(pid, signal.SIGKILL if f.kind == "kill" else signal.SIGSTOP)
                if f.kind == "sigstop":
                    stopped.append((pid, now + f.duration))
                sent.append({"signal": f.label(), "sim_s": round(watch.sim - start, 2), "pid": pid})
                log(f"  sent {f.label()} to pid {pid} at {watch.sim - start:.1f} s")
        code = p.wait(timeout=900)
    finally:
        for pid, _ in stopped:              # never leave a stopped process behind
            try:
                os.kill(pid, signal.SIGCONT)
            except ProcessLookupError:
                pass
        if p.poll() is None:
            p.terminate()
            p.wait(60)
        if watch is not None:
            watch.graph.close()
        domain.release()
    record = {"path": path, "seed": seed, "plan": [f.label() for f in plan], "sent": sent, "exit": code}
    metrics_file = out / "metrics.json"
    if code != 0 or not metrics_file.exists():
        return dict(record, outcome="failed", stop_reason=f"frog-twin exited {code} (see {out / 'twin.log'})")
    (m,) = json.loads(metrics_file.read_text())
    stale = m["stale_pulses"]       # the twin's audit of its recording (frog_twin.core.state_audit)
    outcome = "failed" if stale or m["unclean_stops"] else "completed" if m["goal_reached"] else "stopped"
    return dict(record, outcome=outcome, stop_reason=m["stop_reason"], pulse_ages=m["pulse_ages"], stale_pulses=stale,
                restarts=m["supervision"]["restarts"], verdicts=m.get("liveness_verdicts", []))


def campaign_plans(paths, seeds, moments=CAMPAIGN_MOMENTS):
    """[(label, path, seed, [signal])]: each signal at each moment of each path, per seed."""
    out = []
    for path in paths:
        for text in SIGNALS:
            base = parse_plan(text)[0]
            for m in moments:
                at = round(m * NOMINAL_TIME_S[path], 1)
                for seed in seeds:
                    f = parse_plan(f"{base.label().split('@')[0]}@{at}" + (f"+{base.duration:g}" if base.duration
                                                                             else ""))[0]
                    out.append((f"{f.label().replace(':', '-').replace('+', '_')}_{path}_s{seed}", path, seed, [f]))
    return out


def table(records) -> str:
    """Markdown: one row per signal over its runs."""
    rows = {}
    for r in records:
        for label in r["plan"]:
            kind = label.split("@")[0]
            row = rows.setdefault(kind, {"runs": 0, "completed": 0, "stopped": 0, "failed": 0, "pulses": 0,
                                         "stale": 0, "oldest": 0.0, "received": 0.0})
            row["runs"] += 1
            row[r["outcome"]] += 1
            ages = r.get("pulse_ages") or {}
            row["pulses"] += ages.get("pulses", 0)
            row["stale"] += len(r.get("stale_pulses", []))
            row["oldest"] = max(row["oldest"], (ages.get("published") or {}).get("max", 0.0))
            row["received"] = max(row["received"], (ages.get("received") or {}).get("max", 0.0))
    lines = ["| signal | runs | completed | stopped with a reason | failed | pulses | pulses on stale state | "
             "oldest state at a pulse [s]: by publish times | by receive times |",
             "|---|---|---|---|---|---|---|---|---|"]
    for kind, r in rows.items():
        lines.append(f"| {kind} | {r['runs']} | {r['completed']} | {r['stopped']} | {r['failed']} | {r['pulses']} | "
                     f"{r['stale']} | {r['oldest']:.3f} | {r['received']:.3f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    from soft_robot_common.graph_watch import exit_status
    return exit_status(_main(argv))


def _main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="frog-outside-faults", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--path", default="line", choices=tuple(NOMINAL_TIME_S), help="path of a single run")
    ap.add_argument("--plan", default=None, help="signals of a single run, e.g. 'kill:tracker_node@6;"
                                                 "sigstop:sim_node@12+3' (AT: simulated s after the planner starts)")
    ap.add_argument("--campaign", action="store_true", help="every signal x 3 moments x --seeds x line and sine")
    ap.add_argument("--seeds", type=int, default=1, help="campaign: seeds per case (default 1)")
    ap.add_argument("--seed", type=int, default=1, help="the first seed")
    ap.add_argument("--library", type=Path, default=None, help="motion library (default: the twin's default)")
    ap.add_argument("--out", type=Path, default=None, help="run folder (default runs/outside_<time>)")
    args = ap.parse_args(argv)
    if args.campaign == (args.plan is not None):
        ap.error("give one of --plan (one run) and --campaign")
    try:
        cases = (campaign_plans(("line", "sine"), [args.seed + i for i in range(args.seeds)]) if args.campaign
                 else [("run", args.path, args.seed, parse_plan(args.plan))])
    except FaultSpecError as exc:
        ap.error(str(exc))
    from frog_twin.twin import ensure_library, repo_root
    library = args.library or ensure_library(repo_root() / "runs" / "library" / "frog_default.npz", 200)
    out = args.out or repo_root() / "runs" / time.strftime("outside_%Y%m%d_%H%M%S")
    records = []
    for k, (label, path, seed, plan) in enumerate(cases, 1):
        done = out / label / "record.json"
        if done.exists():                   # a rerun with the same --out resumes
            records.append(json.loads(done.read_text()))
            continue
        print(f"[{k}/{len(cases)}] {path}, seed {seed}: {'; '.join(f.label() for f in plan)}", flush=True)
        rec = run_with_signals(path, plan, out / label, library, seed)
        done.write_text(json.dumps(rec, indent=1, default=float) + "\n")
        print(f"  -> {rec['outcome']} ({rec['stop_reason'] or 'goal reached'}); pulses on stale state "
              f"{len(rec.get('stale_pulses', []))}", flush=True)
        records.append(rec)
    text = table(records)
    (out / "outside_faults.md").write_text(text + "\n")
    print(text)
    return 0 if all(r["outcome"] != "failed" for r in records) else 1


if __name__ == "__main__":
    sys.exit(main())
