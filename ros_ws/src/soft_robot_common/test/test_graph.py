"""The graph loader: modes, clock, overrides, exclusions, errors, ros2 run lines; the shipped files."""
from pathlib import Path

import pytest
from soft_robot_common.graph import GraphError, load_graph

SRC = Path(__file__).resolve().parents[2]
FILES = [SRC / "frog_twin" / "frog_twin" / "config" / "frog_graph.yaml",
         SRC / "softkin_fk" / "softkin_fk" / "config" / "finger_graph.yaml"]

GRAPH = """
graph:
  ros__parameters:
    robot: toy
    clock_source: [world]
    order: [world, cam_sim, cam, driver]
    world: {package: p_sim, executable: world, tag: sim}
    cam_sim: {package: p_vis, executable: cam_sim, tag: sim}
    cam: {package: p_vis, executable: cam, tag: real, remaps: ["image:=camera/image_raw"]}
    driver: {package: p_drv, executable: driver_node, tag: both}
world:
  ros__parameters:
    rate: 2.0
driver:
  ros__parameters:
    port: /dev/ttyACM0
    gain: 3
"""


@pytest.fixture
def toy(tmp_path):
    f = tmp_path / "toy.yaml"
    f.write_text(GRAPH)
    return f


def test_modes_pick_tags_and_clock(toy):
    sim = load_graph(toy, "sim")
    assert sim.names() == ["world", "cam_sim", "driver"]
    assert "use_sim_time" not in sim["world"].parameters and sim["driver"].parameters["use_sim_time"] is True
    real = load_graph(toy, "real")
    assert real.names() == ["cam", "driver"]
    assert "use_sim_time" not in real["driver"].parameters
    assert real["cam"].remaps == {"image": "camera/image_raw"}


def test_overrides_exclusions_and_command_lines(toy):
    g = load_graph(toy, "real", {"driver": {"port": "/tmp/pty", "gain": None}}, exclude=("cam",))
    assert g.names() == ["driver"]
    assert g["driver"].parameters == {"port": "/tmp/pty"}
    assert g["driver"].argv() == ["driver_node", "--ros-args", "-p", "port:=/tmp/pty", "-r", "__node:=driver"]
    assert g["driver"].ros2_run() == "ros2 run p_drv driver_node --ros-args -p port:=/tmp/pty -r __node:=driver"
    empty = load_graph(toy, "sim", {"world": {"name": ""}})
    assert empty["world"].ros2_run().endswith("-p \"name:=''\"")


def test_errors_name_the_problem(toy, tmp_path):
    with pytest.raises(GraphError, match="mode 'lab'"):
        load_graph(toy, "lab")
    with pytest.raises(GraphError, match="node 'cam'.*no 'cam' in sim mode"):
        load_graph(toy, "sim", {"cam": {"x": 1}})
    with pytest.raises(GraphError, match="no node"):
        load_graph(toy, "sim", {"camera": {"x": 1}})
    with pytest.raises(GraphError, match="leave out node 'nope'"):
        load_graph(toy, "sim", exclude=("nope",))
    bad = tmp_path / "bad.yaml"
    bad.write_text(GRAPH.replace("tag: both", "tag: lab"))
    with pytest.raises(GraphError, match="tag 'lab'"):
        load_graph(bad, "sim")
    bad.write_text("world:\n  ros__parameters: {a: 1}\n")
    with pytest.raises(GraphError, match="no 'graph: ros__parameters:' section"):
        load_graph(bad, "sim")
    with pytest.raises(GraphError, match="does-not-exist"):
        load_graph(tmp_path / "does-not-exist.yaml", "sim")


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_shipped_graph_files_load_in_both_modes(path):
    for mode in ("sim", "real"):
        g = load_graph(path, mode)
        assert g.nodes and all(n.tag in (mode, "both") for n in g)
