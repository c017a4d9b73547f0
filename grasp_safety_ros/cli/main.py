"""Command line: ``grasp-safety rank``, ``demo``, ``robots``, ``frames``, ``reproduce`` and
``batch``."""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..core.exceptions import GraspSafetyError, InvalidInputError
from ..core.method.metrics import METRICS
from ..paths import config_file

if TYPE_CHECKING:
    from ..core.analyses.safety_report import SafetyReport
    from ..scenario.schema import Scenario

# The commands import the core, the scenario reader and the report writer when they run, so
# ``grasp-safety --help`` and argument errors stay fast (docs/performance_pipeline.md).

EXIT_BAD_INPUT = 2
DEMO_SCENARIO = "book_baxter.yaml"
DEMO_BACKEND = "python"
"""The demo's three grasps run on the Pinocchio path: under a second, where compiling the
kernels they would use takes minutes on a new machine; ``grasp-safety rank`` of the same file
runs the compiled kernels and prints the same table (docs/performance_pipeline.md)."""
PROGRESS_MIN_SAMPLES = 2000
"""Show a progress bar (on a terminal) when grasps x samples reaches this."""


def _progress_printer(total_samples: int) -> Callable[[str, int, int], None] | None:
    """A bar of the ranking stage's grasps on a terminal (core.pipeline.Progress)."""
    if total_samples < PROGRESS_MIN_SAMPLES or not sys.stderr.isatty():
        return None
    started = time.perf_counter()

    def show(stage: str, done: int, total: int) -> None:
        if stage != "rank":
            return
        width = 30
        filled = int(width * done / total)
        elapsed = time.perf_counter() - started
        sys.stderr.write(
            f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} grasps {elapsed:5.1f} s"
        )
        if done == total:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


def rank_scenario(
    scenario: Scenario, metric: str | None = None, backend: str = "auto"
) -> SafetyReport:
    """Load the scenario's robot, rank its grasps and run the analyses the scenario asks for
    (``backend``: EvaluationConfig's); a kernel compiled on the way (first use on a machine)
    is announced on stderr."""
    from ..core.method.ranking import EvaluationConfig, GraspSafetyEvaluator
    from ..core.method.warm_up import announce_compiles
    from ..core.pipeline import run_pipeline

    announce_compiles()
    robot = scenario.robot.load(scenario.base_dir)
    config = EvaluationConfig(metric=metric or scenario.metric, ik=scenario.ik, backend=backend)
    evaluator = GraspSafetyEvaluator(robot, config)
    progress = _progress_printer(len(scenario.grasps) * len(scenario.trajectory.times_s()))
    return run_pipeline(evaluator, scenario.request(robot), progress)


def run_header(scenario: Scenario, report: SafetyReport) -> str:
    """The line printed before the table: robot, problem size and the backend that ran."""
    from ..core.model.armature import published_for
    from ..core.model.robot import NO_ARMATURE_NOTE

    urdf = scenario.robot.urdf
    if urdf.startswith("example-robot-data:"):
        robot = urdf.split(":", 1)[1]
    elif "<" in urdf:
        robot = "(inline URDF)"
    else:
        robot = Path(urdf).name
    header = (
        f"robot {robot} ({scenario.robot.base_frame} -> {scenario.robot.tip_frame}), "
        f"{_problem_size(scenario)}, backend {report.ranking.backend}"
    )
    if not report.ranking.armature_given:
        header += f"\n{NO_ARMATURE_NOTE}"
    elif isinstance(scenario.robot.armature_kgm2, str):
        entry = published_for(scenario.robot.armature_kgm2, scenario.robot.urdf, ())
        header += f"\narmature: published '{entry.name}' ({entry.status}, {entry.date})"
    return header


def _problem_size(scenario: Scenario) -> str:
    """``G grasps x N samples``; grasps with a planned joint trajectory are sampled at its
    points, so their counts are given apart: ``3 grasps: 2 x 41 samples, 1 x 5 (planned)``."""
    counts: dict[tuple[int, bool], int] = {}
    for grasp in scenario.grasps:
        planned = grasp.joint_trajectory
        key = (scenario.trajectory.num_samples, False)
        if planned is not None:
            key = (len(planned.times_s), True)
        counts[key] = counts.get(key, 0) + 1
    grasps = f"{len(scenario.grasps)} grasp{'s' if len(scenario.grasps) != 1 else ''}"
    if len(counts) == 1 and not next(iter(counts))[1]:
        return f"{grasps} x {scenario.trajectory.num_samples} samples"
    groups = [
        f"{count} x {samples} samples{' (planned)' if planned else ''}"
        for (samples, planned), count in counts.items()
    ]
    return f"{grasps}: {', '.join(groups)}"


def _write_outputs(
    report: SafetyReport,
    json_path: Path | None,
    plot_path: Path | None,
    title: str,
    per_sample: bool = True,
) -> list[Path]:
    """Write the --json and --plot files; returns the paths written, in order. Called before
    the table is printed, so a reader that stops early (``| head``) cannot cost a file."""
    written: list[Path] = []
    if json_path is not None:
        from .report import report_json_bytes

        data = report_json_bytes(report, per_sample)
        try:
            json_path.parent.mkdir(parents=True, exist_ok=True)
            json_path.write_bytes(data)
        except OSError as error:
            raise InvalidInputError(
                "--json", f"cannot write '{json_path}': {error.strerror or error}"
            ) from None
        written.append(json_path)
    if plot_path is not None:
        from .plotting import plot_report

        try:
            plot_report(report, plot_path, title)
            if report.retimed:
                from .retime_plot import plot_retimed

                written.extend(plot_retimed(report, plot_path, title))
        except (OSError, ValueError) as error:  # ValueError: a format matplotlib lacks
            reason = getattr(error, "strerror", None) or " ".join(str(error).split())
            raise InvalidInputError("--plot", f"cannot write '{plot_path}': {reason}") from None
        written.append(plot_path)
    return written


def _print_results(scenario: Scenario, report: SafetyReport, written: list[Path]) -> None:
    from .report import report_text

    print(run_header(scenario, report))
    print(report_text(report))
    for path in written:
        print(f"wrote {path}")


def _command_rank(args: argparse.Namespace) -> int:
    from ..scenario.schema import load_scenario

    scenario = load_scenario(args.scenario)
    if args.retime and scenario.options.retime is None:  # the limits: refused when missing
        from dataclasses import replace

        from ..scenario.fields import read_yaml_file
        from ..scenario.schema import parse_retime

        section = read_yaml_file(args.scenario).get("retime")  # its limits, even if disabled
        retime = parse_retime(section, requested=True)
        scenario = replace(scenario, options=replace(scenario.options, retime=retime))
    report = rank_scenario(scenario, args.metric)
    written = _write_outputs(
        report, args.json, args.plot, Path(args.scenario).name, args.per_sample
    )
    _print_results(scenario, report, written)
    return 0


def _command_demo(args: argparse.Namespace) -> int:
    from ..scenario.schema import load_scenario

    path = config_file(DEMO_SCENARIO)
    print(f"demo: the paper's book experiment on Baxter ({path})")
    scenario = load_scenario(path)
    report = rank_scenario(scenario, backend=DEMO_BACKEND)
    out = Path(args.out)
    written = _write_outputs(
        report, out / "ranking.json", out / "ranking.png", "book on Baxter (demo)"
    )
    _print_results(scenario, report, written)
    return 0


def _command_reproduce(args: argparse.Namespace) -> int:
    from ..validation import format_summary, reproduce

    results = reproduce(Path(args.out), quick=args.quick)
    print(format_summary(results))
    return 0


def _command_robots(args: argparse.Namespace) -> int:
    from .robots import robots_text

    print(robots_text())
    return 0


def _command_frames(args: argparse.Namespace) -> int:
    from .robots import frames_text

    print(frames_text(args.model))
    return 0


def _command_batch(args: argparse.Namespace) -> int:
    try:  # pyarrow, h5py, dask and tqdm are needed by this command only
        from ..dataset.commands import command_batch

        return command_batch(args)
    except ImportError as error:
        missing = error.name or str(error)
        raise InvalidInputError(
            "batch", f"needs the package {missing!r}: pip install -r requirements.txt"
        ) from None


def _non_negative_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``grasp-safety``."""
    parser = argparse.ArgumentParser(
        prog="grasp-safety",
        description="Rank grasps by the effective mass of robot + object along the "
        "post-grasp trajectory (lower = safer impacts).",
    )
    commands = parser.add_subparsers(dest="command", required=True)
    rank = commands.add_parser("rank", help="rank the grasps of a scenario file")
    rank.add_argument("scenario", help="scenario YAML file")
    rank.add_argument("--json", type=Path, help="write the full result as JSON")
    rank.add_argument(
        "--no-per-sample",
        dest="per_sample",
        action="store_false",
        help="leave the per-sample arrays out of the JSON (per-grasp results only)",
    )
    rank.add_argument("--plot", type=Path, help="write the heatmap and curves as PNG")
    rank.add_argument("--metric", choices=METRICS, help="override the scenario's metric")
    rank.add_argument(
        "--retime",
        action="store_true",
        help="retime each grasp to the ISO/TS 15066 site speed limits (needs the scenario's "
        "retime.joint_acceleration_limits; docs/safe_speed.md)",
    )
    rank.set_defaults(handler=_command_rank)
    demo = commands.add_parser("demo", help="the paper's book experiment on the bundled Baxter")
    demo.add_argument("--out", default="demo_output", help="output folder (default: %(default)s)")
    demo.set_defaults(handler=_command_demo)
    robots = commands.add_parser(
        "robots", help="the bundled robots: base and tip frames, DOF and an IK seed that works"
    )
    robots.set_defaults(handler=_command_robots)
    frames = commands.add_parser(
        "frames", help="a model's frames by kind and the tree of its links (chains)"
    )
    frames.add_argument(
        "model", help="URDF or MJCF file, example-robot-data:<name>, or a robot name"
    )
    frames.set_defaults(handler=_command_frames)
    reproduce = commands.add_parser(
        "reproduce", help="validate with simulated impacts in MuJoCo (the paper's experiments)"
    )
    reproduce.add_argument("--out", default="validation_output", help="output folder")
    reproduce.add_argument("--quick", action="store_true", help="a reduced, fast version")
    reproduce.set_defaults(handler=_command_reproduce)
    batch = commands.add_parser(
        "batch", help="safety labels for grasp datasets (ACRONYM, GraspGen, scenario files)"
    )
    batch.add_argument("spec", help="batch SPEC YAML file (docs/batch.md)")
    batch.add_argument("--out", type=Path, required=True, help="output folder (Parquet parts)")
    batch.add_argument("--scheduler", help="Dask scheduler address tcp://HOST:PORT")
    batch.add_argument(
        "--workers", type=_non_negative_int, default=0, help="local pool size (0: one per core)"
    )
    batch.add_argument("--resume", action="store_true", help="keep parts already written")
    batch.add_argument("--per-sample", action="store_true", help="add per-sample series")
    batch.add_argument(
        "--allow-refused",
        action="store_true",
        help="exit 0 when source files are refused (each is still printed with its reason)",
    )
    batch.set_defaults(handler=_command_batch)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code (2 on bad input, with one line on stderr naming the
    field; ``batch`` lists each refused input on a line of its own before it)."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args))
    except GraspSafetyError as error:
        one_line = " ".join(line.strip() for line in str(error).splitlines())
        print(f"grasp-safety: error: {one_line}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # a reader that stopped early (head): the files are written by then
        sys.stderr.close()
        return 0


QUICK_EXIT_COMMANDS = ("rank", "demo")
"""Commands whose process ends without Python's teardown once its output is flushed: freeing
the compiled kernels' machine code and numba's and Pinocchio's modules takes 0.3-0.6 s, more
than a small ranking (docs/performance_pipeline.md); nothing of theirs is left to finish."""


def run() -> None:
    """The ``grasp-safety`` console script: ``main`` on the command line's arguments, then the
    process's exit (at once after QUICK_EXIT_COMMANDS)."""
    argv = sys.argv[1:]
    status = main(argv)
    if argv and argv[0] in QUICK_EXIT_COMMANDS:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        except (BrokenPipeError, ValueError):  # a reader that stopped early; a closed stream
            pass
        os._exit(status)
    sys.exit(status)


if __name__ == "__main__":  # (profilers run this: the ordinary exit)
    sys.exit(main())
