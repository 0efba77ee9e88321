"""``frog-log``: inspect, export, check and recover MCAP recordings of the recorder node."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from frog_logger.core.log_files import LogFileError, check, export_csv, recover, summarize

EPILOG = """examples:
  frog-log info runs/rec/frog_000.mcap            topics, types, counts, duration
  frog-log export runs/rec/frog_000.mcap -o csv/   one CSV per topic, flattened fields
  frog-log export FILE -o csv/ -t /frog/sim/odom   only some topics
  frog-log check runs/rec/*.mcap                   decode every message (exit 1 on failure)
  frog-log recover crashed_000.mcap fixed.mcap     salvage a file left by a killed recorder
"""


def _fmt_time(ns):
    if ns is None:
        return "-"
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ns / 1e9)) + f".{ns % 10**9 // 10**6:03d}"


def cmd_info(args) -> int:
    for path in args.files:
        s = summarize(path)
        print(f"file:      {s.path}")
        print(f"complete:  {'yes' if s.complete else 'NO (not closed cleanly; run frog-log recover)'}")
        print(f"start:     {_fmt_time(s.start_ns)}")
        print(f"end:       {_fmt_time(s.end_ns)}")
        print(f"duration:  {s.duration_s:.3f} s")
        print(f"messages:  {s.message_count}")
        rec = s.metadata.get("recording", {})
        if rec:
            print(f"host:      {rec.get('host', '-')}   split index: {rec.get('split_index', '-')}")
        width = max([len(t) for t in s.topics] + [5])
        print(f"{'topic':<{width}}  {'count':>8}  {'rate_hz':>8}  type")
        for name in sorted(s.topics):
            t = s.topics[name]
            span = ((t.last_ns - t.first_ns) / 1e9) if t.message_count > 1 else 0.0
            rate = (t.message_count - 1) / span if span > 0 else 0.0
            print(f"{name:<{width}}  {t.message_count:>8}  {rate:>8.1f}  {t.type_name}")
        print()
    return 0


def cmd_export(args) -> int:
    written = export_csv(args.file, args.out, args.topic or None)
    if not written:
        print(f"frog-log: no messages to export from {args.file}", file=sys.stderr)
        return 1
    for topic, path in written.items():
        print(f"{topic} -> {path}")
    return 0


def cmd_check(args) -> int:
    bad = 0
    for path in args.files:
        r = check(path)
        status = "OK" if r.ok else "FAILED"
        print(f"{status}  {r.path}: {r.decoded} messages decoded, {len(r.failures)} problems")
        for f in r.failures:
            print(f"   - {f}")
        bad += not r.ok
    return 1 if bad else 0


def cmd_recover(args) -> int:
    n, clean = recover(args.file, args.out)
    note = "input was complete" if clean else "input was truncated; partial last chunk dropped"
    print(f"recovered {n} messages into {args.out} ({note})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="frog-log", description=__doc__, epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("info", help="topics, types, counts, time span")
    s.add_argument("files", nargs="+", type=Path)
    s.set_defaults(func=cmd_info)
    s = sub.add_parser("export", help="per-topic CSV with flattened fields")
    s.add_argument("file", type=Path)
    s.add_argument("-o", "--out", type=Path, required=True, help="output folder for CSV files")
    s.add_argument("-t", "--topic", action="append", help="topic to export (repeatable)")
    s.set_defaults(func=cmd_export)
    s = sub.add_parser("check", help="decode every message; exit 1 on any failure")
    s.add_argument("files", nargs="+", type=Path)
    s.set_defaults(func=cmd_check)
    s = sub.add_parser("recover", help="rewrite a crashed recording as a complete file")
    s.add_argument("file", type=Path)
    s.add_argument("out", type=Path)
    s.set_defaults(func=cmd_recover)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (LogFileError, OSError) as exc:
        print(f"frog-log: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
