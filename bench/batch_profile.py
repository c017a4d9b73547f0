"""Profile of ``grasp-safety batch``'s chunks (issue 30): bench/batch.py's workload (Panda box
grasps in ACRONYM files, 51 samples, 8 posture restarts, ISO/TS 15066), CHUNKS chunks of
bench/batch.py's CHUNK grasps run by ``evaluate_chunk`` in this process on one worker, under
cProfile after one warm chunk (kernels loaded, first-use costs paid); prints the chunks' rate
and the functions by own time and by cumulative time.

Run: .venv/bin/python bench/batch_profile.py [--chunks 3] [--top 25]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import tempfile
import time
from pathlib import Path

from batch import CHUNK, write_dataset

from grasp_safety_ros.dataset.batch import SpecPayload, evaluate_chunk, plan_chunks
from grasp_safety_ros.dataset.sources import discover
from grasp_safety_ros.dataset.spec import parse_spec
from grasp_safety_ros.scenario.fields import read_yaml_file


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--chunks", type=int, default=3)
    parser.add_argument("--top", type=int, default=25)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        spec_path = write_dataset(root, CHUNK * (args.chunks + 1), CHUNK)
        data = read_yaml_file(spec_path, "spec")
        spec = parse_spec(data, root)
        chunks = plan_chunks(spec, discover(spec)[0], per_sample=False)
        payload = SpecPayload(data, str(spec.base_dir), spec.content_hash, False)
        evaluate_chunk(payload, chunks[0], 1)  # warm
        profile = cProfile.Profile()
        started = time.perf_counter()
        profile.enable()
        samples = sum(evaluate_chunk(payload, c, 1).grasp_samples for c in chunks[1:])
        profile.disable()
        wall = time.perf_counter() - started
    print(
        f"{len(chunks) - 1} chunks of {CHUNK} grasps: {samples} (grasp, sample) in {wall:.2f} s "
        f"under cProfile = {samples / wall:.0f} /s on one worker"
    )
    for order in ("tottime", "cumulative"):
        text = io.StringIO()
        pstats.Stats(profile, stream=text).sort_stats(order).print_stats(args.top)
        print(text.getvalue())


if __name__ == "__main__":
    main()
