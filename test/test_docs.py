"""README.md and docs/: links resolve, generated parts are fresh, and what they show still holds.

Hermetic: the link and render checks read files only; the captured ``grasp-safety`` commands
run in-process on the bundled scenarios (a few seconds), and the grasp orders they print are
compared with the orders shown (not every digit: ``make docs`` re-captures those).
"""

from __future__ import annotations

import re
import shlex
import sys
from contextlib import redirect_stderr, redirect_stdout
from io import StringIO
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
import render_docs  # noqa: E402

from grasp_safety_ros.cli.main import main as grasp_safety  # noqa: E402

LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```$", re.S | re.M)
INLINE_CODE = re.compile(r"`[^`\n]*`")


def slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped (word
    characters, hyphens and spaces kept), spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(text: str) -> set[str]:
    """Every heading anchor of a Markdown text (repeated headings get -1, -2, ...)."""
    seen: dict[str, int] = {}
    found = set()
    for line in FENCE.sub("", text).splitlines():
        match = re.match(r"#{1,6} (.+)", line)
        if match:
            base = slug(match.group(1))
            count = seen.get(base, 0)
            seen[base] = count + 1
            found.add(base if count == 0 else f"{base}-{count}")
    return found


def broken_links(path: Path) -> list[str]:
    """The relative links (and #anchors into Markdown files) of ``path`` that do not resolve;
    links in code blocks and inline code are not links."""
    text = path.read_text()
    prose = INLINE_CODE.sub("", FENCE.sub("", text))
    broken = []
    for target in LINK.findall(prose):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto: ...: not ours to check
            continue
        file_part, _, anchor = target.partition("#")
        resolved = (path.parent / file_part).resolve() if file_part else path
        if not resolved.exists():
            broken.append(f"{target}: no such file")
        elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved.read_text()):
            broken.append(f"{target}: no heading with that anchor")
    return broken


DOCS = render_docs.doc_files()


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path: Path) -> None:
    assert broken_links(path) == []


def test_link_check_finds_broken_links(tmp_path: Path) -> None:
    (tmp_path / "other.md").write_text("# Other page\n\n## A (section): here\n")
    page = tmp_path / "page.md"
    page.write_text(
        "# Page\n[ok](other.md) [ok](other.md#a-section-here) [ok](#page) [web](https://x.y/z)\n"
        "[gone](missing.md) [bad](other.md#nowhere) [bad](#nowhere) `[code](no.md)`\n"
        "```\n[fenced](no.md)\n```\n"
    )
    assert broken_links(page) == [
        "missing.md: no such file",
        "other.md#nowhere: no heading with that anchor",
        "#nowhere: no heading with that anchor",
    ]


def test_readme_is_short_with_contents_and_the_two_commands() -> None:
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 400
    assert "## Contents" in text
    assert "make test" in text and "make demo" in text


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_generated_blocks_are_fresh(path: Path) -> None:
    for name, body in render_docs.generated_blocks(path.read_text()):
        assert body == render_docs.GENERATORS[name](), f"{name} is stale: run make docs"


def test_render_replaces_a_stale_block() -> None:
    stale = "a\n<!-- generated: bench-postures -->\nold\n<!-- end generated -->\nb\n"
    fresh = render_docs.render(stale)
    assert "old" not in fresh and "| restarts |" in fresh and fresh.endswith("-->\nb\n")


def test_no_machine_paths_in_docs() -> None:
    """No path of this machine (the checkout's or its parent folder's) in what the docs show."""
    parent = re.compile(rf"(?<![\w.]){re.escape(str(ROOT.parent))}/\w")
    for path in DOCS:
        text = path.read_text()
        assert str(ROOT) not in text, path
        assert ROOT.parent == ROOT.parent.parent or parent.search(text) is None, path


def test_readme_scenario_is_the_bundled_book() -> None:
    """The scenario shown in the README is config/book_baxter.yaml (the demo's)."""
    text = (ROOT / "README.md").read_text()
    shown = re.search(r"```yaml\n(.*?)```", text, re.S)
    assert shown is not None
    book = yaml.safe_load((ROOT / "config" / "book_baxter.yaml").read_text())
    assert yaml.safe_load(shown.group(1)) == book


# --- captured outputs -------------------------------------------------------------------------


def grasp_orders(output: str) -> list[list[int]]:
    """The grasp indices of every ranking table of a ``grasp-safety`` output, in rank order."""
    orders: list[list[int]] = []
    for line in output.splitlines():
        if re.match(r"\s*rank\s+index\b", line):
            orders.append([])
        elif orders and (row := re.match(r"\s*(\d+)\s+(\d+)\s", line)):
            orders[-1].append(int(row.group(2)))
    return orders


def test_grasp_orders_reads_a_ranking_table() -> None:
    table = "head\nrank  index  name\n---\n   1      2  c  1.0\n   2      0  a  1.1\n\nx 3 4\n"
    assert grasp_orders(table) == [[2, 0]]


def captured_blocks(mode: str | None) -> list[tuple[Path, str, list[str]]]:
    """(file, command, output lines shown) of the captured commands of one mode."""
    found = []
    for path in DOCS:
        for match in render_docs.CAPTURED.finditer(path.read_text()):
            if match.group("mode") == mode:
                for command, output in render_docs.commands(match.group("body")):
                    found.append((path, command, output))
    return found


CLI = [
    block
    for block in captured_blocks(None)
    if block[1].startswith(".venv/bin/grasp-safety ") and "<(" not in block[1]
]
CLI_COMMANDS = sorted({command.split(" | ")[0] for _, command, _ in CLI})
"""Each distinct command (without a filter it is piped into) runs once; every block that shows
it is compared."""


def test_docs_show_the_demo() -> None:
    assert ".venv/bin/grasp-safety demo" in CLI_COMMANDS


@pytest.mark.parametrize("command", CLI_COMMANDS)
def test_shown_ranking_is_the_one_produced(
    command: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The command runs (exit 0) and prints the grasp orders that every block showing it
    shows (piped into a filter such as ``sed -n 1,13p`` or not)."""
    (tmp_path / "config").symlink_to(ROOT / "config")
    monkeypatch.chdir(tmp_path)  # the demo writes demo_output/ here
    out, err = StringIO(), StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        status = grasp_safety(shlex.split(command)[1:])
    assert status == 0, err.getvalue()
    produced = grasp_orders(out.getvalue())
    for path, shown_command, shown in CLI:
        if shown_command.split(" | ")[0] == command:
            shown_orders = grasp_orders("\n".join(shown))
            assert shown_orders, f"{path}: no ranking table shown for {command}"
            assert produced == shown_orders, f"{path} is stale: run make docs"


SHELL = [block for block in captured_blocks(None) if block not in CLI]


@pytest.mark.parametrize(
    "path, command, shown", SHELL, ids=[f"{p.relative_to(ROOT)}: {c}" for p, c, _ in SHELL]
)
def test_shown_one_line_outputs_are_current(path: Path, command: str, shown: list[str]) -> None:
    """Other captured commands (one-line outputs, such as an error) print exactly that."""
    output = render_docs.run_shown(command, ROOT)
    assert output.rstrip("\n").splitlines() == shown, f"{path}: run make docs"


def test_capture_rewrites_outputs(tmp_path: Path) -> None:
    page = "x\n<!-- captured -->\n```text\n$ echo 'a\nb'\nold\n$ printf c\n```\ny\n"
    assert render_docs.capture(page, tmp_path) == (
        "x\n<!-- captured -->\n```text\n$ echo 'a\nb'\na\nb\n$ printf c\nc\n```\ny\n"
    )
