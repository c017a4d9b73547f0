"""Re-render the generated parts of README.md and docs/ and re-capture the outputs they show.

Two kinds of marked blocks, both rewritten in place:

- ``<!-- generated: NAME -->`` ... ``<!-- end generated -->``: Markdown rendered from the code
  or from committed measurements, by GENERATORS[NAME]: the node's parameter reference (from
  ``PARAMETERS`` and ``parameter_constraints``), the table of options (``core.options``) and
  the benchmark tables (from ``bench/results.json``). Cheap and deterministic: the tests
  compare every such block with a fresh render (``check``).
- ``<!-- captured -->`` followed by a fenced block whose lines starting with ``$ `` are shell
  commands (run from the repository root with ``.venv/bin`` first on PATH; a command goes on
  over further lines while a quote is open) and whose other lines are their output. With
  ``--capture`` each command is run again and the block rewritten with its current output
  (the checkout's path shown as ``<checkout>``). The tests run the ``grasp-safety`` commands
  of these blocks and compare the grasp orders shown with the ones produced.

Usage (from the repository root; ``make docs`` runs both)::

    .venv/bin/python scripts/render_docs.py            # generated blocks only (instant)
    .venv/bin/python scripts/render_docs.py --capture  # and the captured outputs (~30 s)
    .venv/bin/python scripts/render_docs.py --check    # exit 1 if a generated block is stale
    .venv/bin/python scripts/render_docs.py --capture docs/cli.md   # one file
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

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
BENCH = ROOT / "bench" / "results.json"


def doc_files(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown file below docs/."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


# --- the parameter reference ------------------------------------------------------------------

_UNIT_SUFFIXES = {"_kgm2": "kg m²", "_kg": "kg", "_m": "m", "_s": "s"}
_TYPE_NAMES = {bool: "bool", int: "integer", float: "double", str: "string"}


def parameter_type(spec: Any) -> str:
    """The declared ROS type of a ParameterSpec in words (as ``ros2 param describe`` says)."""
    if isinstance(spec.default, (list, tuple)):
        item = spec.item_type or type(spec.default[0])
        return f"{_TYPE_NAMES[item]} array"
    return _TYPE_NAMES[type(spec.default)]


def parameter_unit(name: str, description: str) -> str:
    """The unit: from the name's suffix (``_s``, ``_m``, ``_kg``, ``_kgm2``), else the first
    bracketed unit of the description (``[rad or m]``); empty for plain numbers."""
    for suffix, unit in _UNIT_SUFFIXES.items():
        if name.endswith(suffix):
            return unit
    match = re.search(r"\[([a-zA-Z][^\]]*)\]", description)
    return match.group(1).replace("^2", "²") if match else ""


def _default(value: Any) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_default(item) for item in value) + "]"
    return repr(value)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("<", "&lt;")


def _number(value: float) -> str:
    return f"{int(value):,}" if float(value).is_integer() else f"{value:g}"


def render_parameters() -> str:
    """The node's parameters as a Markdown table: type, default, constraints, unit, meaning."""
    sys.path.insert(0, str(ROOT))
    from grasp_safety_ros.ros.parameters import PARAMETERS, parameter_constraints

    rows = [
        "| Parameter | Type | Default | Constraints | Unit | Description |",
        "|---|---|---|---|---|---|",
    ]
    for name, spec in PARAMETERS.items():
        constraints = parameter_constraints(name)
        limits = [constraints.text] if constraints.text else []
        if constraints.value_range is not None:
            low, high = constraints.value_range
            limits.insert(0, f"in [{_number(low)}, {_number(high)}]")
        if spec.read_only:
            limits.append("read-only (start-up only)")
        cells = [
            f"`{name}`",
            parameter_type(spec),
            f"`{_default(spec.default)}`",
            _cell("; ".join(limits)),
            parameter_unit(name, spec.description),
            _cell(spec.description),
        ]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def render_options() -> str:
    """The one table of options (core.options) as Markdown: the scenario key, the node
    parameter, type, default (every interface's), bounds, unit, meaning; then the limits."""
    sys.path.insert(0, str(ROOT))
    from grasp_safety_ros.core.options import LIMITS, OPTIONS

    rows = [
        "| Scenario key | Node parameter | Type | Default | Bounds | Unit | Meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for key, option in OPTIONS.items():
        bounds = option.bounds
        cells = [
            f"`{option.scenario_key}`",
            f"`{key}`",
            option.type.__name__,
            f"`{_default(option.default)}`",
            "" if bounds is None else f"[{_number(bounds[0])}, {_number(bounds[1])}]",
            option.unit,
            _cell(option.help),
        ]
        rows.append("| " + " | ".join(cells) + " |")
    rows += ["", "| Limit | Scenario (and top of the node parameter) | Node parameter: default |"]
    rows.append("|---|---|---|")
    for limit in LIMITS.values():
        node = f"`{limit.node}`: {_number(limit.budget)}" if limit.node else ""
        unit = f" {limit.unit}" if limit.unit else ""
        rows.append(f"| {limit.name} | {_number(limit.value)}{unit} | {node} |")
    return "\n".join(rows) + "\n"


# --- tables of the committed benchmark results --------------------------------------------------


def _bench() -> dict[str, Any]:
    return json.loads(BENCH.read_text())


def render_bench_arms() -> str:
    """The ranking's speed per (grasp, sample) on Panda and Baxter, from bench/results.json."""
    arms = _bench()["arms"]
    names = [name for name in ("panda", "baxter") if name in arms]

    def row(label: str, pick: Callable[[dict[str, Any]], str]) -> str:
        return f"| {label} | " + " | ".join(pick(arms[name]) for name in names) + " |"

    def ours(arm: dict[str, Any]) -> str:
        figure = arm["us_per_sample_with_ik"]
        return f"**{figure['median']:.2f}** [{figure['min']:.2f}..{figure['max']:.2f}]"

    lines = [
        "| µs per (grasp, sample) | " + " | ".join(name.capitalize() for name in names) + " |",
        "|---" * (len(names) + 1) + "|",
        row("ours, 1 core, IK included", ours),
        row(
            "ours, 1 core, effective mass only, per grasp (the analyses' path)",
            lambda a: f"{a['us_per_sample_without_ik']['median']:.2f}",
        ),
        row(
            "ours, 2 cores",
            lambda a: (
                f"{a['us_per_sample_with_ik_parallel']['median']:.2f} "
                f"(×{a['parallel_speedup']:.2f})"
            ),
        ),
        row("Python/Pinocchio path", lambda a: f"{a['python_backend_us_per_sample_with_ik']:.0f}"),
        row(
            "first implementation (`bench/reference.py`)",
            lambda a: f"{a['reference']['us_per_sample_with_ik']:.0f}",
        ),
    ]
    if all("pykdl" in arms[name] for name in names):
        lines += [
            row(
                "PyKDL pipeline, IK included",
                lambda a: f"{a['pykdl']['us_per_sample_with_ik']['median']:.0f}",
            ),
            row("speed-up over PyKDL, same run", lambda a: f"**×{a['speedup_vs_pykdl']:.0f}**"),
            row(
                "KDL's solver calls alone (FK, Jacobian, mass matrix)",
                lambda a: f"{a['pykdl']['kdl_calls_us_per_sample']:.1f}",
            ),
        ]
    lines += [
        row(
            "Gauss-Newton iterations per sample (after sample 0)",
            lambda a: f"{a['ik_iterations_per_sample_excluding_first']:.3f}",
        ),
        row("feasible grasps of 100", lambda a: f"{a['feasible_grasps']}"),
        row("physical floor (flop count)", lambda a: f"{a['floor_us_per_sample']:.2f}"),
    ]
    results = _bench()
    continuous = results.get("continuous_arm")
    if continuous:
        figure = continuous["us_per_sample_with_ik"]
        lines += [
            "",
            "| continuous joints (Kinova Jaco2), same run | |",
            "|---|---|",
            f"| ours, 1 core, IK included | {figure['median']:.2f} "
            f"[{figure['min']:.2f}..{figure['max']:.2f}] µs per sample, "
            f"**×{results['continuous_vs_revolute_cpu']:.2f}** the slowest revolute arm "
            "(CPU time) |",
            f"| Python/Pinocchio path | {continuous['python_backend_us_per_sample_with_ik']:.0f} "
            "µs per sample |",
            f"| compiled vs Python: max rel. diff of M_eff | "
            f"{continuous['python_backend_max_rel_diff']:.1e} |",
            f"| feasible grasps of {continuous['grasps']} | {continuous['feasible_grasps']} |",
        ]
    machine = results["machine"]
    lines += [
        "",
        f"Machine: {machine['cores_available']} cores, Python {machine['python']}, load average "
        f"{machine['load_average_1min_before']:.1f} before and "
        f"{machine['load_average_1min_after']:.1f} after the run.",
    ]
    return "\n".join(lines) + "\n"


def render_bench_postures() -> str:
    """CPU cost and score gain of posture selection per restart count, from bench/results.json."""
    workloads = _bench()["posture_selection"]
    counts = [row["restarts"] for row in next(iter(workloads.values())) if row["restarts"]]
    header = " | ".join(f"**{c}**" if c == 8 else str(c) for c in counts)
    lines = [f"| restarts | {header} |", "|---" * (len(counts) + 1) + "|"]
    for name, rows in workloads.items():
        by_count = {row["restarts"]: row for row in rows}
        cells = []
        for count in counts:
            row = by_count[count]
            cell = f"{row['cpu_ms_per_grasp']:.1f} / {row['mean_gain_percent']:.1f} %"
            cells.append(f"**{cell}**" if count == 8 else cell)
        lines.append(f"| {name}: ms per grasp / mean gain | " + " | ".join(cells) + " |")
    lines.append("")
    for name, rows in workloads.items():
        row = next(row for row in rows if row["restarts"] == 8)
        lines.append(
            f"- {name}, 8 restarts: largest gain of one grasp {row['max_gain_percent']:.1f} %, "
            f"{row['postures_tried_mean']:.1f} distinct start postures on average, "
            f"{row['feasible']} feasible, {row['rescued_by_selection']} feasible only with "
            "selection."
        )
    return "\n".join(lines) + "\n"


_SERVICE_ROWS = (
    (None, "`posture.restarts: 0`, default response"),
    ("per_sample_off", "same, `response.per_sample: false`"),
    ("node_defaults", "node defaults (`posture.restarts: 8`)"),
    ("least_response", "the least the node returns"),
)


def render_bench_service() -> str:
    """The service round trip per configuration, from bench/results.json."""
    service = _bench()["service"]
    lines = [
        "| | 10 × 101 median, p90 | ranking alone | ratio | 1,000 × 201 end to end | response |",
        "|---|---|---|---|---|---|",
    ]
    for key, label in _SERVICE_ROWS:
        figures = service if key is None else service.get(key)
        if figures is None:
            continue
        large = figures["end_to_end_1000x201"]
        latency = figures["latency_ms"]
        lines.append(
            f"| {label} | {latency['median']:.1f}, {latency['p90']:.1f} ms | "
            f"{figures['ranking_ms']['median']:.1f} ms | ×{figures['latency_over_ranking']:.1f} | "
            f"{large['wall_s']:.2f} s | {large['response_bytes']:,} B |"
        )
    spans = ", ".join(f"{name} {value:.1f}" for name, value in service["spans_ms"].items())
    lines += [
        "",
        f"Where 10 × 101 goes, `posture.restarts: 0`, default response (ms, medians): {spans}.",
        f"The floor of an empty request: {service['empty_request_ms']['median']:.1f} ms with "
        f"`EventsExecutor`, {service['empty_request_spin_once_ms']['median']:.1f} with a "
        f"`spin_once` loop, {service['empty_request_spin_until_ms']['median']:.1f} with "
        "`spin_until_future_complete`; the 10 × 101 ranking "
        f"{service['latency_ms']['median']:.1f}, {service['latency_spin_once_ms']['median']:.1f} "
        f"and {service['latency_spin_until_ms']['median']:.1f} ms.",
    ]
    return "\n".join(lines) + "\n"


GENERATORS: dict[str, Callable[[], str]] = {
    "parameters": render_parameters,
    "options": render_options,
    "bench-arms": render_bench_arms,
    "bench-postures": render_bench_postures,
    "bench-service": render_bench_service,
}
"""Every generated block's renderer, by the name its marker gives."""


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
    output = (done.stdout + done.stderr).replace(str(root), "<checkout>")
    return ABBREVIATED[0].sub(ABBREVIATED[1], output)


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
        deadline = time.monotonic() + 120.0
        while "robot from urdf" not in self.log.read_text():
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError(f"the node did not start:\n{self.log.read_text()}")
            time.sleep(0.2)
        while "/grasp_safety" not in self.run("ros2 node list"):  # the daemon has found it
            time.sleep(0.5)

    def first_log_line(self) -> str:
        return self.log.read_text().splitlines()[0]

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
        shown = commands(match.group("body"))
        for k, (command, _) in enumerate(shown):
            if mode == "node-start":
                output = session.first_log_line() if k == len(shown) - 1 else ""
            elif mode == "node":
                output = session.run(command)
            else:
                output = run_shown(command, root)
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
