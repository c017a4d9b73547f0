"""The batch: chunks of (source file, grasp range), each ranked by ``run_pipeline`` and
written as one Parquet part (atomically), on the package's own pool or a Dask cluster.

Output folder: ``parts/part-00000.parquet`` ... (one per chunk, in plan order, each with its
chunk's content hash in the file metadata), ``manifest.json`` (versions, the parts in order;
written last, removed when a run starts) and ``summary.json`` (counts, failures by reason,
throughput). A part whose stored hash equals its chunk's (same SPEC, same source bytes and
robot description, same range, same package sources) is not computed again with ``resume``.
Local and Dask runs give identical part files.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
import re
import resource
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pyarrow as pa
import pyarrow.parquet as pq

from .. import __version__
from ..core.exceptions import GraspSafetyError, InvalidInputError, field_and_reason
from ..core.method.ranking import EvaluationConfig, GraspSafetyEvaluator
from ..core.method.warm_up import warm_up
from ..core.model.robot import resolve_urdf
from ..core.pipeline import run_pipeline
from ..scenario.fields import read_yaml_file
from ..scenario.schema import Scenario
from .rows import block_columns
from .schema import SCHEMA_VERSION, grasp_schema, table
from .sources import Failure, GraspBlock, SourceFile, discover, load_block, scenario_of
from .spec import BatchSpec, parse_spec

if TYPE_CHECKING:
    from distributed import Client  # imported when a batch runs on Dask

PARTS = "parts"
"""Subfolder of the part files."""

MANIFEST = "manifest.json"
"""File of a finished batch's parts in order (what ``read_batch`` reads)."""

HASH_KEY = b"grasp_safety.chunk_hash"
"""Parquet metadata key of a part's chunk content hash."""

PROGRESS_LINES = 20
"""Plain progress lines per run when stderr is not a terminal."""

MAX_LISTED_FAILURES = 1000
"""Failures listed one by one in summary.json (all are counted)."""


@dataclass(frozen=True)
class SpecPayload:
    """What a worker needs to rebuild the SPEC: its YAML data and folder (sent once per run,
    parsed once per worker process)."""

    data: Any
    base_dir: str
    content_hash: str
    per_sample: bool


@dataclass(frozen=True)
class Chunk:
    """Grasps [start, stop) of one source file: one task, one part file."""

    index: int
    source: SourceFile
    start: int
    stop: int
    content_hash: str

    @property
    def part_name(self) -> str:
        """File name of the chunk's part (sorts in plan order)."""
        return f"part-{self.index:05d}.parquet"


@dataclass(frozen=True)
class ChunkResult:
    """A chunk's rows and what it cost.

    Attributes:
        grasp_samples: Readable grasps x trajectory samples evaluated.
        seconds: Wall time of the chunk in its worker [s].
        max_rss_kb: Peak resident memory of the worker process so far [KiB].
        worker: Process id of the worker.
    """

    index: int
    table: pa.Table
    grasp_samples: int
    seconds: float
    max_rss_kb: int
    worker: int


@functools.cache
def code_sha256() -> str:
    """SHA-256 of the package's Python sources (names and bytes), once per process: a part
    computed by other code is not resumed."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _robot_sha256(source: SourceFile) -> str:
    """For a scenario file, the digest of the robot description it points to ("" if it
    cannot be read: its rows say why); "" for other formats (the SPEC's robot is in its
    hash)."""
    if source.format != "scenarios":
        return ""
    try:
        scenario = scenario_of(source)
        return description_sha256(scenario.robot.urdf, scenario.base_dir)
    except (GraspSafetyError, OSError):
        return ""


def plan_chunks(spec: BatchSpec, files: Sequence[SourceFile], per_sample: bool) -> list[Chunk]:
    """Chunks of at most ``spec.chunk_grasps`` grasps, file by file, in order."""
    chunks: list[Chunk] = []
    for source in files:
        robot = _robot_sha256(source)
        for start in range(0, source.num_grasps, spec.chunk_grasps):
            stop = min(start + spec.chunk_grasps, source.num_grasps)
            inputs = (spec.content_hash, per_sample, source.format, source.name, source.sha256)
            key = json.dumps(
                [SCHEMA_VERSION, __version__, code_sha256(), *inputs, robot, start, stop]
            )
            digest = hashlib.sha256(key.encode()).hexdigest()
            chunks.append(Chunk(len(chunks), source, start, stop, digest))
    return chunks


# In each worker process --------------------------------------------------------------------

_LOCK = threading.Lock()
_WARMED = False
_SPECS: dict[str, BatchSpec] = {}
_EVALUATORS: dict[tuple[str, ...], GraspSafetyEvaluator] = {}


def description_sha256(urdf: str, base_dir: Path | None) -> str:
    """SHA-256 of a robot description: of its file's bytes when ``urdf`` names a file (so an
    edited file counts as another robot), else of the XML text."""
    text, is_xml = resolve_urdf(urdf, base_dir)
    return hashlib.sha256(text.encode() if is_xml else Path(text).read_bytes()).hexdigest()


def _warm_up_once() -> None:
    """Compile (or load) the numba kernels once per process, not per task."""
    global _WARMED
    with _LOCK:
        if not _WARMED:
            warm_up()
            _WARMED = True


def _spec(payload: SpecPayload) -> BatchSpec:
    with _LOCK:
        if payload.content_hash not in _SPECS:
            _SPECS[payload.content_hash] = parse_spec(payload.data, Path(payload.base_dir))
        return _SPECS[payload.content_hash]


def _evaluator(scenario: Scenario, workers: int) -> GraspSafetyEvaluator:
    """The process's evaluator for the scenario's robot, metric and IK (URDF parsed once)."""
    robot = scenario.robot
    key = (
        json.dumps(dataclasses.asdict(robot), sort_keys=True, default=str),
        description_sha256(robot.urdf, scenario.base_dir),
        str(scenario.base_dir),
        scenario.metric,
        repr(scenario.ik),
        str(workers),
    )
    with _LOCK:
        if key not in _EVALUATORS:
            # a chunk is already a coarse unit: share out whatever its size
            config = EvaluationConfig(
                metric=scenario.metric, ik=scenario.ik, workers=workers, parallel_min_samples=1
            )
            _EVALUATORS[key] = GraspSafetyEvaluator(robot.load(scenario.base_dir), config)
        return _EVALUATORS[key]


def _unreadable(chunk: Chunk, key: str, reason: str) -> GraspBlock:
    count = chunk.stop - chunk.start
    return GraspBlock(
        source=chunk.source,
        start=chunk.start,
        grasp_ids=tuple(str(chunk.start + k) for k in range(count)),
        labels=(None,) * count,
        errors=((key, reason),) * count,
        scenario=None,
    )


def evaluate_chunk(payload: SpecPayload, chunk: Chunk, workers: int) -> ChunkResult:
    """Rank one chunk in this process (``workers``: the package pool's size; 1 inside Dask
    workers so pools do not nest). An input error makes error rows, not a failed chunk."""
    started = time.perf_counter()
    _warm_up_once()
    spec = _spec(payload)
    try:
        block = load_block(spec, chunk.source, chunk.start, chunk.stop)
    except GraspSafetyError as error:
        block = _unreadable(chunk, *field_and_reason(error))
    except OSError as error:
        block = _unreadable(chunk, "/", f"cannot read: {error.strerror or error}")
    report, samples = None, 0
    if block.scenario is not None:
        try:
            evaluator = _evaluator(block.scenario, workers)
            report = run_pipeline(evaluator, block.scenario.request(evaluator.robot))
            samples = len(block.scenario.grasps) * block.scenario.trajectory.num_samples
        except GraspSafetyError as error:
            block = _unreadable(chunk, *field_and_reason(error))
    metric = block.scenario.metric if block.scenario is not None else spec.metric
    columns = block_columns(block, report, metric, payload.per_sample)
    return ChunkResult(
        index=chunk.index,
        table=table(columns, payload.per_sample),
        grasp_samples=samples,
        seconds=time.perf_counter() - started,
        max_rss_kb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
        worker=os.getpid(),
    )


# In the driver -----------------------------------------------------------------------------


def _atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """``write`` to a temporary file beside ``path``, then rename it over ``path``."""
    temporary = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        write(temporary)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def write_part(out_dir: Path, chunk: Chunk, rows: pa.Table) -> None:
    """The chunk's part file, with its content hash in the metadata, written atomically."""
    rows = rows.replace_schema_metadata({HASH_KEY: chunk.content_hash.encode()})
    _atomic_write(out_dir / PARTS / chunk.part_name, lambda path: pq.write_table(rows, path))


def _write_json(path: Path, data: Any) -> None:
    text = json.dumps(data, indent=1, allow_nan=False)
    _atomic_write(path, lambda p: p.write_text(text + "\n", encoding="utf-8"))


def part_is_done(out_dir: Path, chunk: Chunk) -> bool:
    """Whether the chunk's part exists with the chunk's content hash."""
    path = out_dir / PARTS / chunk.part_name
    try:
        metadata = pq.read_schema(path).metadata or {}
    except (OSError, pa.ArrowInvalid):
        return False
    return metadata.get(HASH_KEY) == chunk.content_hash.encode()


def read_batch(out_dir: str | Path, columns: Sequence[str] | None = None) -> pa.Table:
    """The grasp table of a finished batch (its parts in manifest order), all columns or
    ``columns``."""
    out_dir = Path(out_dir)
    try:
        manifest = json.loads((out_dir / MANIFEST).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InvalidInputError(
            MANIFEST, f"missing in '{out_dir}': the batch did not finish; run it again"
        ) from None
    schema = grasp_schema(manifest["per_sample"])
    if columns is not None:
        schema = pa.schema([schema.field(name) for name in columns])
    tables = []
    for part in manifest["parts"]:
        rows = pq.read_table(out_dir / PARTS / part["file"], columns=columns)
        if (rows.schema.metadata or {}).get(HASH_KEY) != part["chunk_hash"].encode():
            raise InvalidInputError(
                f"{PARTS}/{part['file']}",
                f"is not the part {MANIFEST} lists (another chunk hash): the batch in "
                f"'{out_dir}' is incomplete or was changed; run it again",
            )
        tables.append(rows.replace_schema_metadata())
    return pa.concat_tables(tables) if tables else schema.empty_table()


class _Progress:
    """A tqdm bar on a terminal; otherwise a plain line per about 1/PROGRESS_LINES of it."""

    def __init__(self, total: int, done: int) -> None:
        self.total, self.done, self.started = total, done, time.perf_counter()
        self.every = max(1, total // PROGRESS_LINES)
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=done, unit="chunk", file=sys.stderr)

    def step(self) -> None:
        self.done += 1
        if self.bar is not None:
            self.bar.update(1)
        elif self.done % self.every == 0 or self.done == self.total:
            elapsed = time.perf_counter() - self.started
            print(f"batch: {self.done}/{self.total} chunks, {elapsed:.1f} s", file=sys.stderr)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _run_local(
    payload: SpecPayload, chunks: Sequence[Chunk], workers: int
) -> Iterator[ChunkResult]:
    for chunk in chunks:
        yield evaluate_chunk(payload, chunk, workers)


def _run_dask(
    payload: SpecPayload, chunks: Sequence[Chunk], client: Client
) -> Iterator[ChunkResult]:
    """The chunks as one Dask graph (the SPEC a single shared node), computed at once; the
    results as they complete."""
    import dask
    from distributed import as_completed

    shared = dask.delayed(payload, pure=True)
    tasks = [
        dask.delayed(evaluate_chunk, pure=True)(
            shared, chunk, 1, dask_key_name=f"chunk-{chunk.content_hash}"
        )
        for chunk in chunks
    ]
    for future in as_completed(client.compute(tasks)):
        yield future.result()
        future.release()


def _connect(address: str) -> Client:
    """A ``distributed.Client`` of the scheduler at ``address``; a one-line error naming
    ``--scheduler`` when there is none (timeout: distributed.comm.timeouts.connect)."""
    from distributed import Client

    try:
        return Client(address)
    except (OSError, ValueError, TypeError) as error:  # TimeoutError is an OSError
        reason = " ".join(str(error).split()) or type(error).__name__
        raise InvalidInputError(
            "--scheduler", f"cannot connect to {address!r}: {reason}"
        ) from None


def _reason_pattern(reason: str) -> str:
    """A failure reason with its numbers as '#', so alike failures count together."""
    return re.sub(r"[-+]?\d+(\.\d+)?([eE][-+]?\d+)?", "#", reason)[:160]


def summarise(out_dir: Path, failures: Sequence[Failure]) -> dict[str, Any]:
    """Counts and failures of a finished batch, from its parts (so they do not depend on how
    it was computed or resumed); reads the few columns needed, not the per-sample ones."""
    import pyarrow.compute as pc

    rows = read_batch(out_dir, ["source", "feasible", "reason", "error_key"])
    failed = rows.filter(pc.invert(rows.column("feasible")))
    unreadable = failed.filter(pc.is_valid(failed.column("error_key")))
    listed = [{"file": f.file, "key": f.key, "reason": f.reason} for f in failures]
    listed += [
        {"file": r["source"], "key": r["error_key"], "reason": r["reason"]}
        for r in unreadable.slice(0, MAX_LISTED_FAILURES).to_pylist()
    ]
    by_reason: Counter[str] = Counter()
    for item in pc.value_counts(failed.column("reason")).to_pylist():
        by_reason[_reason_pattern(item["values"])] += item["counts"]
    by_reason.update(_reason_pattern(f"file refused: {f.reason}") for f in failures)
    return {
        "grasps": rows.num_rows,
        "feasible": rows.num_rows - failed.num_rows,
        "infeasible": failed.num_rows - unreadable.num_rows,
        "unreadable_grasps": unreadable.num_rows,
        "files_refused": len(failures),
        "refused_files": [{"file": f.file, "key": f.key, "reason": f.reason} for f in failures],
        "failures_by_reason": dict(sorted(by_reason.items(), key=lambda kv: (-kv[1], kv[0]))),
        "failures": listed[:MAX_LISTED_FAILURES],
    }


def run_batch(
    spec_path: str | Path,
    out_dir: str | Path,
    *,
    workers: int = 0,
    scheduler: str | None = None,
    client: Client | None = None,
    resume: bool = False,
    per_sample: bool = False,
) -> dict[str, Any]:
    """Run the batch of a SPEC file into ``out_dir``; returns the summary (also written).

    Args:
        workers: The package pool's size on this machine (0: one per core); ignored on Dask.
        scheduler: A Dask scheduler address (``tcp://host:port``); None: this machine.
        client: A ``distributed.Client`` to use instead (tests, notebooks).
        resume: Keep the parts already written for the same inputs.
    """
    spec_path = Path(spec_path)
    data = read_yaml_file(spec_path, "spec")
    spec = parse_spec(data, spec_path.resolve().parent)
    out_dir = Path(out_dir)
    (out_dir / PARTS).mkdir(parents=True, exist_ok=True)
    (out_dir / MANIFEST).unlink(missing_ok=True)  # until this run has written every part
    files, failures = discover(spec)
    chunks = plan_chunks(spec, files, per_sample)
    todo = [c for c in chunks if not (resume and part_is_done(out_dir, c))]
    payload = SpecPayload(data, str(spec.base_dir), spec.content_hash, per_sample)
    progress = _Progress(len(chunks), len(chunks) - len(todo))
    started = time.perf_counter()
    samples, seconds, rss = _compute_parts(
        out_dir, chunks, todo, payload, progress, workers, scheduler, client
    )
    wall = time.perf_counter() - started
    _remove_stale_parts(out_dir, chunks)
    _write_json(out_dir / MANIFEST, _manifest(spec, chunks, per_sample))
    summary = summarise(out_dir, failures)
    summary.update(
        {
            "chunks": len(chunks),
            "chunks_computed": len(todo),
            "chunks_resumed": len(chunks) - len(todo),
            "scheduler": scheduler or ("dask client" if client is not None else "local"),
            "throughput": {
                "wall_s": wall,
                "grasp_samples": int(samples),
                "grasp_samples_per_s": samples / wall if wall > 0 else None,
                "chunk_seconds_total": seconds,
                "peak_memory_per_worker_mib": {
                    str(pid): kb / 1024 for pid, kb in sorted(rss.items())
                },
            },
        }
    )
    _write_json(out_dir / "summary.json", summary)
    return summary


def _compute_parts(
    out_dir: Path,
    chunks: Sequence[Chunk],
    todo: Sequence[Chunk],
    payload: SpecPayload,
    progress: _Progress,
    workers: int,
    scheduler: str | None,
    client: Client | None,
) -> tuple[float, float, dict[int, int]]:
    """Computes the ``todo`` chunks (on Dask with a scheduler or a client, else in the local
    pool) and writes each part as it arrives; returns the grasp samples, the chunks' total
    compute time [s] and each worker's peak resident memory [KiB]."""
    samples = seconds = 0.0
    rss: dict[int, int] = {}
    own_client = None
    try:
        if scheduler is not None and client is None:
            client = own_client = _connect(scheduler)
        results = (
            _run_dask(payload, todo, client)
            if client is not None
            else _run_local(payload, todo, workers or 0)
        )
        for result in results:
            write_part(out_dir, chunks[result.index], result.table)
            samples += result.grasp_samples
            seconds += result.seconds
            rss[result.worker] = max(rss.get(result.worker, 0), result.max_rss_kb)
            progress.step()
    finally:
        progress.close()
        if own_client is not None:
            own_client.close()
    return samples, seconds, rss


def _remove_stale_parts(out_dir: Path, chunks: Sequence[Chunk]) -> None:
    """Deletes the part files of ``out_dir`` this plan does not have (an earlier run's)."""
    planned = {c.part_name for c in chunks}
    for stale in (out_dir / PARTS).glob("*part-*"):
        if stale.name not in planned:
            stale.unlink()


def _manifest(spec: BatchSpec, chunks: Sequence[Chunk], per_sample: bool) -> dict[str, Any]:
    """The manifest of a finished run: versions, the spec's hash and every part's chunk."""
    return {
        "package_version": __version__,
        "schema_version": SCHEMA_VERSION,
        "pyarrow_version": pa.__version__,
        "spec_hash": spec.content_hash,
        "per_sample": per_sample,
        "parts": [
            {
                "file": c.part_name,
                "chunk_hash": c.content_hash,
                "source": c.source.name,
                "start": c.start,
                "stop": c.stop,
            }
            for c in chunks
        ],
    }
