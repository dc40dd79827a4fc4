"""
What a run survives: checkpoints written atomically, SIGTERM taken as Ctrl-C, and on resume the logs cut
back to the checkpoint the run continues from, so that every curve reads as one run.

A checkpoint is a folder ``checkpoints/<steps>/`` holding ``model.zip``, the replay buffer when the run
keeps one, and ``state.json`` (written last, so a folder without it is incomplete): the step count, the
SHA-256 of each file, and the size of every log file at that moment. The two newest checkpoints are kept;
one whose files do not match their hashes (a crash during the write, a truncated disk) is skipped for the
one before it.
"""

import contextlib
import hashlib
import json
import os
import shutil
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, Optional

from stable_baselines3.common.callbacks import BaseCallback

from sb3_disagree.files import write_atomic

CHECKPOINTS = "checkpoints"
STATE = "state.json"
KEEP = 2
BUFFER = "replay_buffer.npz"  # arrays only: loading a checkpoint runs nothing
# The logs a run appends to; a resumed run cuts them back to their size at its checkpoint.
LOG_PATTERNS = ("progress.csv", "trajectories.jsonl", "monitor/*.monitor.csv")


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def log_sizes(run_dir: Path) -> dict[str, int]:
    """The size of every log file of a run, by path relative to the run folder."""
    sizes = {}
    for pattern in LOG_PATTERNS:
        for path in sorted(run_dir.glob(pattern)):
            sizes[str(path.relative_to(run_dir))] = path.stat().st_size
    return sizes


def save_checkpoint(model: Any, run_dir: Path, with_buffer: bool = True, extra: Optional[dict[str, Any]] = None) -> Path:
    """
    Write a checkpoint of ``model`` (and its replay buffer) under ``run_dir/checkpoints``, then copy its model
    to ``run_dir/model.zip`` by a rename; keep the two newest checkpoints (only this one without a buffer).

    :param extra: What else the run must resume with, kept in the checkpoint's ``state.json``

    :return: The checkpoint's folder
    """
    root = run_dir / CHECKPOINTS
    folder = root / f"{int(model.num_timesteps):012d}"
    tmp = root / f".{folder.name}.tmp"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    files = {"model.zip": tmp / "model.zip"}
    model.save(files["model.zip"])
    if with_buffer and hasattr(model, "save_replay_buffer"):
        files[BUFFER] = tmp / BUFFER
        model.save_replay_buffer(files[BUFFER])
    for path in files.values():
        _fsync(path)
    state = {"num_timesteps": int(model.num_timesteps), "files": {n: _sha256(p) for n, p in files.items()},
             "logs": log_sizes(run_dir), **(extra or {})}
    write_atomic(tmp / STATE, json.dumps(state, indent=2) + "\n")
    if folder.exists():
        shutil.rmtree(folder)
    os.replace(tmp, folder)
    # The model users load sits at the run's root: a copy, swapped in by a rename.
    shutil.copyfile(folder / "model.zip", run_dir / ".model.zip.tmp")
    _swap_in(run_dir / ".model.zip.tmp", run_dir / "model.zip")
    # The two newest, or only the last where the run has finished (no replay buffer kept: nothing to fall back to).
    keep = KEEP if with_buffer else 1
    for old in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))[:-keep]:
        shutil.rmtree(old)
    return folder


def replace_model(model: Any, run_dir: Path) -> None:
    """Write ``model`` as ``run_dir/model.zip`` by a rename (a crash leaves the old file or the new, whole)."""
    model.save(run_dir / ".model.zip.tmp")
    _swap_in(run_dir / ".model.zip.tmp", run_dir / "model.zip")


def _swap_in(tmp: Path, path: Path) -> None:
    _fsync(tmp)
    os.replace(tmp, path)


def latest_checkpoint(run_dir: Path) -> Optional[tuple[Path, dict[str, Any]]]:
    """The newest complete checkpoint whose files match their hashes, with its state; None where there is none."""
    root = run_dir / CHECKPOINTS
    if not root.exists():
        return None
    return latest_checkpoint_in(sorted((p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")),
                                       reverse=True))


def resume_point(run_dir: Path) -> tuple[Path, dict[str, Any]]:
    """
    The checkpoint a run resumes from: the newest whose files match their hashes. Newer ones that do not are moved
    aside (``checkpoints/.damaged-<steps>``), never deleted; where none is intact, a ValueError in one line.
    """
    root = run_dir / CHECKPOINTS
    moved = []
    for folder in sorted((p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")), reverse=True) \
            if root.is_dir() else []:
        found = latest_checkpoint_in([folder])
        if found is not None:
            return found
        aside = root / f".damaged-{folder.name}"
        n = 1
        while aside.exists():
            n += 1
            aside = root / f".damaged-{folder.name}-{n}"
        os.replace(folder, aside)
        moved.append(aside.name)
    where = f" (damaged: moved aside as {', '.join(moved)})" if moved else ""
    raise ValueError(f"{run_dir} has no intact checkpoint to resume from{where}; start it again with --force "
                     "instead of --resume")


def latest_checkpoint_in(folders: list[Path]) -> Optional[tuple[Path, dict[str, Any]]]:
    """The first of ``folders`` that is a complete checkpoint whose files match their hashes, with its state."""
    for folder in folders:
        try:
            state = json.loads((folder / STATE).read_text())
            if all(_sha256(folder / name) == digest for name, digest in state["files"].items()):
                return folder, state
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            pass  # incomplete or damaged: the one before
    return None


def truncate_logs(run_dir: Path, sizes: dict[str, int]) -> None:
    """
    Cut every log back to its size at a checkpoint (a log born after it is removed), so that a run resumed
    after a kill continues its history from there.
    """
    for rel in log_sizes(run_dir):
        path = run_dir / rel
        if rel not in sizes:
            path.unlink()
        elif path.stat().st_size > sizes[rel]:
            with open(path, "r+b") as f:
                f.truncate(sizes[rel])


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the context, SIGTERM (what ``timeout``, containers, SLURM and Ray send) raises KeyboardInterrupt in
    the main thread, as Ctrl-C does, so a run saves before it goes. Elsewhere than the main thread: no change."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class Checkpoint(BaseCallback):
    """
    A checkpoint (:func:`save_checkpoint`) every ``every`` env steps.

    :param run_dir: The run's folder
    :param every: Env steps between checkpoints
    :param extra: Called at each checkpoint for what else the run must resume with (:func:`save_checkpoint`)
    """

    def __init__(self, run_dir: Path, every: int, extra: Optional[Callable[[], dict[str, Any]]] = None) -> None:
        super().__init__()
        self.run_dir, self.every, self.extra = run_dir, every, extra
        self.next = 0

    def _on_training_start(self) -> None:
        self.next = (self.model.num_timesteps // self.every + 1) * self.every

    def _on_rollout_start(self) -> None:
        # Before a rollout: the last segment is learned from (and in the replay buffer), the logs written.
        if self.model.num_timesteps >= self.next:
            save_checkpoint(self.model, self.run_dir, extra=self.extra() if self.extra else None)
            self.next = (self.model.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        return True
