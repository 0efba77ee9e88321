"""A robot's node graph as data: one YAML file -> the processes :mod:`.processes` starts.

The file is an rcl parameter file (``<node>: ros__parameters: {...}``), so a ROS user can
pass it whole to any of its nodes with ``--params-file``. rcl allows no other key beside
``ros__parameters``, so what starts the nodes sits in the parameters of a pseudo-node
``graph`` that no process runs (rcl reads it as the parameters of a node nobody starts;
every real node ignores it)::

    graph:
      ros__parameters:
        robot: frog
        clock_source: [sim_node]      # in sim mode every other node gets use_sim_time
        order: [recorder, sim_node, ...]
        sim_node: {package: frog_sim, executable: sim_node, tag: sim}
        camera_node: {package: frog_vision, executable: camera_node, tag: real,
                      remaps: ["camera/image_raw:=camera/image_raw"]}
    sim_node:
      ros__parameters:
        publish_clock: true

``tag`` is ``sim`` (only in the twin), ``real`` (only on the real robot) or ``both``.
:func:`load_graph` picks a mode's nodes, applies per-run overrides and returns
:class:`GraphNode` objects that start themselves and print their ``ros2 run`` line.
Pure Python (PyYAML), no rclpy.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Optional

from .processes import NodeProcess, ros_args

MODES = ("sim", "real")
TAGS = ("sim", "real", "both")
GRAPH_KEY = "graph"


class GraphError(ValueError):
    """A graph file or an override that cannot be used (the message names the problem)."""


@dataclass
class GraphNode:
    """One node of a graph in one mode: what to run and with which parameters and remaps."""

    name: str
    package: str
    executable: str
    tag: str
    parameters: dict = field(default_factory=dict)
    remaps: dict = field(default_factory=dict)

    def ros_arguments(self) -> list[str]:
        node_name = self.name if self.name != self.executable else None
        return ros_args(self.parameters, self.remaps, node_name)

    def argv(self) -> list[str]:
        """The executable (on PATH in this workspace) and its ``--ros-args``."""
        return [self.executable, *self.ros_arguments()]

    def ros2_run(self) -> str:
        """The equivalent ``ros2 run <package> <executable> --ros-args ...`` command line."""
        return " ".join(_shell_word(w) for w in ["ros2", "run", self.package, self.executable,
                                                  *self.ros_arguments()])

    def start(self, env: dict, log_dir: Path, label: Optional[str] = None) -> NodeProcess:
        label = label or self.name
        return NodeProcess(self.argv(), env, Path(log_dir) / f"{label}.log", label)


@dataclass
class Graph:
    """The nodes of one mode, in start order."""

    robot: str
    mode: str
    nodes: list

    def __iter__(self):
        return iter(self.nodes)

    def __contains__(self, name: str) -> bool:
        return any(n.name == name for n in self.nodes)

    def __getitem__(self, name: str) -> GraphNode:
        for n in self.nodes:
            if n.name == name:
                return n
        raise KeyError(f"node {name!r} is not in the {self.robot} graph's {self.mode} mode "
                       f"(nodes: {', '.join(n.name for n in self.nodes)})")

    def names(self) -> list[str]:
        return [n.name for n in self.nodes]

    def ros2_run_lines(self) -> list[str]:
        return [n.ros2_run() for n in self.nodes]


def _shell_word(word: str) -> str:
    """``word`` quoted for a POSIX shell, readably (``-p 'name:='`` rather than shlex's escapes)."""
    if shlex.quote(word) == word:
        return word
    if "'" in word and not any(c in word for c in '"$`\\!'):
        return '"' + word + '"'
    return shlex.quote(word)


def read_graph_file(path) -> dict:
    """The parsed YAML of a graph file, checked for the ``graph`` section."""
    import yaml
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise GraphError(f"graph file {path}: {exc.strerror or exc}") from exc
    except yaml.YAMLError as exc:
        raise GraphError(f"graph file {path} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict) or not isinstance(data.get(GRAPH_KEY), dict) \
            or not isinstance(data[GRAPH_KEY].get("ros__parameters"), dict):
        raise GraphError(f"graph file {path}: no '{GRAPH_KEY}: ros__parameters:' section (the node list)")
    return data


def load_graph(path, mode: str, overrides: Optional[Mapping[str, Mapping]] = None,
               exclude: Iterable[str] = (), remaps: Optional[Mapping[str, Mapping]] = None) -> Graph:
    """The nodes of graph file ``path`` for ``mode`` (``sim`` or ``real``), ready to start.

    Parameters
    ----------
    path : path of the graph YAML.
    mode : ``sim`` keeps nodes tagged ``sim`` or ``both`` and puts every node except the
        graph's ``clock_source`` on ``use_sim_time``; ``real`` keeps ``real`` and ``both``
        on the system clock.
    overrides : ``{node: {parameter: value}}`` applied over the file's parameters; a value
        of None removes the parameter (the node's default applies).
    exclude : names of nodes to leave out (options such as ``--no-vision``).
    remaps : ``{node: {from: to}}`` added to the file's remaps.

    Raises
    ------
    GraphError
        naming the file and the entry: unknown mode or tag, a node without package or
        executable, an override or exclusion of a node the mode does not have.
    """
    if mode not in MODES:
        raise GraphError(f"graph mode {mode!r}: expected one of {', '.join(MODES)}")
    data = read_graph_file(path)
    meta = data[GRAPH_KEY]["ros__parameters"]
    order = meta.get("order")
    if not isinstance(order, list) or not order:
        raise GraphError(f"graph file {path}: '{GRAPH_KEY}.order' must list the nodes in start order")
    clock_sources = set(meta.get("clock_source", []) or [])
    nodes = []
    all_names = set(order)
    for name in order:
        spec = meta.get(name)
        if not isinstance(spec, dict):
            raise GraphError(f"graph file {path}: node {name!r} is in '{GRAPH_KEY}.order' but has no "
                             f"'{GRAPH_KEY}.{name}' entry (package, executable, tag)")
        missing = [k for k in ("package", "executable", "tag") if not spec.get(k)]
        if missing:
            raise GraphError(f"graph file {path}: node {name!r} lacks {', '.join(missing)}")
        if spec["tag"] not in TAGS:
            raise GraphError(f"graph file {path}: node {name!r} has tag {spec['tag']!r}; expected one of "
                             f"{', '.join(TAGS)}")
        if spec["tag"] not in (mode, "both"):
            continue
        params = dict((data.get(name) or {}).get("ros__parameters") or {})
        if mode == "sim" and name not in clock_sources:
            params["use_sim_time"] = True
        node_remaps = {}
        for r in spec.get("remaps", []) or []:
            if not isinstance(r, str) or ":=" not in r:
                raise GraphError(f"graph file {path}: node {name!r} remap {r!r} is not 'from:=to'")
            a, b = r.split(":=", 1)
            node_remaps[a] = b
        nodes.append(GraphNode(name, spec["package"], spec["executable"], spec["tag"], params, node_remaps))
    graph = Graph(str(meta.get("robot", Path(path).stem)), mode, nodes)
    for what, table in (("override", overrides or {}), ("remap", remaps or {})):
        for name, values in table.items():
            if name not in graph:
                where = "has no node" if name not in all_names else f"has no {name!r} in {mode} mode"
                raise GraphError(f"{what} for node {name!r}: graph file {path} {where}"
                                 + ("" if name in all_names else f" (nodes: {', '.join(order)})"))
            target = graph[name].parameters if what == "override" else graph[name].remaps
            for k, v in values.items():
                if v is None:
                    target.pop(k, None)
                else:
                    target[k] = v
    for name in exclude:
        if name not in all_names:
            raise GraphError(f"cannot leave out node {name!r}: graph file {path} has no such node")
    graph.nodes = [n for n in graph.nodes if n.name not in set(exclude)]
    return graph
