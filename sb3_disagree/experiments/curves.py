"""Training curves read back from run folders (SB3 Monitor files and progress.csv), and an experiment's
training-success curves kept in one file once its runs' per-episode files are left out of the repository."""

import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Optional

import numpy as np
import pandas as pd


def success_curve(run_dir: Path, grid: np.ndarray, window: int = 50, min_episodes: int = 10) -> np.ndarray:
    """
    Training success rate against env steps: the success of the last ``window`` episodes (over all
    envs) that had ended by each step of ``grid``; nan until ``min_episodes`` episodes have ended.

    :param run_dir: A run folder with ``monitor/*.monitor.csv`` (written with ``is_success``)
    :param grid: Env steps (over all envs) at which to read the curve
    :param window: Episodes in the moving window
    """
    frames = []
    files = sorted((run_dir / "monitor").glob("*.monitor.csv"))
    for f in files:
        df = pd.read_csv(f, skiprows=1)
        # An env's own step count at each episode end, times the number of envs: the total steps then.
        df["steps"] = df["l"].cumsum() * len(files)
        frames.append(df[["steps", "is_success"]])
    if not frames:
        return np.full(len(grid), np.nan)
    episodes = pd.concat(frames).sort_values("steps")
    steps = episodes["steps"].to_numpy()
    success = episodes["is_success"].astype(float).to_numpy()
    out = np.full(len(grid), np.nan)
    for i, g in enumerate(grid):
        n = np.searchsorted(steps, g, side="right")
        if n >= min_episodes:
            out[i] = success[max(0, n - window):n].mean()
    return out


def has_monitors(run_dir: Path) -> bool:
    """Whether the run folder still holds its per-episode Monitor files."""
    return any((run_dir / "monitor").glob("*.monitor.csv"))


# Every run's training success on its report's grid, one row per run (cell, seed, then one column per grid
# step): what the report reads where a run's monitor files are not there (they stay out of the repository).
TRAINING_CURVES = "training-success.csv"


def read_training_curves(root: Path, grid: np.ndarray) -> dict[tuple[str, int], np.ndarray]:
    """
    The curves kept in ``root/TRAINING_CURVES`` by (cell, seed); none where there is no such file.

    :raises ValueError: Where the file was written on another grid (the experiment's steps changed)
    """
    path = root / TRAINING_CURVES
    if not path.exists():
        return {}
    df = pd.read_csv(path)
    steps = np.array([float(c) for c in df.columns[2:]])
    if len(steps) != len(grid) or not np.allclose(steps, grid):
        raise ValueError(f"{path} holds curves on another grid of steps ({len(steps)} points to {steps[-1]:,.0f}) "
                         f"than the experiment's ({len(grid)} to {grid[-1]:,.0f}); remove it and report from "
                         "runs that still have their monitor files")
    values = df.iloc[:, 2:].to_numpy(dtype=float)
    return {(str(cell), int(seed)): values[i] for i, (cell, seed) in enumerate(zip(df["cell"], df["seed"]))}


def write_training_curves(root: Path, grid: np.ndarray, curves: dict[tuple[str, int], np.ndarray]) -> Path:
    """Write ``curves`` into ``root/TRAINING_CURVES``, keeping the rows of other runs already there (a report
    restricted to some seeds leaves the others' rows as they were). Values keep full precision."""
    kept = {**read_training_curves(root, grid), **curves}
    rows = [[cell, seed, *kept[(cell, seed)]] for cell, seed in sorted(kept)]
    df = pd.DataFrame(rows, columns=["cell", "seed", *[f"{g:.10g}" for g in grid]])
    df.to_csv(root / TRAINING_CURVES, index=False)
    return root / TRAINING_CURVES


def check_monitor_coverage(run_dir: Path, steps: int, n_envs: int, max_episode_steps: int, legs: int = 1) -> None:
    """
    Refuse a run whose monitor files hold fewer of its steps than it ran: each env's unfinished last
    episode of each leg (a continued run has two) may be missing, no more. A training curve read from
    such files would hold its last value (or, in a continued run, shift the later episodes back in
    time) without saying so.

    :raises ValueError: Naming the run and how much its files hold
    """
    files = sorted((run_dir / "monitor").glob("*.monitor.csv"))
    held = sum(int(pd.read_csv(f, skiprows=1)["l"].sum()) for f in files)
    if held < steps - legs * n_envs * max_episode_steps:
        raise ValueError(f"{run_dir}: its monitor files hold episodes of {held:,} env steps, but the run took "
                         f"{steps:,}; its training curve cannot be read. Run it again: remove the folder and run "
                         "its experiment (finished runs are skipped)")


# The logged values an experiment's pages read back, kept per run in ``curves.csv`` (a few columns of
# ``progress.csv``, whose other columns stay in the run folder and out of the repository).
CURVE_KEYS = ("time/total_timesteps", "rollout/success_rate", "rollout/ep_len_mean", "rollout/ep_rew_mean",
              "prior/usage", "prior/entropy", "prior/disagreement", "train/entropy_loss", "train/ent_coef",
              "eval/success_rate", "eval/success_rate_greedy", "eval/mean_ep_length", "jsrl/horizon")
CURVES = "curves.csv"


def write_curves(run_dir: Path) -> Path:
    """Write a run's ``curves.csv``: the ``CURVE_KEYS`` columns of its ``progress.csv``, the rows that hold one."""
    df = pd.read_csv(run_dir / "progress.csv")
    keys = [k for k in CURVE_KEYS if k in df]
    df[keys].dropna(how="all", subset=keys[1:]).to_csv(run_dir / CURVES, index=False)
    return run_dir / CURVES


def progress_curve(run_dir: Path, key: str, grid: np.ndarray, smooth: int = 1) -> np.ndarray:
    """
    A logged value (e.g. ``prior/usage``) against env steps, from ``curves.csv`` (or ``progress.csv`` where the
    run has none), held between dumps.

    :param smooth: Moving average over this many dumps (each dump holds one rollout's value)
    """
    try:
        df = pd.read_csv(run_dir / CURVES if (run_dir / CURVES).exists() else run_dir / "progress.csv")
    except (FileNotFoundError, pd.errors.EmptyDataError):  # a run shorter than one log interval
        return np.full(len(grid), np.nan)
    if key not in df or "time/total_timesteps" not in df:
        return np.full(len(grid), np.nan)
    df = df[["time/total_timesteps", key]].dropna()
    steps = df["time/total_timesteps"].to_numpy()
    values = df[key].rolling(smooth, min_periods=1).mean().to_numpy()
    idx = np.searchsorted(steps, grid, side="right") - 1
    return np.where(idx >= 0, values[np.clip(idx, 0, None)], np.nan)


def mean_and_band(curves: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean over seeds and a 95% band (t-interval of the mean; no band where only one seed has a value)."""
    from scipy import stats

    c = np.array(curves, dtype=float)
    n = np.sum(~np.isnan(c), axis=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # steps where fewer than two seeds have a value
        mean = np.nanmean(c, axis=0)
        sem = np.nanstd(c, axis=0, ddof=1) / np.sqrt(np.maximum(n, 1)) if len(c) > 1 else np.zeros_like(mean)
    half = np.where(n > 1, stats.t.ppf(0.975, np.maximum(n - 1, 1)) * np.nan_to_num(sem), 0.0)
    return mean, mean - half, mean + half


def first_defined(curve: np.ndarray) -> float:
    defined = curve[~np.isnan(curve)]
    return float(defined[0]) if len(defined) else float("nan")


def last_defined(curve: np.ndarray) -> float:
    """The curve's last value (a run shorter than the grid ends in nan), or nan if it has none."""
    defined = curve[~np.isnan(curve)]
    return float(defined[-1]) if len(defined) else float("nan")


def steps_to(curve: np.ndarray, grid: np.ndarray, level: float) -> Optional[float]:
    """The first grid step where the curve reaches ``level``, or None."""
    hit = np.flatnonzero(np.nan_to_num(curve, nan=-1) >= level)
    return float(grid[hit[0]]) if len(hit) else None
