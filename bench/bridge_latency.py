"""Bridge latency: primitive message in -> first serial byte out, and Q line in -> frog/imu out.

Real processes on an isolated ROS domain and a real pty: this process publishes
Primitive H (one line, ``h 1``) and times the first byte arriving on the pty's controller
side; it writes ``Central: Q ...`` lines and times the Imu message arriving. Both clocks are
this process's ``time.perf_counter``. The same hops are timed through a bare rclpy process
(bench/bridge_baseline_node.py: subscribe -> os.write, read -> publish, no checks) running
at the same time on its own pty and namespace, samples alternating between the two, so both
see the same machine load; the ratio says what the bridge's framing, protection and
scheduling cost.
Target: median <= 2 ms, p99 <= 5 ms for both directions.

    ./dev bench bridge_latency [--samples 300] [--rate 10]
"""

import argparse
import os
import select
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from ros_harness import NodeProcess, acquire_domain, open_pty_pair, ros_args  # noqa: E402
from soft_robot_common.graph_watch import GraphWatch  # noqa: E402


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def percentile(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q / 100 * (len(xs) - 1))))]


class Probe(GraphWatch):
    """The bench's graph watch, spun by a thread of its own: the Imu callback stamps arrivals."""

    def __init__(self, domain_id, namespaces):
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu
        from soft_robot_interfaces.msg import Primitive
        super().__init__(domain_id, "bench_probe")
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.Primitive = Primitive
        self.namespaces = namespaces
        self.pubs = {ns: self.node.create_publisher(Primitive, f"{ns}/frog/primitive", qos) for ns in namespaces}
        self.imu_at = {ns: None for ns in namespaces}
        self.imu_event = {ns: threading.Event() for ns in namespaces}
        for ns in namespaces:
            self.node.create_subscription(Imu, f"{ns}/frog/imu", lambda m, ns=ns: self._on_imu(ns), qos)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        from rclpy.executors import ExternalShutdownException
        try:
            while self.context.ok():
                self.executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            pass

    def _on_imu(self, ns):
        self.imu_at[ns] = time.perf_counter()
        self.imu_event[ns].set()

    def wait_matched(self, timeout=30):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if all(self.pubs[ns].get_subscription_count() >= 1 and self.node.count_publishers(f"{ns}/frog/imu") >= 1
                   for ns in self.namespaces):
                return
            time.sleep(0.05)
        raise TimeoutError("the nodes under test did not subscribe/publish in time")

    def primitive(self):
        m = self.Primitive(id=7, name="H")
        m.header.stamp = self.node.get_clock().now().to_msg()
        return m

    def close(self):
        self._rclpy.shutdown(context=self.context)
        self.thread.join(2)


def measure(probe, controllers, samples, rate):
    """{ns: (primitive -> first byte latencies, Q line -> Imu latencies)} in ms; targets alternate."""
    out = {ns: ([], []) for ns in controllers}
    period = 1.0 / rate
    line = b"Central: Q 0.9239 0.0000 0.0000 0.3827\r\n"
    for i in range(samples + 10):
        for ns, controller in controllers.items():
            while select.select([controller], [], [], 0)[0]:
                os.read(controller, 4096)          # the rest of a line
            msg = probe.primitive()
            t0 = time.perf_counter()
            probe.pubs[ns].publish(msg)
            if select.select([controller], [], [], 1.0)[0]:
                t1 = time.perf_counter()
                os.read(controller, 4096)
                if i >= 10:
                    out[ns][0].append((t1 - t0) * 1e3)
            time.sleep(period / 4)
            probe.imu_event[ns].clear()
            t0 = time.perf_counter()
            os.write(controller, line)
            if probe.imu_event[ns].wait(1.0) and i >= 10:
                out[ns][1].append((probe.imu_at[ns] - t0) * 1e3)
            time.sleep(period / 4)
    return out


def start(kind, domain, tmp):
    controller, device, path = open_pty_pair()
    if kind == "bridge_node":
        # protection off so the bench can send at `rate` (the checks still run on every command)
        argv = ["bridge_node", *ros_args({"port": path, "settle_s": 0.1, "stall_timeout_s": 0.0,
                                          "min_limb_interval_s": 0.0, "max_duty_cycle": 1.0},
                                         remap={"__ns": "/" + kind})]
        ready = "link ready"
    else:
        argv = [sys.executable, str(ROOT / "bench" / "bridge_baseline_node.py"), path,
                *ros_args(remap={"__ns": "/" + kind})]
        ready = "baseline ready"
    proc = NodeProcess(argv, domain.env, Path(tmp) / f"{kind}.log", kind)
    proc.wait_for_log(ready, 30)
    return proc, controller, device


def run(domain, tmp, samples, rate):
    """Both processes at once on their own pty and namespace; samples alternate between them."""
    kinds = ("baseline", "bridge_node")
    started = {}
    try:
        for kind in kinds:
            started[kind] = start(kind, domain, tmp)
        probe = Probe(domain.domain_id, ["/" + k for k in kinds])
        probe.wait_matched()
        time.sleep(0.5)
        controllers = {"/" + k: started[k][1] for k in kinds}
        for c in controllers.values():
            while select.select([c], [], [], 0)[0]:
                os.read(c, 4096)               # the bridge's "p 80"
        cpu0 = {k: cpu_seconds(started[k][0].pid) for k in kinds}
        wall0 = time.perf_counter()
        lat = measure(probe, controllers, samples, rate)
        wall = time.perf_counter() - wall0
        cpu = {k: cpu_seconds(started[k][0].pid) - cpu0[k] for k in kinds}
        probe.close()
    finally:
        for proc, controller, device in started.values():
            proc.stop()
            os.close(controller)
            os.close(device)
    return {k: (*lat["/" + k], cpu[k], wall) for k in kinds}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=300, help="timed round trips per direction and process")
    ap.add_argument("--rate", type=float, default=10.0, help="primitives (and Q lines) per second")
    ap.add_argument("--plot", default=str(ROOT / "runs" / "bench" / "bridge_latency.png"),
                    help="latency distributions as PNG ('' = none)")
    args = ap.parse_args()
    domain = acquire_domain()
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        results = run(domain, tmp, args.samples, args.rate)
    domain.release()
    load1 = os.getloadavg()
    print(f"\nload average (1 min) {load0[0]:.2f} before, {load1[0]:.2f} after; {os.cpu_count()} cores")
    print(f"{'process':<12} {'direction':<26} {'n':>4} {'median ms':>10} {'p99 ms':>8} {'max ms':>8} "
          f"{'x baseline':>11}")
    base = {}
    for kind in ("baseline", "bridge_node"):
        out_lat, in_lat, cpu, wall = results[kind]
        for label, lat in (("primitive -> first byte", out_lat), ("Q line -> frog/imu", in_lat)):
            med, p99 = statistics.median(lat), percentile(lat, 99)
            ratio = f"{med / base[label]:.2f}" if kind == "bridge_node" else "1.00"
            base.setdefault(label, med)
            print(f"{kind:<12} {label:<26} {len(lat):>4} {med:>10.3f} {p99:>8.3f} {max(lat):>8.3f} {ratio:>11}")
        n = 2 * len(out_lat)
        print(f"{kind:<12} CPU {cpu:.2f} s over {wall:.1f} s wall ({100 * cpu / wall:.1f} % of a core; "
              f"{1e3 * cpu / max(n, 1):.2f} ms CPU per message incl. idle timers)")
    med_out, med_in = statistics.median(results["bridge_node"][0]), statistics.median(results["bridge_node"][1])
    p99_out, p99_in = percentile(results["bridge_node"][0], 99), percentile(results["bridge_node"][1], 99)
    ok = med_out <= 2 and med_in <= 2 and p99_out <= 5 and p99_in <= 5
    print(f"\ntarget median <= 2 ms and p99 <= 5 ms both ways: {'met' if ok else 'NOT met'}")
    if args.plot:
        plot(results, Path(args.plot))
        print(f"plot: {args.plot}")


def plot(results, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, idx, title in ((axes[0], 0, "primitive -> first serial byte"), (axes[1], 1, "Q line -> frog/imu")):
        for kind, (out_lat, in_lat, _cpu, _wall) in results.items():
            lat = np.sort([out_lat, in_lat][idx])
            ax.plot(lat, np.arange(1, len(lat) + 1) / len(lat), label=kind)
        ax.axvline(2.0, color="grey", ls=":", label="median target")
        ax.axvline(5.0, color="grey", ls="--", label="p99 target")
        ax.set_xscale("log")
        ax.set_xlabel("latency [ms]")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("fraction of samples")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
