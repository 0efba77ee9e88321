"""Every relative link in the READMEs and docs/ points at a file that exists, and at a heading
of it when the link has an anchor (GitHub's anchor rule: lower case, punctuation dropped,
spaces to hyphens)."""

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _docs():
    yield REPO / "README.md"
    yield from sorted((REPO / "docs").glob("*.md"))
    yield from sorted((REPO / "ros_ws" / "src").glob("*/README.md"))


def anchor(heading: str) -> str:
    text = heading.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    """The anchors of a document: its headings', and explicit ``<a id="...">`` ones (which keep
    a link working when its heading is reworded)."""
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    headings = {anchor(m.group(1)) for m in re.finditer(r"^#+ (.+)$", text, re.M)}
    return headings | set(re.findall(r"<a (?:id|name)=\"([^\"]+)\"", text))


def test_anchor_rule():
    assert anchor("Simulator fidelity (`frog_sim`)") == "simulator-fidelity-frog_sim"
    assert anchor("Planners compared: the twin's runs (depth 1, 2)") == "planners-compared-the-twins-runs-depth-1-2"


def test_every_relative_link_resolves():
    broken = []
    for doc in _docs():
        text = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)
        for target in LINK.findall(text):
            if re.match(r"[a-z]+:", target):
                continue                     # http(s), mailto
            file_part, _, frag = target.partition("#")
            dest = (doc.parent / file_part).resolve() if file_part else doc
            if not dest.exists():
                broken.append(f"{doc.relative_to(REPO)}: {target}: no such file")
            elif frag and dest.suffix == ".md" and frag not in _anchors(dest):
                broken.append(f"{doc.relative_to(REPO)}: {target}: no heading #{frag}")
    assert not broken, "\n".join(broken)


def test_every_package_has_a_readme():
    packages = [p.parent for p in (REPO / "ros_ws" / "src").glob("*/package.xml")]
    assert len(packages) >= 9
    missing = [p.name for p in packages if not (p / "README.md").exists()]
    assert not missing, missing
