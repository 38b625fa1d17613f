"""The README and the pages under docs/: first commands that CI runs, and links that resolve."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]

FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)
LINK = re.compile(r"\]\(([^)\s]+)\)")  # [text](target) and ![alt](target)


def first_commands() -> list[str]:
    """The lines of the README's first code block."""
    block = re.search(r"^```bash\n(.*?)^```", README.read_text(), re.MULTILINE | re.DOTALL)
    assert block, "the README has no bash block"
    return block.group(1).splitlines()


def test_readme_opens_with_the_two_commands() -> None:
    head = "\n".join(README.read_text().splitlines()[:15])
    train, test = first_commands()
    assert train in head and test in head
    assert train.endswith("pip install -e . && lanro train --quick")
    assert test.endswith("pip install -e '.[test]' && pytest")


def test_ci_runs_the_readme_second_command() -> None:
    steps = first_commands()[1].split(" && ")
    ci = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    positions = [ci.index(step) for step in steps]  # ValueError names a step CI does not run
    assert positions == sorted(positions), "CI runs the README's steps in another order"


@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.relative_to(ROOT).as_posix())
def test_relative_links_resolve(page: Path) -> None:
    text = FENCE.sub("", page.read_text())
    missing = []
    for target in LINK.findall(text):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path = target.split("#")[0]  # an anchor alone points into the page itself
        resolved = (page.parent / path).resolve()
        if path and not (resolved.is_file() and resolved.is_relative_to(ROOT)):
            missing.append(target)
    assert not missing, f"{page.name} links to missing files: {missing}"
