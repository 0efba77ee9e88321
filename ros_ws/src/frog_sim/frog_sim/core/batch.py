"""Batch runner: many independent simulations in chunks, on local processes or a Dask cluster.

The work is ``n_items`` independent items (e.g. initial states of the motion library),
split into fixed chunks. A chunk is computed by a plain module-level function
``task(spec, start, stop) -> dict[str, ndarray]`` whose result depends only on ``spec``
and the item range, so outputs are bit-identical whatever the number or kind of workers.
Each finished chunk is written atomically (temporary file + rename) into a work folder
with a manifest; a rerun with the same spec skips the chunks already there, so an
interrupted run resumes and never leaves a corrupt chunk.

Examples
--------
>>> result = run_chunked(task, spec, n_items=1000, chunk_size=50,
...                      work_dir='runs/lib.chunks')                # doctest: +SKIP
>>> result = run_chunked(task, spec, 1000, 50, 'runs/lib.chunks',
...                      scheduler='tcp://10.0.0.5:8786')           # doctest: +SKIP
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from frog_common.atomic_files import atomic_save_npz

__all__ = ["BatchError", "run_chunked", "spec_hash", "chunk_ranges"]


class BatchError(RuntimeError):
    """A batch cannot run or resume (mismatched work folder, failed chunk, bad arguments)."""


def spec_hash(spec: dict) -> str:
    """SHA-256 of the canonical JSON of ``spec`` (what a work folder is bound to)."""
    text = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    raise TypeError(f"spec value {obj!r} of type {type(obj).__name__} is not JSON-serialisable")


def chunk_ranges(n_items: int, chunk_size: int) -> list[tuple[int, int]]:
    """``[(start, stop), ...]`` covering ``range(n_items)`` in chunks of ``chunk_size``."""
    if n_items < 0 or chunk_size < 1:
        raise BatchError(f"n_items = {n_items} must be >= 0 and chunk_size = {chunk_size} >= 1")
    return [(s, min(s + chunk_size, n_items)) for s in range(0, n_items, chunk_size)]


def _load_chunk(path: Path) -> Optional[dict]:
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError):
        return None  # unreadable: recompute


def _run_task(task, spec, start, stop):
    return task(spec, start, stop)


def run_chunked(task: Callable, spec: dict, n_items: int, chunk_size: int, work_dir,
                workers: Optional[int] = None, scheduler: Optional[str] = None,
                progress: bool = True, desc: str = "chunks") -> dict:
    """Run ``task`` over all chunks (resuming), and return the concatenated arrays.

    Parameters
    ----------
    task : callable
        Module-level (picklable) ``task(spec, start, stop) -> dict[str, ndarray]``; every
        array's first axis has length ``stop - start``.
    spec : dict
        JSON-serialisable description of the work; bound to the work folder by its hash.
    n_items, chunk_size : int
        Number of items and items per chunk.
    work_dir : path
        Folder for the manifest and chunk files (created; reused to resume).
    workers : int, optional
        Local worker processes (default: all cores). 1 runs in this process.
    scheduler : str, optional
        Dask scheduler address (``tcp://host:8786``); the same task runs on its workers.
    progress : bool
        tqdm progress bar (items, rate, ETA).

    Returns
    -------
    dict of ndarray
        Every key concatenated over the chunks in item order.

    Raises
    ------
    BatchError
        If ``work_dir`` holds chunks of a different spec, or a chunk fails.
    """
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    ranges = chunk_ranges(n_items, chunk_size)
    digest = spec_hash({"spec": spec, "n_items": n_items, "chunk_size": chunk_size})
    manifest = work / "manifest.json"
    if manifest.exists():
        old = json.loads(manifest.read_text())
        if old.get("hash") != digest:
            raise BatchError(f"work folder {str(work)!r} holds chunks of another job (spec hash "
                             f"{old.get('hash', '?')[:12]} != {digest[:12]}); use another folder "
                             f"or delete it")
    else:
        manifest.write_text(json.dumps({"hash": digest, "n_items": n_items,
                                        "chunk_size": chunk_size, "spec": spec},
                                       default=_json_default, indent=1))

    def chunk_path(i):
        return work / f"chunk_{i:06d}.npz"

    results: dict[int, dict] = {}
    for i, _ in enumerate(ranges):
        if chunk_path(i).exists():
            loaded = _load_chunk(chunk_path(i))
            if loaded is not None:
                results[i] = loaded
    todo = [i for i in range(len(ranges)) if i not in results]

    bar = None
    if progress:
        from tqdm import tqdm
        done_items = sum(ranges[i][1] - ranges[i][0] for i in results)
        bar = tqdm(total=n_items, initial=done_items, unit="item", desc=desc, smoothing=0.05)

    def finish(i, arrays):
        start, stop = ranges[i]
        for k, v in arrays.items():
            if np.shape(v)[:1] != (stop - start,):
                raise BatchError(f"task returned {k!r} with shape {np.shape(v)} for chunk "
                                 f"{start}:{stop}; first axis must be {stop - start}")
        atomic_save_npz(chunk_path(i), arrays)
        results[i] = arrays
        if bar is not None:
            bar.update(stop - start)

    try:
        if todo and scheduler:
            _run_dask(task, spec, ranges, todo, scheduler, finish)
        elif todo and (workers == 1 or len(todo) == 1):
            for i in todo:
                finish(i, _run_task(task, spec, *ranges[i]))
        elif todo:
            _run_pool(task, spec, ranges, todo, workers or os.cpu_count() or 1, finish)
    finally:
        if bar is not None:
            bar.close()
    if not ranges:
        return {}
    keys = results[0].keys()
    return {k: np.concatenate([results[i][k] for i in range(len(ranges))]) for k in keys}


def _run_pool(task, spec, ranges, todo, workers, finish):
    # spawn: workers start clean (no inherited threads or locks), and import what they need
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        pending = {pool.submit(_run_task, task, spec, *ranges[i]): i for i in todo}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                i = pending.pop(fut)
                try:
                    arrays = fut.result()
                except Exception as exc:
                    for f in pending:
                        f.cancel()
                    raise BatchError(f"chunk {i} (items {ranges[i][0]}:{ranges[i][1]}) failed: "
                                     f"{exc!r}") from exc
                finish(i, arrays)


def _run_dask(task, spec, ranges, todo, scheduler, finish):
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - dask is in the requirements
        raise BatchError("a Dask scheduler was given but 'distributed' is not installed") from exc
    try:
        client = Client(scheduler, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise BatchError(f"cannot connect to the Dask scheduler at {scheduler!r}: {exc}") from exc
    try:
        futures = {client.submit(_run_task, task, spec, *ranges[i], pure=False): i for i in todo}
        for fut in as_completed(list(futures)):
            i = futures[fut]
            try:
                arrays = fut.result()
            except Exception as exc:
                raise BatchError(f"chunk {i} failed on the Dask cluster: {exc!r}") from exc
            finish(i, arrays)
    finally:
        client.close()
