"""Workspace rules that keep the packages usable on a real ROS 2 install and without ROS.

- every Python package has package.xml (format 3, ament_python), setup.cfg installing
  scripts into lib/<pkg>, the ament resource marker, a core/ and a nodes/ subpackage;
- core modules import neither rclpy nor another package of ours but the shared vocabulary
  frog_common (cores meet only through messages and files; the composition package frog_twin
  is the one exception), checked statically and by importing them with rclpy blocked;
- frog_common imports no ROS and nothing of ours (numpy and the standard library only);
- every console script is installed where `ros2 run` looks and its function exists;
- every ROS package or third-party library a package's code imports is in its package.xml
  (a rosdep key, or a ``pip-only`` comment naming it where rosdep has none).
"""

import ast
import configparser
import importlib
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "ros_ws" / "src"
INSTALL = SRC.parent / "install"
COMMON = "soft_robot_common"   # node plumbing shared by all nodes; no core, no algorithms
COMPOSITION = "frog_twin"      # the one package whose core may use other packages' cores
VOCABULARY = "frog_common"     # what every frog package shares (primitives, SE(2), file schema)
ALL_PY = sorted(p.name for p in SRC.iterdir() if (p / "setup.py").is_file())
PY_PACKAGES = [p for p in ALL_PY if p not in (COMMON, VOCABULARY)]
OURS = set(ALL_PY) | {"soft_robot_interfaces"}


def test_expected_packages_exist():
    assert set(PY_PACKAGES) == {"frog_sim", "frog_planner", "frog_vision", "frog_bridge",
                                "softkin_fk", "frog_logger", COMPOSITION}
    assert (SRC / "soft_robot_interfaces" / "CMakeLists.txt").is_file()
    assert (SRC / COMMON / "setup.py").is_file()
    assert (SRC / VOCABULARY / "setup.py").is_file()


def test_common_package_is_only_plumbing():
    """soft_robot_common may import ROS, the standard library and the vocabulary, nothing else of ours."""
    for path in (SRC / COMMON / COMMON).rglob("*.py"):
        assert not (_imports(path) & (OURS - {COMMON, VOCABULARY})), path


def test_vocabulary_is_pure():
    """frog_common: numpy and the standard library only, so every core may use it."""
    for path in (SRC / VOCABULARY / VOCABULARY).rglob("*.py"):
        names = _imports(path) - {VOCABULARY}
        assert names <= set(sys.stdlib_module_names) | {"numpy"}, (path, names)


@pytest.mark.parametrize("pkg", PY_PACKAGES)
def test_package_layout(pkg):
    root = SRC / pkg
    xml = ET.parse(root / "package.xml").getroot()
    assert xml.get("format") == "3"
    assert xml.findtext("name") == pkg
    assert xml.find("export/build_type").text == "ament_python"
    assert xml.findall("exec_depend"), "package.xml lists no run dependencies"
    cfg = configparser.ConfigParser()
    cfg.read(root / "setup.cfg")
    assert cfg["install"]["install_scripts"] == f"$base/lib/{pkg}"
    assert cfg["develop"]["script_dir"] == f"$base/lib/{pkg}"
    assert (root / "resource" / pkg).is_file()
    for sub in ("core", "nodes"):
        assert (root / pkg / sub / "__init__.py").is_file()
    assert (root / "test").is_dir()


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


@pytest.mark.parametrize("pkg", PY_PACKAGES)
def test_core_imports_no_ros_and_no_other_package(pkg):
    core = SRC / pkg / pkg / "core"
    bad = {}
    for path in core.rglob("*.py"):
        names = _imports(path)
        ros = {n for n in names if n in ("rclpy", "rosidl_runtime_py", "rosbag2_py")
               or n.endswith("_msgs") or n.endswith("_srvs")}
        others = (names & OURS) - {pkg, VOCABULARY} if pkg != COMPOSITION else set()
        if ros or others:
            bad[str(path.relative_to(SRC))] = sorted(ros | others)
    assert not bad, f"core modules importing ROS or another package's code: {bad}"


BLOCKER = """
import importlib.abc, sys
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('rclpy',):
            raise ImportError('core imported ' + name)
sys.meta_path.insert(0, Block())
import importlib, pkgutil
import {pkg}.core as core
for m in pkgutil.walk_packages(core.__path__, '{pkg}.core.'):
    importlib.import_module(m.name)
print('ok')
"""


@pytest.mark.parametrize("pkg", PY_PACKAGES)
@pytest.mark.system
def test_core_imports_without_rclpy(pkg):
    r = subprocess.run([sys.executable, "-c", BLOCKER.format(pkg=pkg)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-3000:]


def _console_scripts(pkg):
    text = (SRC / pkg / "setup.py").read_text()
    return re.findall(r"'([\w-]+)\s*=\s*([\w.]+):(\w+)'", text)


@pytest.mark.parametrize("pkg", ALL_PY)
def test_console_scripts_installed_and_resolvable(pkg):
    for exe, module, func in _console_scripts(pkg):
        assert (INSTALL / pkg / "lib" / pkg / exe).is_file(), \
            f"{exe} not installed in install/{pkg}/lib/{pkg} (run colcon build)"
        assert callable(getattr(importlib.import_module(module), func))


# import name -> rosdep key, where the two differ (rosdep's python.yaml)
ROSDEP_KEYS = {"numpy": "python3-numpy", "scipy": "python3-scipy", "matplotlib": "python3-matplotlib",
               "tqdm": "python3-tqdm", "numba": "python3-numba", "yaml": "python3-yaml",
               "serial": "python3-serial", "cv2": "python3-opencv", "psutil": "python3-psutil",
               "cvxopt": "python3-cvxopt", "PIL": "python3-pil", "filterpy": "python3-filterpy"}


def _manifest(pkg: str) -> tuple[set[str], str]:
    text = (SRC / pkg / "package.xml").read_text()
    xml = ET.fromstring(text)
    keys = {e.text.strip() for tag in ("exec_depend", "depend", "build_export_depend") for e in xml.iter(tag)}
    pip_only = " ".join(re.findall(r"<!--\s*pip-only[^>]*-->", text))
    return keys, pip_only


def _missing_dependencies(pkg: str, keys: set[str], pip_only: str) -> dict[str, str]:
    """``{import name: first file}`` of imports that neither ``keys`` nor ``pip_only`` cover."""
    missing = {}
    for path in sorted((SRC / pkg / pkg).rglob("*.py")):
        for name in sorted(_imports(path) - {pkg}):
            if name in sys.stdlib_module_names or name in keys or ROSDEP_KEYS.get(name) in keys:
                continue
            if re.search(rf"\b{re.escape(name)}\b", pip_only):
                continue
            missing.setdefault(name, str(path.relative_to(SRC)))
    return missing


@pytest.mark.parametrize("pkg", ALL_PY)
def test_manifest_lists_every_import(pkg):
    """Each non-stdlib import of the package's code is a dependency in package.xml."""
    missing = _missing_dependencies(pkg, *_manifest(pkg))
    assert not missing, (f"{pkg}/package.xml lacks dependencies its code imports (import name: first file): "
                         f"{missing}; add an exec_depend (rosdep key) or a '<!-- pip-only: name -->' comment")


def test_manifest_check_catches_a_missing_dependency():
    """The check is not vacuous: without numpy, rclpy and the mcap comment it names them."""
    keys, pip_only = _manifest("frog_sim")
    assert "numpy" not in _missing_dependencies("frog_sim", keys, pip_only)
    assert "numpy" in _missing_dependencies("frog_sim", keys - {"python3-numpy"}, pip_only)
    assert "rclpy" in _missing_dependencies("frog_sim", keys - {"rclpy"}, pip_only)
    keys, pip_only = _manifest("frog_logger")
    assert "mcap" in _missing_dependencies("frog_logger", keys, "")


@pytest.mark.parametrize("pkg", [p for p in PY_PACKAGES if p != COMPOSITION])
def test_no_package_but_the_composition_imports_another_packages_code(pkg):
    """Nodes, tools and cores of a package stand alone (they meet through messages and files)."""
    bad = {}
    for path in (SRC / pkg / pkg).rglob("*.py"):
        others = (_imports(path) & (OURS - {"soft_robot_interfaces", COMMON, VOCABULARY})) - {pkg}
        if others:
            bad[str(path.relative_to(SRC))] = sorted(others)
    assert not bad, f"imports of another package's code outside {COMPOSITION}: {bad}"
