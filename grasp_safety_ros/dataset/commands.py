"""``grasp-safety batch``: run a SPEC, print where the output went, the summary's counts and
every refused input with its reason."""

from __future__ import annotations

import argparse
import sys

from ..core.exceptions import InvalidInputError
from .batch import run_batch


def command_batch(args: argparse.Namespace) -> int:
    """Run the batch the arguments describe; 0, or EXIT_BAD_INPUT (by the caller) on a bad
    SPEC or, without ``--allow-refused``, when a requested input (a source file, a glob that
    matches nothing) is refused. The output is written either way; each refused input is
    printed on stderr with its key and reason. Unreadable grasps of a file that is read are
    rows with an error (counted), not refusals."""
    summary = run_batch(
        args.spec,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        resume=args.resume,
        per_sample=args.per_sample,
    )
    refused = summary["refused_files"]
    for item in refused:
        print(
            f"grasp-safety: refused {item['file']}: {item['key']}: {item['reason']}",
            file=sys.stderr,
        )
    rate = summary["throughput"]["grasp_samples_per_s"]
    print(
        f"wrote {args.out}: {summary['grasps']} grasps ({summary['feasible']} feasible, "
        f"{summary['infeasible']} infeasible, {summary['unreadable_grasps']} unreadable), "
        f"{summary['files_refused']} files refused, {summary['chunks_computed']} of "
        f"{summary['chunks']} chunks computed"
        + (f", {rate:.0f} (grasp, sample)/s" if rate else "")
    )
    if refused and not args.allow_refused:
        raise InvalidInputError(
            "sources",
            f"{len(refused)} requested input{'s' if len(refused) != 1 else ''} refused (listed "
            "above); --allow-refused accepts a partial run",
        )
    return 0
