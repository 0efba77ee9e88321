"""The package READMEs' node tables are what the running nodes declare.

``scripts/node_reference.py --check`` starts every node at its defaults on an isolated domain
and compares its topics, services, actions and parameters (type, default, range, live,
description) with the block in its package README: a parameter added, renamed or re-ranged
in the code and not in the docs fails here, naming the node and the lines.
"""

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.system

REPO = Path(__file__).resolve().parents[1]


def test_package_readmes_match_the_running_nodes():
    run = subprocess.run([sys.executable, str(REPO / "scripts" / "node_reference.py"), "--check"],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-6000:]
    assert "13 node references current" in run.stdout


def test_check_names_a_stale_block(tmp_path, monkeypatch):
    """A README whose block differs from the node is reported with its diff, and exits 1."""
    sys.path.insert(0, str(REPO / "scripts"))
    import node_reference as ref
    readme = tmp_path / "README.md"
    good = "#### `sim_node`\n\n| parameter | type | default | range | live | description |"
    readme.write_text(f"{ref.BEGIN.format('sim_node')}\nold text\n{ref.END}\n")
    monkeypatch.setattr(ref, "readme", lambda node: readme)
    monkeypatch.setattr(ref, "collect", lambda names, expected=None: {n: good for n in names})
    monkeypatch.setattr(ref, "REPO", tmp_path)
    assert ref.main(["--check", "sim_node"]) == 1
    assert ref.main(["--write", "sim_node"]) == 0
    assert ref.current_block(readme.read_text(), "sim_node") == good
    assert ref.main(["--check", "sim_node"]) == 0
