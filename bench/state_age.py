"""How old is the state behind each limb pulse? The twin's loop timing, quiet and beside busy processes.

Runs ``frog-twin`` on a path (default the line, then the sine) once on the machine as it is and
once beside ``--busy`` processes that each spin a core, and reads every pulse of each recording:
the age of its state when the bridge wrote it (``frog/bridge/sent`` state_age: capture of the
measurement -> the write, which is what ``max_state_age_s`` bounds), the tracker's
capture-to-publish latency and frame rate, and the planner's refusals for an old state. It
prints medians, the 99th percentile and the maximum, each as a ratio of the bound, and CPU time
beside wall time. docs/faults.md derives the default bound from these figures.

    ./dev bench state_age                       # line and sine, quiet and beside 2 busy processes
    ./dev bench state_age --paths line --busy 0
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from frog_common.state_age import MAX_STATE_AGE_S
from frog_logger.core.log_files import read_messages


def busy(count: int) -> list:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(count)]


def run(path: str, out: Path, library: str | None, seed: int) -> dict:
    cmd = [sys.executable, "-m", "frog_twin.twin", "--path", path, "--out", str(out), "--seed", str(seed)]
    if library:
        cmd += ["--library", library]
    t0, c0 = time.monotonic(), resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(cmd, capture_output=True, text=True)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(r.stdout[-2000:] + r.stderr[-2000:])
    (m,) = json.loads((out / "metrics.json").read_text())
    claimed, ticks, latency, frames, waited = [], [], [], [], 0
    for f in m["recording"]:
        for topic, _, msg in read_messages(f, ["/frog/bridge/sent", "/diagnostics", "/frog/planner/status"]):
            if topic == "/frog/bridge/sent" and len(msg.limbs):
                claimed.append(msg.state_age)
            elif topic == "/frog/planner/status":
                waited += msg.state == 3 and "old" in msg.message
                if msg.state in (1, 3) and np.isfinite(msg.state_age):      # following or waiting: each tick
                    ticks.append(msg.state_age)
            else:
                for st in msg.status:
                    if st.name.startswith("tracker_node: tag"):
                        v = {kv.key: kv.value for kv in st.values}
                        if v.get("latency_ms", "nan") != "nan":
                            latency.append(float(v["latency_ms"]) * 1e-3)
                            frames.append(float(v["frames"]))
    wall = time.monotonic() - t0
    cpu = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
    rate = (frames[-1] - frames[0]) / (m["wall_time_s"]) if len(frames) > 1 else float("nan")
    return {"claimed": np.array(claimed), "ticks": np.array(ticks), "latency": np.array(latency), "rate": rate,
            "waited": waited, "goal": m["goal_reached"], "wall": wall, "cpu": cpu}


def line(label: str, r: dict) -> str:
    a = r["claimed"]
    q = np.quantile(a, [0.5, 0.99]) if len(a) else [np.nan, np.nan]
    return (f"{label:24s} pulses {len(a):3d}  state age median {q[0]:.3f} s ({q[0] / MAX_STATE_AGE_S:.2f} of the "
            f"bound), p99 {q[1]:.3f} ({q[1] / MAX_STATE_AGE_S:.2f}), max {a.max() if len(a) else np.nan:.3f} "
            f"({(a.max() if len(a) else np.nan) / MAX_STATE_AGE_S:.2f}); at the planner's ticks median "
            f"{np.median(r['ticks']):.3f} s, p99 {np.quantile(r['ticks'], 0.99):.3f} s; tracker latency median "
            f"{np.median(r['latency']) * 1e3:.0f} ms at {r['rate']:.1f} frames/s; refused for age {r['waited']}; "
            f"goal {'yes' if r['goal'] else 'no'}; wall {r['wall']:.0f} s, CPU {r['cpu']:.0f} s")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--paths", nargs="+", default=["line", "sine"])
    ap.add_argument("--busy", type=int, default=2, help="busy processes of the loaded run (0: quiet only)")
    ap.add_argument("--library", default=None)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    print(f"max_state_age_s {MAX_STATE_AGE_S} s; camera frame interval {1 / 30:.3f} s (30 Hz); "
          f"{os.cpu_count()} cores", flush=True)
    pooled = {"quiet": [], "loaded": []}
    ticks = {"quiet": [], "loaded": []}
    with tempfile.TemporaryDirectory() as tmp:
        for path in args.paths:
            for cond in ("quiet", "loaded") if args.busy else ("quiet",):
                procs = busy(args.busy) if cond == "loaded" else []
                try:
                    r = run(path, Path(tmp) / f"{path}_{cond}", args.library, args.seed)
                finally:
                    for p in procs:
                        p.kill()
                        p.wait()
                pooled[cond].append(r["claimed"])
                ticks[cond].append(r["ticks"])
                print(line(f"{path}, {cond}" + (f" ({args.busy} busy)" if procs else ""), r), flush=True)
    for cond, runs in pooled.items():
        if runs:
            a = np.concatenate(runs)
            t = np.concatenate(ticks[cond])
            print(f"pooled {cond}: {len(a)} pulses, state age at the write median {np.median(a):.3f} s, p99 "
                  f"{np.quantile(a, 0.99):.3f} s, max {a.max():.3f} s = {a.max() / MAX_STATE_AGE_S:.2f} of the bound; "
                  f"at {len(t)} planner ticks median {np.median(t):.3f} s, p99 {np.quantile(t, 0.99):.3f} s, "
                  f"{np.mean(t > MAX_STATE_AGE_S) * 100:.1f} % over the bound")
    return 0


if __name__ == "__main__":
    sys.exit(main())
