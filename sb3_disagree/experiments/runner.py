"""
Running an experiment's grid: a local process pool (default) or Ray tasks on a cluster.

A run is finished when its ``result.json`` exists; it is written last and atomically, so an
interrupted experiment resumes by skipping the finished runs. Each run keeps torch to one thread, since
several runs share a machine.
"""

import json
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict
from pathlib import Path
from typing import Any, Optional

import yaml

from sb3_disagree.experiments.curves import write_curves
from sb3_disagree.experiments.spec import RESULT, Experiment, Run
from sb3_disagree.files import write_atomic

BACKENDS = ("local", "ray")


def _copy_unfinished(source: Path, folder: Path) -> None:
    """``source``'s files in ``folder`` (afresh) without its ``result.json``: not finished until written."""
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(source, folder, ignore=shutil.ignore_patterns(RESULT))


def _start_from(source: Path, folder: Path) -> int:
    """Copy a finished run (checked by ``Run.source``) into ``folder`` to continue it, afresh, so that a
    stopped continuation starts again; :return: its env steps."""
    _copy_unfinished(source, folder)
    return int(yaml.safe_load((folder / "config.yaml").read_text())["num_timesteps"])


def copy_run(run: Run, source: Path, folder: Path) -> dict[str, Any]:
    """Take a finished run of the same configuration (checked by ``Run.copy_source``) as this one;
    :return: its result, relabelled with this run's cell."""
    _copy_unfinished(source, folder)
    result = {**json.loads((source / RESULT).read_text()), "cell": run.cell, "copied_from": str(source)}
    write_atomic(folder / RESULT, json.dumps(result, indent=2) + "\n")
    return result


def torch_threads(overlap: bool, cores: int) -> int:
    """
    Torch's threads for one run given the cores it has to itself: one, or two for an overlapped run (its on-policy
    update may use both while the other thread is idle), never more than its cores: threads that outnumber the cores
    spin against each other (two overlapped runs side by side on 2 cores trained their first 12k env steps at 68 env
    steps/s each with two threads each, at 204 with one). ``OMP_NUM_THREADS``, where set, says instead (runs started
    side by side in separate processes).
    """
    given = os.environ.get("OMP_NUM_THREADS", "")
    if given.isdigit() and int(given) > 0:
        return int(given)
    return max(1, min(2 if overlap else 1, cores))


def train_and_evaluate(run: Run, folder: Path, source: Optional[Path] = None,
                       progress_every: Optional[float] = None, cores: int = 1) -> dict[str, Any]:
    """
    Train one run into ``folder``, evaluate the new policy alone, and write ``result.json``.

    :param source: A finished run to continue to ``run.config.steps`` instead of starting afresh
    :param progress_every: Print a progress line (prefixed with the cell and seed) every this many seconds
    :param cores: The cores this run has to itself (:func:`torch_threads`)
    :return: The result record
    """
    import torch as th

    threads = torch_threads(run.config.overlap, cores)
    th.set_num_threads(threads)
    from sb3_disagree.run import train, write_card

    begun = _start_from(source, folder) if source is not None else 0
    start = time.perf_counter()
    callbacks = []
    if progress_every:
        from sb3_disagree.run.progress import ProgressLines

        callbacks.append(ProgressLines(progress_every, prefix=f"  {run.cell} seed {run.seed}: "))
    if source is not None:
        run_dir, model, finished = train(run.config, resume=folder, steps=run.config.steps, callbacks=callbacks)
    else:
        # An unfinished run of this experiment (no result.json) starts again from scratch.
        run_dir, model, finished = train(run.config, run_dir=folder, callbacks=callbacks, force=True)
    if not finished:
        raise KeyboardInterrupt
    seconds = time.perf_counter() - start
    write_curves(folder)
    # The new policy alone from env seeds the run never trained on, greedy (SB3's default) and sampled, on its card.
    evaluations = write_card(folder, model, run.final_episodes, f"dopt experiment run {run.cell} (seed {run.seed})")
    result = {"cell": run.cell, "seed": run.seed, "steps": int(model.num_timesteps), "seconds": round(seconds, 1),
              "fps": round((model.num_timesteps - begun) / max(seconds, 1e-9), 1), "torch_threads": threads,
              "final_alone": evaluations["sampled"].as_dict(), "final_alone_greedy": evaluations["greedy"].as_dict(),
              "config": asdict(run.config), **({"continued_from": str(source), "from_steps": begun} if source else {})}
    write_atomic(folder / RESULT, json.dumps(result, indent=2) + "\n")
    return result


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _ray_task(run: Run, start: Optional[dict[str, bytes]] = None) -> tuple[dict[str, Any], dict[str, bytes]]:
    """A run on a Ray worker, in a scratch folder; the run it continues travels there, its files travel back."""
    with tempfile.TemporaryDirectory() as tmp:
        source = None
        if start is not None:
            source = Path(tmp) / "source"
            _unpack(source, start)
        result = train_and_evaluate(run, Path(tmp) / "run", source)
        files = _files(Path(tmp) / "run")
    return result, files


def _unpack(folder: Path, files: dict[str, bytes]) -> None:
    for rel, data in sorted(files.items(), key=lambda kv: kv[0] == RESULT):  # result.json last
        write_atomic(folder / rel, data)


def run_experiment(
    experiment: Experiment,
    root: Path,
    backend: str = "local",
    jobs: Optional[int] = None,
    address: Optional[str] = None,
    on_result: Optional[Callable[[dict[str, Any]], None]] = None,
    progress_every: Optional[float] = None,
) -> list[dict[str, Any]]:
    """
    Run every unfinished (cell, seed) of an experiment.

    :param experiment: The grid
    :param root: The experiment's results folder
    :param backend: "local" (a process pool) or "ray"
    :param jobs: Runs at a time on the local backend (default: the machine's cores)
    :param address: The Ray cluster's address ("auto", "ray://host:10001"); None starts a local Ray
    :param on_result: Called with each run's result as it arrives
    :param progress_every: Each local run prints a progress line every this many seconds (None: silent)
    :return: The results of the runs done now
    """
    if backend not in BACKENDS:
        raise ValueError(f"--backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    # Each unfinished run with the run it continues or repeats, all checked before anything starts.
    unfinished = [r for r in experiment.runs() if not r.finished(root)]
    copies = [(r, r.copy_source(root)) for r in unfinished]
    todo = [(r, r.source(root, experiment.continues)) for r, copy in copies if copy is None]
    results: list[dict[str, Any]] = []

    def done(result: dict[str, Any]) -> None:
        results.append(result)
        if on_result:
            on_result(result)

    for r, copy in copies:
        if copy is not None:
            done(copy_run(r, copy, r.folder(root)))
    if not todo:
        return results
    if backend == "ray":
        import ray

        ray.init(address=address, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
        task = ray.remote(num_cpus=1)(_ray_task)
        pending = {task.remote(r, _files(source) if source else None): r for r, source in todo}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            run = pending.pop(ready[0])
            result, files = ray.get(ready[0])
            _unpack(run.folder(root), files)
            done(result)
    elif (jobs or os.cpu_count() or 1) == 1:
        for r, source in todo:
            done(train_and_evaluate(r, r.folder(root), source, progress_every, os.cpu_count() or 1))
    else:
        jobs = jobs or os.cpu_count() or 1
        cores = max(1, (os.cpu_count() or 1) // jobs)
        with ProcessPoolExecutor(jobs) as pool:
            futures = [pool.submit(train_and_evaluate, r, r.folder(root), source, progress_every, cores)
                       for r, source in todo]
            for future in as_completed(futures):
                done(future.result())
    return results
