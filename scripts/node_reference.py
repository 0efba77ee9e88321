#!/usr/bin/env python3
"""Each node's topics, services, actions and parameters, as the running node declares them.

Starts every node executable of the workspace at its defaults on an isolated ROS domain, asks
each what ``ros2 node info`` and ``ros2 param describe`` would show (graph queries and the
parameter services), and writes one Markdown block per node into its package's README.md,
between ``<!-- node-reference: NODE -->`` and ``<!-- /node-reference -->``. ``--check``
compares instead and exits 1 naming every block that differs, so a parameter or topic added
in the code and not in the package README fails the tests (tests/test_node_reference.py).

Examples:
  ./dev run python scripts/node_reference.py --check          # are the READMEs current?
  ./dev run python scripts/node_reference.py --write          # regenerate the blocks
  ./dev run python scripts/node_reference.py --print sim_node # one node's block on stdout
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SRC = REPO / "ros_ws" / "src"

#: executable -> (package, module, parameters it needs to start here without hardware and
#: without touching a device path another run may hold; the table shows the code's default)
NODES = {
    "sim_node": ("frog_sim", "frog_sim.nodes.sim_node", {}),
    "rollout_node": ("frog_sim", "frog_sim.nodes.rollout_node", {}),
    "planner_node": ("frog_planner", "frog_planner.nodes.planner_node", {}),
    "camera_sim": ("frog_vision", "frog_vision.nodes.camera_sim", {}),
    "tracker_node": ("frog_vision", "frog_vision.nodes.tracker_node", {}),
    "camera_node": ("frog_vision", "frog_vision.nodes.camera_node", {"source": "{tmp}/video.avi"}),
    "bridge_node": ("frog_bridge", "frog_bridge.nodes.bridge_node", {"port": "{tmp}/no_robot_tty"}),
    "robot_emulator": ("frog_bridge", "frog_bridge.nodes.robot_emulator", {"link_path": "{tmp}/robot_tty"}),
    "recorder": ("frog_logger", "frog_logger.nodes.recorder_node", {"output_dir": "{tmp}/rec", "topics": ["/none"]}),
    "image_preview": ("frog_twin", "frog_twin.nodes.image_preview", {}),
    "kinematics_node": ("softkin_fk", "softkin_fk.nodes.kinematics_node", {}),
    "stepper_driver": ("softkin_fk", "softkin_fk.nodes.stepper_driver", {"port": "{tmp}/no_marlin"}),
    "marlin_emulator": ("softkin_fk", "softkin_fk.nodes.marlin_emulator", {"port_link": "{tmp}/marlin"}),
}
#: what every rclpy node has; said once in the READMEs, not per node
STANDARD_PARAMS = {"use_sim_time", "start_type_description_service"}
STANDARD_TOPICS = {"/parameter_events", "/rosout"}
BEGIN = "<!-- node-reference: {} -->"
END = "<!-- /node-reference -->"
TYPE_NAMES = {1: "bool", 2: "int", 3: "float", 4: "string", 5: "bytes", 6: "bool[]", 7: "int[]",
              8: "float[]", 9: "string[]"}


def _value(v) -> object:
    """A ParameterValue as a Python value."""
    fields = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
              5: "byte_array_value", 6: "bool_array_value", 7: "integer_array_value",
              8: "double_array_value", 9: "string_array_value"}
    return list(getattr(v, fields[v.type])) if v.type >= 5 else getattr(v, fields[v.type], None)


def code_default(node: str, name: str):
    """The default of parameter ``name`` in the node module's ``Param`` tables."""
    import importlib
    from soft_robot_common.parameters import Param
    module = importlib.import_module(NODES[node][1])
    for value in vars(module).values():
        if isinstance(value, list):
            for row in value:
                if isinstance(row, Param) and row.name == name:
                    return row.default
    raise LookupError(f"{node}: no Param {name!r} in {NODES[node][1]}")


def _video(path: str) -> None:
    """A two-frame video file for camera_node to open (no camera on a build machine)."""
    import cv2
    import numpy as np
    out = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
    for _ in range(2):
        out.write(np.zeros((480, 640, 3), np.uint8))
    out.release()


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _default(value, tmp: str) -> str:
    text = repr(value) if not isinstance(value, str) else (f"`{value}`" if value else "''")
    return text.replace(tmp, "<tmp>")


def _range(d) -> str:
    if d.floating_point_range:
        r = d.floating_point_range[0]
        return f"{r.from_value:g} .. {r.to_value:g}"
    if d.integer_range:
        r = d.integer_range[0]
        return f"{r.from_value} .. {r.to_value}"
    return ""


def _ends(names_types, tmp) -> list[tuple[str, str]]:
    return sorted((name.replace(tmp, "<tmp>"), ", ".join(t.split("/")[-1] for t in types))
                  for name, types in names_types)


def block(info: dict) -> str:
    """The Markdown of one node, from what :func:`query` returned."""
    lines = [f"#### `{info['name']}`", ""]
    ends = [("publishes", info["publishers"]), ("subscribes", info["subscriptions"]),
            ("service", info["services"]), ("client of", info["clients"]),
            ("action server", info["actions"])]
    if any(rows for _, rows in ends):
        lines += ["| | name | type |", "|---|---|---|"]
        for kind, rows in ends:
            lines += [f"| {kind} | `{n}` | {t} |" for n, t in rows]
        lines.append("")
    lines += ["| parameter | type | default | range | live | description |",
              "|---|---|---|---|---|---|"]
    lines += [f"| `{p['name']}` | {p['type']} | {_cell(p['default'])} | {p['range']} | "
              f"{'yes' if p['live'] else ''} | {_cell(p['description'])} |" for p in info["params"]]
    return "\n".join(lines)


def query(probe, fq: str, tmp: str) -> dict:
    """Topics, services, actions and parameters of the running node ``fq`` (``/name``)."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters
    from rclpy.action import get_action_server_names_and_types_by_node
    import rclpy

    name = fq.lstrip("/")
    node = probe

    def call(srv_type, service, request):
        client = node.create_client(srv_type, f"{fq}/{service}")
        if not client.wait_for_service(timeout_sec=60.0):
            raise RuntimeError(f"{fq}: no {service} service within 60 s")
        # a response can be lost while discovery settles, and kinematics_node answers only once
        # its start-up solves are done (about a minute on a loaded 2-core machine)
        deadline = time.monotonic() + 300.0
        while time.monotonic() < deadline:
            future = client.call_async(request)
            rclpy.spin_until_future_complete(node, future, timeout_sec=5.0)
            if future.done():
                node.destroy_client(client)
                return future.result()
        raise RuntimeError(f"{fq}: {service} did not answer within 300 s")

    names = sorted(n for n in call(ListParameters, "list_parameters", ListParameters.Request()).result.names
                   if n not in STANDARD_PARAMS)
    descriptors = call(DescribeParameters, "describe_parameters",
                       DescribeParameters.Request(names=names)).descriptors
    values = call(GetParameters, "get_parameters", GetParameters.Request(names=names)).values
    overridden = NODES[name][2]
    params = [{"name": n, "type": TYPE_NAMES.get(d.type, "?"),
               "default": _default(code_default(name, n) if n in overridden else _value(v), tmp),
               "range": _range(d), "live": not d.read_only, "description": d.description}
              for n, d, v in zip(names, descriptors, values)]
    # graph entries settle after discovery, endpoint by endpoint and late under load: ask until
    # three answers a second apart agree and name some endpoint (every node here has one), for
    # at most 60 s
    previous, same = None, 0
    for _ in range(60):
        hidden = re.compile(r"/_action/|/(describe|get|list|set)_parameters(_atomically)?$|"
                            r"/get_parameter_types$|/get_type_description$")
        current = {
            "publishers": [e for e in _ends(node.get_publisher_names_and_types_by_node(name, "/"), tmp)
                           if e[0] not in STANDARD_TOPICS and not hidden.search(e[0])],
            "subscriptions": [e for e in _ends(node.get_subscriber_names_and_types_by_node(name, "/"), tmp)
                              if e[0] not in STANDARD_TOPICS and not hidden.search(e[0])],
            "services": [e for e in _ends(node.get_service_names_and_types_by_node(name, "/"), tmp)
                         if not hidden.search(e[0])],
            "clients": [e for e in _ends(node.get_client_names_and_types_by_node(name, "/"), tmp)
                        if not hidden.search(e[0])],
            "actions": _ends(get_action_server_names_and_types_by_node(node, name, "/"), tmp),
        }
        same = same + 1 if current == previous else 0
        if same >= 2 and any(current.values()):
            break
        previous = current
        rclpy.spin_once(node, timeout_sec=1.0)
    return {"name": name, "params": params, **current}


def collect(names: list[str], expected: dict[str, str | None] | None = None) -> dict[str, str]:
    """Start ``names``, query each, stop them; node -> Markdown block.

    With ``expected`` (the README blocks, for --check), a node whose block differs is asked
    again for up to 60 s before its answer is kept: under load a node's publishers can reach the
    graph seconds after its subscriptions, and a node at its defaults only gains endpoints, so a
    real difference persists and is still reported.
    """
    import rclpy
    from soft_robot_common.processes import NodeProcess, acquire_domain, ros_args

    domain = acquire_domain()
    tmp = tempfile.mkdtemp(prefix="node_reference_")
    procs = []
    _video(f"{tmp}/video.avi")
    try:
        for n in names:
            params = {k: (v.replace("{tmp}", tmp) if isinstance(v, str) else v)
                      for k, v in NODES[n][2].items()}
            procs.append(NodeProcess([n, *ros_args(params)], domain.env, Path(tmp) / f"{n}.log", n))
        import os
        os.environ.update(domain.env)
        rclpy.init()
        probe = rclpy.create_node("node_reference_probe")
        out = {}
        try:
            for n, proc in zip(names, procs):
                deadline = time.monotonic() + 120
                while ("/" + n) not in {"/" + x for x, _ in probe.get_node_names_and_namespaces()}:
                    if not proc.running():
                        raise RuntimeError(f"{n} exited at its defaults:\n{proc.log_text()[-2000:]}")
                    if time.monotonic() > deadline:
                        raise RuntimeError(f"{n} did not join the graph within 120 s")
                    rclpy.spin_once(probe, timeout_sec=0.2)
                again = time.monotonic() + 60
                out[n] = block(query(probe, "/" + n, tmp))
                while expected and out[n] != expected.get(n) and time.monotonic() < again:
                    out[n] = block(query(probe, "/" + n, tmp))
                print(f"  {n}", file=sys.stderr)
        finally:
            probe.destroy_node()
            rclpy.shutdown()
        return out
    finally:
        for p in procs:
            p.stop()
        domain.release()


def readme(node: str) -> Path:
    return SRC / NODES[node][0] / "README.md"


def current_block(text: str, node: str) -> str | None:
    m = re.search(re.escape(BEGIN.format(node)) + r"\n(.*?)\n" + re.escape(END), text, re.S)
    return m.group(1) if m else None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 2)[2],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="compare with the package READMEs; exit 1 on a difference")
    mode.add_argument("--write", action="store_true", help="rewrite the blocks in the package READMEs")
    mode.add_argument("--print", action="store_true", help="print the blocks")
    ap.add_argument("nodes", nargs="*", help=f"nodes (default all: {', '.join(NODES)})")
    args = ap.parse_args(argv)
    unknown = [n for n in args.nodes if n not in NODES]
    if unknown:
        ap.error(f"unknown node(s) {', '.join(unknown)}; known: {', '.join(NODES)}")
    names = args.nodes or list(NODES)
    expected = {n: current_block(readme(n).read_text(), n) if readme(n).exists() else None
                for n in names} if args.check else None
    blocks = collect(names, expected)
    if args.print:
        print("\n\n".join(blocks.values()))
        return 0
    stale = []
    for n, new in blocks.items():
        path = readme(n)
        text = path.read_text() if path.exists() else ""
        old = current_block(text, n)
        if old == new:
            continue
        if args.check:
            where = "no block" if old is None else "differs"
            diff = "" if old is None else "\n".join(difflib.unified_diff(
                old.splitlines(), new.splitlines(), "README", "running node", lineterm="", n=0))
            stale.append(f"{path.relative_to(REPO)}: {n}: {where}\n{diff}")
        elif old is None:
            raise SystemExit(f"{path.relative_to(REPO)} has no '{BEGIN.format(n)}' ... '{END}' block: "
                             f"add the two marker lines where {n}'s reference belongs")
        else:
            begin = BEGIN.format(n)
            path.write_text(text.replace(f"{begin}\n{old}\n{END}", f"{begin}\n{new}\n{END}"))
            print(f"wrote {n} into {path.relative_to(REPO)}")
    if stale:
        print("\n\n".join(stale) + "\n\nregenerate: ./dev run python scripts/node_reference.py --write",
              file=sys.stderr)
        return 1
    if args.check:
        print(f"{len(blocks)} node references current")
    return 0


if __name__ == "__main__":
    sys.exit(main())
