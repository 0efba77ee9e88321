"""Bridge latency: primitive message in -> first serial byte out, and Q line in -> frog/imu out.

Real processes on an isolated ROS domain and a real pty: this process publishes
Primitive H (one line, ``h 1``) and times the first byte arriving on the pty's controller
side; it writes ``Central: Q ...`` lines and times the Imu message arriving. Both clocks are
this process's ``time.perf_counter``. The same hops are timed through a bare rclpy process
(bench/bridge_baseline_node.py: subscribe -> os.write, read -> publish, no checks) in the
same run; the ratio says what the bridge's framing, protection and scheduling cost.
Target (issue 13): median <= 2 ms, p99 <= 5 ms for both directions.

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


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def percentile(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q / 100 * (len(xs) - 1))))]


class Probe:
    def __init__(self, domain_id):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import Imu
        from soft_robot_interfaces.msg import Primitive
        self.rclpy = rclpy
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain_id)
        self.node = rclpy.create_node("bench_probe", context=self.ctx)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.Primitive = Primitive
        self.pub = self.node.create_publisher(Primitive, "/frog/primitive", qos)
        self.imu_at = None
        self.imu_event = threading.Event()
        self.node.create_subscription(Imu, "/frog/imu", self._on_imu, qos)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        from rclpy.executors import ExternalShutdownException
        try:
            while self.ctx.ok():
                self.ex.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            pass

    def _on_imu(self, msg):
        self.imu_at = time.perf_counter()
        self.imu_event.set()

    def wait_matched(self, timeout=30):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.pub.get_subscription_count() >= 1 and self.node.count_publishers("/frog/imu") >= 1:
                return
            time.sleep(0.05)
        raise TimeoutError("the node under test did not subscribe/publish in time")

    def primitive(self):
        m = self.Primitive(id=7, name="H")
        m.header.stamp = self.node.get_clock().now().to_msg()
        return m

    def close(self):
        self.rclpy.shutdown(context=self.ctx)
        self.thread.join(2)


def measure(probe, controller, samples, rate):
    """(primitive -> first byte latencies, Q line -> Imu latencies) in ms."""
    out_lat, in_lat = [], []
    period = 1.0 / rate
    line = b"Central: Q 0.9239 0.0000 0.0000 0.3827\r\n"
    for i in range(samples + 10):
        # drain anything pending (the rest of a line)
        while select.select([controller], [], [], 0)[0]:
            os.read(controller, 4096)
        msg = probe.primitive()
        t0 = time.perf_counter()
        probe.pub.publish(msg)
        if select.select([controller], [], [], 1.0)[0]:
            t1 = time.perf_counter()
            os.read(controller, 4096)
            if i >= 10:
                out_lat.append((t1 - t0) * 1e3)
        time.sleep(period / 2)
        probe.imu_event.clear()
        t0 = time.perf_counter()
        os.write(controller, line)
        if probe.imu_event.wait(1.0) and i >= 10:
            in_lat.append((probe.imu_at - t0) * 1e3)
        time.sleep(period / 2)
    return out_lat, in_lat


def run(kind, domain, tmp, samples, rate):
    controller, device, path = open_pty_pair()
    if kind == "bridge_node":
        # protection off so the bench can send at `rate` (the checks still run on every command)
        argv = ["bridge_node", *ros_args({"port": path, "settle_s": 0.1, "stall_timeout_s": 0.0,
                                          "min_limb_interval_s": 0.0, "max_duty_cycle": 1.0})]
        ready = "link ready"
    else:
        argv = [sys.executable, str(ROOT / "bench" / "bridge_baseline_node.py"), path]
        ready = "baseline ready"
    proc = NodeProcess(argv, domain.env, Path(tmp) / f"{kind}.log", kind)
    try:
        proc.wait_for_log(ready, 30)
        probe = Probe(domain.domain_id)
        probe.wait_matched()
        time.sleep(0.5)
        while select.select([controller], [], [], 0)[0]:
            os.read(controller, 4096)          # the bridge's "p 80"
        cpu0, wall0 = cpu_seconds(proc.pid), time.perf_counter()
        out_lat, in_lat = measure(probe, controller, samples, rate)
        cpu, wall = cpu_seconds(proc.pid) - cpu0, time.perf_counter() - wall0
        probe.close()
    finally:
        proc.stop()
        for fd in (controller, device):
            os.close(fd)
    return out_lat, in_lat, cpu, wall


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=300, help="timed round trips per direction and process")
    ap.add_argument("--rate", type=float, default=10.0, help="primitives (and Q lines) per second")
    args = ap.parse_args()
    domain = acquire_domain()
    load0 = os.getloadavg()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("baseline", "bridge_node"):
            results[kind] = run(kind, domain, tmp, args.samples, args.rate)
            print(f"{kind}: done", flush=True)
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


if __name__ == "__main__":
    main()
