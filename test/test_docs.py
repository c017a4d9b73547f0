"""README.md and docs/: links resolve, generated parts are fresh, and what they show still holds.

Hermetic: the link and render checks read files only; the captured ``grasp-safety`` commands
run in-process on the bundled scenarios and examples (a few seconds), the other captured
commands as shown, the ``node`` blocks against a node started per page in a ROS domain of this
process's own; what they print is compared with what the pages show, every number to its
last digit (``make docs`` re-captures them).
"""

from __future__ import annotations

import re
import shlex
import subprocess
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

NUMBER = re.compile(r"-?\d+(?:\.(\d+))?(?:[eE]([-+]?\d+))?")


def differences(shown: list[str], produced: list[str]) -> list[str]:
    """Where ``produced`` differs from ``shown``: the text between numbers exactly, each
    integer exactly, each decimal to one unit of its last shown digit (a value on a rounding
    boundary may print one unit apart on another CPU: last-bit differences)."""
    if len(shown) != len(produced):
        return [f"{len(shown)} lines shown, {len(produced)} produced:", *produced]
    return [
        f"shown {old!r}, produced {new!r}"
        for old, new in zip(shown, produced, strict=True)
        if not _same_line(old, new)
    ]


def _same_line(old: str, new: str) -> bool:
    if NUMBER.sub("#", old) != NUMBER.sub("#", new):
        return False
    for a, b in zip(NUMBER.finditer(old), NUMBER.finditer(new), strict=True):
        (digits, exponent), (other_digits, other_exponent) = a.groups(), b.groups()
        decimal = digits is not None and other_digits is not None
        if not decimal or len(digits) != len(other_digits) or exponent != other_exponent:
            if a.group() != b.group():  # an integer, or other digits or exponent shown
                return False
            continue
        unit = 10.0 ** (int(exponent or 0) - len(digits))
        if abs(float(a.group()) - float(b.group())) > 1.000001 * unit:
            return False
    return True


def test_differences_allow_one_unit_of_the_last_digit_only() -> None:
    shown = ["rank 1 of 3: 1.0189 kg..1.0396 kg, x1.30, 5.1e-4"]
    assert differences(shown, ["rank 1 of 3: 1.0190 kg..1.0395 kg, x1.31, 5.2e-4"]) == []
    for stale in (
        "rank 1 of 3: 1.0191 kg..1.0396 kg, x1.30, 5.1e-4",  # two units
        "rank 2 of 3: 1.0189 kg..1.0396 kg, x1.30, 5.1e-4",  # an integer
        "rank 1 of 3: 1.0189 kg..1.0396 kg, x1.30, 5.1e-3",  # an exponent
        "rank 1 of 3: 1.0189 kg..1.0396 kg, x1.3, 5.1e-4",  # the digits shown
        "rank 1 of 3: 1.0189 kg..1.0396 kg, ×1.30, 5.1e-4",  # the text
    ):
        assert differences(shown, [stale]) != [], stale
    assert differences(shown, [*shown, "more"]) != []


def captured_blocks(mode: str | None) -> list[tuple[Path, str, list[str]]]:
    """(file, command, output lines shown) of the captured commands of one mode."""
    found = []
    for path in DOCS:
        for match in render_docs.CAPTURED.finditer(path.read_text()):
            if match.group("mode") == mode:
                for command, output in render_docs.commands(match.group("body")):
                    found.append((path, command, output))
    return found


SINGLE_CLI = re.compile(r"\.venv/bin/grasp-safety [^;&<>|\n]*")
"""One ``grasp-safety`` command (its output may be piped into a filter)."""
CLI = [block for block in captured_blocks(None) if SINGLE_CLI.fullmatch(block[1].split(" | ")[0])]
CLI_COMMANDS = sorted({command.split(" | ")[0] for _, command, _ in CLI})
"""Each distinct command (without a filter it is piped into) runs once, in this process;
every block that shows it is compared."""


def test_docs_show_the_demo_the_examples_and_the_batch() -> None:
    assert ".venv/bin/grasp-safety demo" in CLI_COMMANDS
    shown = " ".join(CLI_COMMANDS)
    for example in ("examples/mjcf/", "examples/dataset/spec.yaml", "spec_refused.yaml"):
        assert example in shown, example


def test_cli_page_lists_every_command() -> None:
    """The command list of docs/cli.md names every command of the parser."""
    from grasp_safety_ros.cli.main import build_parser

    page = (ROOT / "docs" / "cli.md").read_text()
    block = re.search(r"## Commands\n\n```bash\n(.*?)```", page, re.S)
    assert block is not None
    listed = [line.split()[1] for line in block.group(1).splitlines()]
    parser = build_parser()
    (commands,) = [a for a in parser._actions if a.dest == "command"]  # the subparsers
    assert listed == list(commands.choices)


@pytest.mark.parametrize("command", CLI_COMMANDS)
def test_shown_cli_output_is_the_one_produced(
    command: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The command prints what every block showing it shows (piped into a filter such as
    ``sed -n 1,13p`` or not), numbers to their last digit; it exits 2 where the output shown
    is an error, else 0."""
    for name in ("config", "examples"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)  # the outputs (demo_output/, out/) are written here
    out, err = StringIO(), StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        status = grasp_safety(shlex.split(command)[1:])
    produced = out.getvalue() + err.getvalue()
    for path, shown_command, shown in CLI:
        if shown_command.split(" | ")[0] != command:
            continue
        output = produced
        if " | " in shown_command:
            filtered = subprocess.run(
                ["bash", "-c", shown_command.split(" | ", 1)[1]],
                input=output,
                capture_output=True,
                text=True,
                check=True,
            )
            output = filtered.stdout
        output = render_docs.as_shown(output)
        assert differences(shown, output.rstrip("\n").splitlines()) == [], (
            f"{path} is stale: run make docs"
        )
        error = any(line.startswith("grasp-safety: error:") for line in shown)
        assert status == (2 if error else 0), err.getvalue()


SHELL = [block for block in captured_blocks(None) if block not in CLI]


@pytest.mark.parametrize(
    "path, command, shown", SHELL, ids=[f"{p.relative_to(ROOT)}: {c}" for p, c, _ in SHELL]
)
def test_shown_shell_outputs_are_current(path: Path, command: str, shown: list[str]) -> None:
    """Other captured commands (run as shown, from the checkout) print that, numbers to
    their last digit."""
    output = render_docs.run_shown(command, ROOT)
    assert differences(shown, output.rstrip("\n").splitlines()) == [], f"{path}: run make docs"


NODE_PAGES = [
    path
    for path in DOCS
    if any(match.group("mode") for match in render_docs.CAPTURED.finditer(path.read_text()))
]


@pytest.mark.skipif(
    not (ROOT / ".venv" / "bin" / "ros2").exists(),
    reason="no ros2 command line in .venv/bin (make setup installs it when "
    "../shared/tools/ros2cli/install exists beside the checkout)",
)
@pytest.mark.parametrize("path", NODE_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_shown_node_outputs_are_current(path: Path) -> None:
    """A page's ``node`` blocks, run in order against the node started as the page starts it
    (in a ROS domain of this process's own), print what they show, numbers to their last
    digit; stamps and times are shown as ``…``."""
    stale = []
    session = render_docs.NodeSession(ROOT)
    try:
        for match in render_docs.CAPTURED.finditer(path.read_text()):
            if not match.group("mode"):
                continue
            shown = render_docs.commands(match.group("body"))
            outputs = session.outputs(match.group("mode"), [command for command, _ in shown])
            for (command, lines), output in zip(shown, outputs, strict=True):
                found = differences(lines, output.rstrip("\n").splitlines())
                stale += [f"$ {command.splitlines()[0][:60]}: {line}" for line in found]
    finally:
        session.close()
    assert not stale, "\n".join([f"{path.relative_to(ROOT)}: run make docs", *stale])


def test_capture_rewrites_outputs(tmp_path: Path) -> None:
    page = "x\n<!-- captured -->\n```text\n$ echo 'a\nb'\nold\n$ printf c\n```\ny\n"
    assert render_docs.capture(page, tmp_path) == (
        "x\n<!-- captured -->\n```text\n$ echo 'a\nb'\na\nb\n$ printf c\nc\n```\ny\n"
    )


def test_times_are_shown_as_ellipses_and_progress_lines_left_out() -> None:
    waiting = "Waiting for at least 1 matching subscription(s)...\n"  # a progress line
    output = (
        "batch: 3/3 chunks, 1.4 s\nwrote out: 10 grasps, 3 of 3 chunks, 80 (grasp, sample)/s\n"
        + waiting * 2
        + "[INFO] [1795615960.317059770] [grasp_safety]: robot from urdf: 7 joints\n"
        "ranking at 1795615980.729 (base), metric mean, 2 candidates, 0.091 s\n"
        "  #1 candidate 1: score 1.0189, peak 1.0823 kg over 101 samples"
    )
    assert render_docs.as_shown(output) == (
        "batch: 3/3 chunks, … s\nwrote out: 10 grasps, 3 of 3 chunks, … (grasp, sample)/s\n"
        "[INFO] […] [grasp_safety]: robot from urdf: 7 joints\n"
        "ranking at … (base), metric mean, 2 candidates, … s\n"
        "  #1 candidate 1: score 1.0189, peak 1.0823 kg over 101 samples"
    )
