"""Re-render the generated parts of README.md and docs/ and re-capture the outputs they show.

Two kinds of marked blocks, both rewritten in place:

- ``<!-- generated: NAME -->`` ... ``<!-- end generated -->``: Markdown rendered from the code
  or from committed measurements by GENERATORS[NAME] (``scripts/doc_tables.py``): the node's
  parameter reference, the table of options (``core.options``), the command line's input
  bounds, the benchmark tables (from
  ``bench/results*.json``) and the MuJoCo validation's figures (from
  ``docs/validation/results.json``). Cheap and deterministic: the tests compare every such
  block with a fresh render (``check``); timing figures belong here, not in captured blocks.
- ``<!-- captured -->`` followed by a fenced block whose lines starting with ``$ `` are shell
  commands (run from the repository root with ``.venv/bin`` first on PATH; a command goes on
  over further lines while a quote is open) and whose other lines are their output. With
  ``--capture`` each command is run again and the block rewritten with its current output
  (the checkout's path shown as ``<checkout>``, times, stamps and rates as ``…``: TIMINGS).
  ``<!-- captured: node -->`` blocks run against the node as the docs start it (NodeSession,
  one per page, in a ROS domain of its own), in the page's order. The tests run every captured
  command again and compare the whole output with the one shown: text exactly, every number
  to one unit of its last shown digit.

Usage (from the repository root; ``make docs`` runs both)::

    .venv/bin/python scripts/render_docs.py            # generated blocks only (instant)
    .venv/bin/python scripts/render_docs.py --capture  # and the captured outputs (a few minutes)
    .venv/bin/python scripts/render_docs.py --check    # exit 1 if a generated block is stale
    .venv/bin/python scripts/render_docs.py --capture docs/cli.md   # one file
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

from doc_tables import GENERATORS

ROOT = Path(__file__).resolve().parents[1]
GENERATED = re.compile(
    r"(<!-- generated: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- end generated -->)", re.S
)
CAPTURED = re.compile(
    r"(<!-- captured(?:: (?P<mode>[\w-]+))? -->\n```\w*\n)(?P<body>.*?)(^```$)", re.S | re.M
)
NODE_COMMAND = (
    "ros2 run grasp_safety_ros grasp_safety_node --ros-args --params-file "
    "config/grasp_safety_node.yaml"
)
"""How the docs start the node; the ``node`` blocks run against it."""
ABBREVIATED = (re.compile(r"poses=\[.*\]\)$", re.M), "poses=[...])")
"""Echoes shortened in the docs (the publishers' echo of a whole message)."""
WAITING = re.compile(r"^Waiting for at least \d+ matching subscription\(s\)\.\.\.\n", re.M)
"""``ros2 topic pub``'s progress line, printed once a second until discovery has matched its
publisher (none to several times): left out of the outputs shown."""
COMPILING = re.compile(
    r"^compiling kernel \S+ \(first use on this machine\) \.\.\. [0-9.]+ s\n", re.M
)
"""A kernel compiled on the way (core.kernels._jit): depends on the machine's cache, not shown."""
TIMINGS = (
    (re.compile(r"^(batch: \d+/\d+ chunks, )\d+(?:\.\d+)? s$", re.M), r"\1… s"),
    (re.compile(r", \d+ \(grasp, sample\)/s"), ", … (grasp, sample)/s"),
    (re.compile(r"^(\[[A-Z]+\] )\[\d+\.\d+\]", re.M), r"\1[…]"),  # a ROS log line's stamp
    (  # examples/echo_ranking.py: the ranking's stamp and compute time
        re.compile(
            r"^(ranking at )\d+\.\d+( \(\w+\), metric \w+, \d+ candidates, )\d+\.\d+ s$", re.M
        ),
        r"\1…\2… s",
    ),
)
"""Times, stamps and rates in outputs, shown as ``…``: they differ from run to run, so no test
can hold them (measured speeds are in the generated bench blocks)."""
NODE_WAIT_S = 120.0
"""How long the node may take to start, and the ``ros2`` daemon to find it before each block
(discovery on a loaded machine takes seconds)."""


def doc_files(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown file below docs/."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def render(text: str) -> str:
    """``text`` with every generated block rendered afresh.

    Raises:
        KeyError: a marker names no generator.
    """
    return GENERATED.sub(lambda m: m.group(1) + GENERATORS[m.group("name")]() + m.group(4), text)


def generated_blocks(text: str) -> Iterator[tuple[str, str]]:
    """(name, body) of every generated block of ``text``."""
    for match in GENERATED.finditer(text):
        yield match.group("name"), match.group("body")


# --- captured command outputs -----------------------------------------------------------------


def commands(block: str) -> list[tuple[str, list[str]]]:
    """The (command, output lines) of a captured block, in order."""
    result: list[tuple[str, list[str]]] = []
    pending: list[str] = []
    for line in block.splitlines():
        if pending or line.startswith("$ "):
            pending.append(line.removeprefix("$ ") if not pending else line)
            try:
                shlex.split("\n".join(pending))
            except ValueError:  # a quote still open: the command goes on
                continue
            result.append(("\n".join(pending), []))
            pending = []
        elif result:
            result[-1][1].append(line)
    return result


def run_shown(command: str, root: Path = ROOT, cwd: Path | None = None) -> str:
    """The output (stdout and stderr) of a shown command, run with bash from ``cwd`` (default
    ``root``) with ``root/.venv/bin`` first on PATH, as a user would; the checkout's path is
    shown as ``<checkout>``."""
    env = dict(os.environ, PATH=f"{root / '.venv' / 'bin'}{os.pathsep}{os.environ['PATH']}")
    done = subprocess.run(
        ["bash", "-c", command],
        cwd=cwd or root,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    return as_shown(done.stdout + done.stderr, root)


def as_shown(output: str, root: Path = ROOT) -> str:
    """An output as the docs show it: the checkout's path as ``<checkout>``, whole messages
    abbreviated, progress and kernel-compile lines left out, times, stamps and rates as ``…``."""
    venv = root / ".venv"  # a venv linked into the checkout is shown as the checkout's
    output = output.replace(str(venv.resolve()), str(venv)).replace(str(root), "<checkout>")
    output = ABBREVIATED[0].sub(ABBREVIATED[1], COMPILING.sub("", WAITING.sub("", output)))
    for pattern, replacement in TIMINGS:
        output = pattern.sub(replacement, output)
    return output


class NodeSession:
    """The node as the docs start it, in a ROS domain of its own (claimed as the tests do),
    for the ``node`` blocks; their commands run in a scratch folder beside links to the
    checkout's ``.venv``, ``config`` and ``examples`` (so a dump lands there)."""

    def __init__(self, root: Path) -> None:
        import tempfile

        sys.path.insert(0, str(root / "test"))
        from ros_domains import claim_ros_domain

        self.root = root
        self.claim = claim_ros_domain()
        self.scratch = Path(tempfile.mkdtemp(prefix="render_docs_"))
        for name in (".venv", "config", "examples"):
            (self.scratch / name).symlink_to(root / name)
        self.prefix = f"source .venv/setup.bash && export ROS_DOMAIN_ID={self.claim.domain_id}"
        self.log = self.scratch / "node.log"
        with self.log.open("w") as out:
            self.process = subprocess.Popen(
                ["bash", "-c", f"{self.prefix} && exec {NODE_COMMAND}"],
                cwd=self.scratch,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                env=dict(os.environ, RCUTILS_COLORIZED_OUTPUT="0"),
            )
        deadline = time.monotonic() + NODE_WAIT_S
        while "robot from urdf" not in self.log.read_text():
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError(f"the node did not start:\n{self.log.read_text()}")
            time.sleep(0.2)
        # A daemon of this session's own, running before the first look at the graph: with
        # none, a ros2 verb starts one and answers from a discovery of its own, so the node
        # could be listed once and then be "not found" by the newborn daemon.
        self.run("ros2 daemon stop; ros2 daemon start")

    def wait_for_node(self) -> None:
        """Until the ``ros2`` daemon lists the node (at most NODE_WAIT_S).

        Raises:
            RuntimeError: it does not within NODE_WAIT_S, or the node has exited.
        """
        deadline = time.monotonic() + NODE_WAIT_S
        while "/grasp_safety" not in self.run("ros2 node list").split():
            if self.process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"ros2 node list: no /grasp_safety\n{self.log.read_text()}")
            time.sleep(0.5)

    def outputs(self, mode: str, shown: list[str]) -> list[str]:
        """The outputs of one block's commands, as the docs show them: a ``node`` block's run
        once the daemon lists the node, a ``node-start`` block's the node's first log line
        after its last command (the ones before it set up the shell)."""
        if mode == "node-start":
            first_log_line = as_shown(self.log.read_text().splitlines()[0], self.root)
            return [""] * (len(shown) - 1) + [first_log_line]
        self.wait_for_node()
        return [self.run(command) for command in shown]

    def run(self, command: str) -> str:
        return run_shown(f"{self.prefix} && {command}", self.root, cwd=self.scratch)

    def close(self) -> None:
        import shutil

        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGINT)
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
        run_shown(f"{self.prefix} && ros2 daemon stop", self.root, cwd=self.scratch)
        shutil.rmtree(self.scratch, ignore_errors=True)
        self.claim.release()


def capture(text: str, root: Path = ROOT) -> str:
    """``text`` with every captured block's commands run again and their outputs replaced:
    a plain block's from the checkout, a ``node`` block's against a node started for the
    whole text (a ``node-start`` block shows the node's first log line)."""
    session: NodeSession | None = None

    def again(match: re.Match[str]) -> str:
        nonlocal session
        mode = match.group("mode")
        if mode and session is None:
            session = NodeSession(root)
        parts = []
        shown = [command for command, _ in commands(match.group("body"))]
        if mode:
            outputs = session.outputs(mode, shown)
        else:
            outputs = [run_shown(command, root) for command in shown]
        for command, output in zip(shown, outputs, strict=True):
            lines = command.splitlines()
            output = output.rstrip("\n")
            parts.append("\n".join(["$ " + lines[0], *lines[1:]] + ([output] if output else [])))
        return match.group(1) + "\n".join(parts) + "\n" + match.group(4)

    try:
        return CAPTURED.sub(again, text)
    finally:
        if session is not None:
            session.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--capture", action="store_true", help="also re-run captured commands")
    parser.add_argument("--check", action="store_true", help="exit 1 if a block is stale")
    parser.add_argument("files", nargs="*", type=Path, help="only these (default: all docs)")
    args = parser.parse_args(argv)
    stale = []
    for path in [file.resolve() for file in args.files] or doc_files():
        text = path.read_text()
        new = render(text)
        if args.capture:
            new = capture(new)
        if new != text:
            stale.append(path.relative_to(ROOT))
            if not args.check:
                path.write_text(new)
    verb = "stale" if args.check else "rewritten"
    print(f"{verb}: {', '.join(map(str, stale))}" if stale else "up to date")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
