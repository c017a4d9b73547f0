"""Spike (issue 30, start-up), not a supported path: the kernels ``grasp-safety rank`` calls,
compiled ahead of time with ``numba.pycc`` (pending deprecation since numba 0.57, still in
0.68), and the command run in a process that never imports numba.

1. Rank the bench's book scenario, 1 grasp x 201 samples, in this process (the JIT kernels,
   from numba's cache): each kernel called through ``call_kernel`` and its signature.
2. Build an extension module (``numba.pycc.CC``, target CPU ``host``) exporting, per kernel,
   a wrapper that calls the JIT dispatcher with that signature: the wrapper links the kernel's
   own compiled code (its options: no fused multiply-add beyond ``contract``, numpy's error
   model, no runtime), so the arithmetic is the JIT's. Timed.
3. Fresh processes, alternated: ``python -c 'import pinocchio'``, ``grasp-safety rank`` (JIT),
   the same with numba hidden and the module's functions in ``call_kernel``'s table; wall
   medians and [min, max], CPU medians, the load.
4. The JSON the AOT process writes against the JIT one, byte for byte.
5. With ``--parts``: where a fresh process's time goes (PARTS), JIT and AOT, and with
   ``--compare CHECKOUT`` the JIT of another checkout (e.g. ``git archive`` of main), its
   bytecode written first: medians per part, a Markdown table.

Run: .venv/bin/python bench/aot_spike.py [--repeats 7] [--keep FOLDER] [--parts]
[--compare CHECKOUT]
"""

from __future__ import annotations

import argparse
import compileall
import contextlib
import io
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from pipeline import CLI, book_scenario, compile_package_bytecode

AOT_RANK = """
import importlib, importlib.util, json, sys
sys.modules["numba"] = None  # never imported: the kernels' modules define plain functions
from grasp_safety_ros.core.method import ik_config
ik_config.NUMBA_AVAILABLE = True  # before any module copies it
from grasp_safety_ros.core.method import compiled
spec = importlib.util.spec_from_file_location(sys.argv[1], sys.argv[2])
aot = importlib.util.module_from_spec(spec)
spec.loader.exec_module(aot)
for module, name in json.loads(sys.argv[3]):
    kernel = getattr(importlib.import_module(module), name)
    compiled._ENTRY_POINTS[kernel] = getattr(aot, name)
sys.argv = ["grasp-safety", *sys.argv[4:]]
from grasp_safety_ros.cli.main import run
run()
"""
"""``grasp-safety`` with numba hidden and the AOT module's functions in call_kernel's table:
argv module name, module path, [[kernel module, kernel name], ...] (JSON), then rank's."""


PARTS = """
import json, os, sys, time
marks = [("start", time.perf_counter())]
def mark(name):
    marks.append((name, time.perf_counter()))
aot, loading = len(sys.argv) > 3, []
import numpy; mark("numpy")
import pinocchio; mark("pinocchio")
import yaml; mark("yaml")
if aot:
    sys.modules["numba"] = None
    from grasp_safety_ros.core.method import ik_config
    ik_config.NUMBA_AVAILABLE = True
else:
    import grasp_safety_ros.core.kernels._jit
    from numba.core.dispatcher import Dispatcher
    compile_or_load = Dispatcher.compile
    def timed(self, signature):
        start = time.perf_counter()
        entry = compile_or_load(self, signature)
        loading.append(time.perf_counter() - start)
        return entry
    Dispatcher.compile = timed
mark("numba")
from grasp_safety_ros.cli.main import run_header
from grasp_safety_ros.cli.report import report_json_bytes, report_text
from grasp_safety_ros.core.method import compiled
from grasp_safety_ros.core.method.ranking import EvaluationConfig, GraspSafetyEvaluator
from grasp_safety_ros.core.method.warm_up import announce_compiles
from grasp_safety_ros.core.pipeline import run_pipeline
from grasp_safety_ros.scenario.schema import load_scenario
mark("the package's modules")
if aot:
    import importlib, importlib.util
    spec = importlib.util.spec_from_file_location(sys.argv[3], sys.argv[4])
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for kernel_module, name in json.loads(sys.argv[5]):
        kernel = getattr(importlib.import_module(kernel_module), name)
        compiled._ENTRY_POINTS[kernel] = getattr(module, name)
mark("AOT module")
announce_compiles()
scenario = load_scenario(sys.argv[1])
robot = scenario.robot.load(scenario.base_dir)
mark("scenario and robot")
evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(metric=scenario.metric, ik=scenario.ik))
report = run_pipeline(evaluator, scenario.request(robot))
mark("ranking, postures, analyses")
assert report.ranking.backend == "compiled", report.ranking.backend
with open(sys.argv[2], "wb") as out:
    out.write(report_json_bytes(report, True))
text = run_header(scenario, report) + report_text(report)
mark("JSON and table")
parts = {name: end - start for (_, start), (name, end) in zip(marks, marks[1:])}
parts["kernels' loading"] = sum(loading) + parts.pop("AOT module")
parts["ranking, postures, analyses"] -= sum(loading)
print(json.dumps(parts))
sys.stdout.flush()
os._exit(0)
"""
"""The steps ``grasp-safety rank`` runs, timed in one fresh process: argv scenario, JSON path,
and for the AOT functions AOT_RANK's three. A kernel's loading from numba's cache happens at
its first call: timed apart (numba's ``Dispatcher.compile``) from the ranking's own time."""


def build(scenario: Path, folder: Path, name: str) -> dict[str, Any]:
    """Steps 1 and 2 (module docstring): the kernels, the module's path, the build time [s]."""
    from numba.pycc import CC

    from grasp_safety_ros.cli.main import main
    from grasp_safety_ros.core.method import compiled

    with contextlib.redirect_stdout(io.StringIO()):
        main(["rank", str(scenario), "--json", str(folder / "jit_in_process.json")])
    cc = CC(name)
    cc.target_cpu = "host"  # the JIT's CPU: its instruction set, its fused multiply-adds
    cc.output_dir = str(folder)
    kernels = []
    for kernel in compiled._ENTRY_POINTS:
        (signature, result), *others = kernel.overloads.items()
        if others:
            raise RuntimeError(f"{kernel.py_func.__name__}: one export per signature needed")
        function = kernel.py_func
        args = ", ".join(f"a{i}" for i in range(len(signature)))
        scope = {"kernel": kernel}
        exec(f"def {function.__name__}({args}):\n    return kernel({args})\n", scope)
        cc.export(function.__name__, result.signature.return_type(*signature))(
            scope[function.__name__]
        )
        kernels.append((function.__module__, function.__name__))
    start = time.perf_counter()
    cc.compile()
    seconds = time.perf_counter() - start
    path = next(folder.glob(f"{name}.*.so"))
    return {"kernels": kernels, "path": path, "build_s": seconds, "bytes": path.stat().st_size}


def _timed(command: list[str]) -> tuple[float, float]:
    """Wall and CPU (user + system) time [s] of ``command``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, timeout=600)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def measure(built: dict[str, Any], scenario: Path, folder: Path, repeats: int) -> dict[str, Any]:
    """Steps 3 and 4 (module docstring)."""
    jit_json, aot_json = folder / "jit.json", folder / "aot.json"
    aot = [sys.executable, "-c", AOT_RANK, built["path"].stem.split(".")[0], str(built["path"])]
    aot += [json.dumps(built["kernels"]), "rank", str(scenario), "--json", str(aot_json)]
    commands = {
        "import_pinocchio": [sys.executable, "-c", "import pinocchio"],
        "rank_jit": [str(CLI), "rank", str(scenario), "--json", str(jit_json)],
        "rank_aot": aot,
    }
    for command in commands.values():
        _timed(command)  # into the page cache
    load = os.getloadavg()[0]
    runs: dict[str, list[tuple[float, float]]] = {key: [] for key in commands}
    for _ in range(repeats):
        for key, command in commands.items():
            runs[key].append(_timed(command))
    result: dict[str, Any] = {"load_before": load, "load_after": os.getloadavg()[0]}
    for key, pairs in runs.items():
        walls = [wall for wall, _ in pairs]
        result[key] = {
            "wall_median_s": statistics.median(walls),
            "wall_range_s": [min(walls), max(walls)],
            "cpu_median_s": statistics.median(cpu for _, cpu in pairs),
        }
    result["aot_json_equals_jit_json"] = aot_json.read_bytes() == jit_json.read_bytes()
    return result


def parts(
    built: dict[str, Any], scenario: Path, folder: Path, repeats: int, compare: Path | None
) -> str:
    """Step 5 (module docstring): the Markdown table of PARTS' medians [ms]."""
    aot = [built["path"].stem.split(".")[0], str(built["path"]), json.dumps(built["kernels"])]
    configs: dict[str, tuple[dict[str, str], list[str]]] = {}
    if compare is not None:
        compileall.compile_dir(compare / "grasp_safety_ros", quiet=1)
        configs[f"JIT, {compare.name}"] = ({"PYTHONPATH": str(compare)}, [])
    configs["JIT"] = ({}, [])
    configs["AOT (spike)"] = ({}, aot)
    runs: dict[str, list[dict[str, float]]] = {label: [] for label in configs}
    interpreter = []
    load = os.getloadavg()[0]
    for _ in range(repeats):
        interpreter.append(_timed([sys.executable, "-c", "pass"])[0])
        for label, (env, extra) in configs.items():
            out = folder / "parts.json"
            command = [sys.executable, "-c", PARTS, str(scenario), str(out), *extra]
            start = time.perf_counter()
            done = subprocess.run(
                command, env={**os.environ, **env}, capture_output=True, text=True, check=True
            )
            whole = time.perf_counter() - start
            runs[label].append(
                {**json.loads(done.stdout.splitlines()[-1]), "whole process": whole}
            )
    rows = [f"| part | {' | '.join(configs)} |", "|---|" + "---|" * len(configs)]
    rows.append(
        "| interpreter (`python -c pass`) | "
        + " | ".join(f"{1e3 * statistics.median(interpreter):.0f}" for _ in configs)
        + " |"
    )
    for part in runs["JIT"][0]:
        medians = [1e3 * statistics.median(run[part] for run in runs[label]) for label in configs]
        rows.append(f"| {part} | {' | '.join(f'{m:.0f}' for m in medians)} |")
    rows.append(
        f"ms, medians of {repeats} fresh processes each, alternated, load {load:.1f} -> "
        f"{os.getloadavg()[0]:.1f}"
    )
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--keep", type=Path, help="build in this folder and keep it")
    parser.add_argument("--parts", action="store_true", help="where the time goes (step 5)")
    parser.add_argument("--compare", type=Path, help="another checkout's JIT in the parts")
    args = parser.parse_args()
    compile_package_bytecode()
    with tempfile.TemporaryDirectory() as scratch:
        folder = args.keep or Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        scenario = book_scenario(1, folder)
        built = build(scenario, folder, "rank_kernels_aot")
        print(
            f"built {len(built['kernels'])} kernels ({', '.join(k for _, k in built['kernels'])})"
            f" in {built['build_s']:.1f} s: {built['bytes'] / 1e6:.1f} MB"
        )
        measured = measure(built, scenario, folder, args.repeats)
        if args.parts:
            print(parts(built, scenario, folder, args.repeats, args.compare))
    pinocchio = measured["import_pinocchio"]["wall_median_s"]
    for key in ("import_pinocchio", "rank_jit", "rank_aot"):
        row = measured[key]
        low, high = row["wall_range_s"]
        print(
            f"{key}: {row['wall_median_s']:.3f} s [{low:.3f}..{high:.3f}] "
            f"(x{row['wall_median_s'] / pinocchio:.2f} import pinocchio), "
            f"CPU {row['cpu_median_s']:.3f} s"
        )
    print(
        f"AOT JSON byte for byte the JIT's: {measured['aot_json_equals_jit_json']}; "
        f"{args.repeats} runs each, alternated, load {measured['load_before']:.1f} -> "
        f"{measured['load_after']:.1f}"
    )


if __name__ == "__main__":
    main()
