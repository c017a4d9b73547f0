"""``grasp-safety batch``: run a SPEC, print where the output went and the summary's counts."""

from __future__ import annotations

import argparse

from .batch import run_batch


def command_batch(args: argparse.Namespace) -> int:
    """Run the batch the arguments describe; 0, or EXIT_BAD_INPUT (by the caller) on a bad
    SPEC. Bad source files do not fail the command: they are counted in summary.json."""
    summary = run_batch(
        args.spec,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        resume=args.resume,
        per_sample=args.per_sample,
    )
    rate = summary["throughput"]["grasp_samples_per_s"]
    print(
        f"wrote {args.out}: {summary['grasps']} grasps ({summary['feasible']} feasible, "
        f"{summary['infeasible']} infeasible, {summary['unreadable_grasps']} unreadable), "
        f"{summary['files_refused']} files refused, {summary['chunks_computed']} of "
        f"{summary['chunks']} chunks computed"
        + (f", {rate:.0f} (grasp, sample)/s" if rate else "")
    )
    return 0
