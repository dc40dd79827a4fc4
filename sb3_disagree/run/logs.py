"""A run's logs: SB3's logger writing ``progress.csv`` (appended to by a resumed run) and TensorBoard events."""

import os
from pathlib import Path

from stable_baselines3.common.logger import CSVOutputFormat, Logger, make_output_format


class AppendingCSVOutputFormat(CSVOutputFormat):
    """``progress.csv`` of a resumed run: the earlier rows stay, new rows follow (SB3's format truncates)."""

    def __init__(self, filename: str):
        self.file = open(filename, "r+")
        header = self.file.readline().rstrip("\n")
        self.keys = header.split(",") if header else []
        self.file.seek(0, os.SEEK_END)
        self.separator = ","
        self.quotechar = '"'


def run_logger(run_dir: Path, append: bool) -> Logger:
    """CSV and TensorBoard logs in the run folder; a resumed run appends to its ``progress.csv``."""
    progress = run_dir / "progress.csv"
    csv = AppendingCSVOutputFormat(str(progress)) if append and progress.exists() else CSVOutputFormat(str(progress))
    return Logger(str(run_dir), [csv, make_output_format("tensorboard", str(run_dir))])

