"""Loggers a model trained outside a run uses (a prior, a benchmark)."""

from stable_baselines3.common.logger import Logger


def silent_logger() -> Logger:
    """A logger that writes nothing: SB3's own default for ``verbose=0`` still makes an empty folder in the temp dir."""
    return Logger(None, [])
