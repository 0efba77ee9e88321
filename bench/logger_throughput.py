"""Logger throughput: the highest Odometry rate the recorder keeps with zero loss.

A publisher process sends Odometry (reliable, depth 1000) at a fixed rate for a few
seconds to the recorder process; the MCAP is counted afterwards. The same rates are sent
to a plain rclpy subscriber that deserialises and counts (the executor's ceiling on this
machine), measured in the same run. Target: >= 5,000 msg/s with zero loss.

    ./dev bench logger_throughput [--rates 3000 5000 7000 9000] [--seconds 5] [--repeats 3]
"""

import argparse
import re
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from ros_harness import NodeProcess, acquire_domain, ros_args  # noqa: E402

from frog_logger.core.log_files import summarize  # noqa: E402

TOOLS = ROOT / "tests" / "tools"


def run_once(domain, workdir: Path, rate: int, seconds: float, target: str, tag: str):
    """Send rate*seconds messages; return (sent, received, achieved publish rate)."""
    count = int(rate * seconds)
    if target == "recorder":
        out = workdir / tag
        sub = NodeProcess(["recorder", *ros_args({"output_dir": str(out), "file_prefix": "b",
                                                   "topics": ["/odom"]})],
                          domain.env, workdir / f"{tag}_sub.log", "recorder")
        sub.wait_for_log("recording topics", 30)
    else:
        sub = NodeProcess([sys.executable, str(TOOLS / "count_subscriber.py"), "/odom"],
                          domain.env, workdir / f"{tag}_sub.log", "counter")
        sub.wait_for_log("subscribed", 30)
    pub = NodeProcess([sys.executable, str(TOOLS / "odom_publisher.py"), "--rate", str(rate),
                       "--count", str(count), "--linger", "3"],
                      domain.env, workdir / f"{tag}_pub.log", "publisher")
    m = pub.wait_for_log(r"done (\d+) messages in ([\d.]+) s \(([\d.]+) msg/s\)",
                         timeout=seconds * 10 + 60)
    achieved = float(m.group(3))
    pub.wait(30)
    sub.stop()
    if target == "recorder":
        received = sum(summarize(f).topics.get("/odom").message_count
                       for f in sorted((workdir / tag).glob("b_*.mcap")))
    else:
        received = int(re.search(r"received (\d+)", sub.log_text()).group(1))
    pub.stop()
    return count, received, achieved


def main():
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", type=int, nargs="+", default=[2000, 3000, 5000, 8000, 10000, 12000])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    domain = acquire_domain()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for target in ("recorder", "rclpy_counter"):
            for rate in args.rates:
                runs = []
                for r in range(args.repeats):
                    sent, got, achieved = run_once(domain, Path(tmp), rate, args.seconds, target,
                                                   f"{target}_{rate}_{r}")
                    runs.append((sent, got, achieved))
                    print(f"{target:>13} rate {rate:>6} run {r}: sent {sent} received {got} "
                          f"({100 * got / sent:.2f} %), publisher achieved {achieved:.0f} msg/s",
                          flush=True)
                results[(target, rate)] = runs
    domain.release()

    print("\nmedian over repeats (zero loss = every message of every repeat received)")
    print(f"{'rate msg/s':>10} | {'recorder recv %':>15} {'lossless':>8} | "
          f"{'rclpy counter recv %':>20} {'lossless':>8} | publisher achieved msg/s")
    best = {"recorder": 0.0, "rclpy_counter": 0.0}
    for rate in args.rates:
        row = []
        for target in ("recorder", "rclpy_counter"):
            runs = results[(target, rate)]
            pct = statistics.median(100 * g / s for s, g, _ in runs)
            lossless = all(g == s for s, g, _ in runs)
            ach = statistics.median(a for *_, a in runs)
            if lossless:
                best[target] = max(best[target], ach)
            row.append((pct, lossless, ach))
        print(f"{rate:>10} | {row[0][0]:>15.2f} {str(row[0][1]):>8} | {row[1][0]:>20.2f} "
              f"{str(row[1][1]):>8} | {row[0][2]:.0f}")
    ratio = best["recorder"] / best["rclpy_counter"] if best["rclpy_counter"] else float("nan")
    print(f"\nrecorder sustained zero-loss throughput: {best['recorder']:.0f} msg/s "
          f"(target >= 5000)")
    print(f"plain rclpy subscriber (deserialising) zero-loss: {best['rclpy_counter']:.0f} msg/s")
    print(f"ratio recorder / plain rclpy subscriber: {ratio:.2f}")


if __name__ == "__main__":
    main()
