"""Callbacks a run can use anywhere: plain progress lines for logs that no live display can draw in."""

import sys
import time
from typing import Optional, TextIO

from stable_baselines3.common.callbacks import BaseCallback


def _duration(seconds: float) -> str:
    minutes, seconds = divmod(int(round(seconds)), 60)
    return f"{minutes}m{seconds:02d}s"


class ProgressLines(BaseCallback):
    """
    A line every ``interval`` seconds, and one at the end, flushed: steps, env steps/s, training success over
    the last 100 episodes, the share of steps that followed the priors, time spent and left. For output that
    is not a terminal (nohup, batch schedulers, CI), where a live display draws nothing.

    :param interval: Seconds between lines
    :param prefix: Put before every line (e.g. the run's name)
    :param stream: Where the lines go (standard output by default)
    """

    def __init__(self, interval: float = 30.0, prefix: str = "", stream: Optional[TextIO] = None) -> None:
        super().__init__()
        self.interval, self.prefix, self.stream = interval, prefix, stream
        self.total = self.n0 = 0
        self.t0 = self.last = 0.0

    def _on_training_start(self) -> None:
        self.total = int(self.locals["total_timesteps"])  # absolute by now, also for a resumed run
        self.n0, self.t0 = self.model.num_timesteps, time.perf_counter()
        self.last = self.t0

    def _on_step(self) -> bool:
        now = time.perf_counter()
        if now - self.last >= self.interval:
            self.last = now
            self.write(now)
        return True

    def _on_training_end(self) -> None:
        self.write(time.perf_counter())

    def line(self, now: float) -> str:
        """The progress line at time ``now`` (``time.perf_counter()``)."""
        done = self.model.num_timesteps
        rate = (done - self.n0) / max(now - self.t0, 1e-9)
        success = self.model.ep_success_buffer
        parts = [f"{self.prefix}steps {done:,}/{self.total:,}", f"{rate:.0f} env steps/s",
                 f"success {sum(success) / len(success):.2f}" if success else "success -"]
        usage = getattr(getattr(self.model, "behaviour", None), "last", {}).get("prior/usage")
        if usage is not None:
            parts.append(f"prior usage {usage:.2f}")
        left = f", {_duration((self.total - done) / rate)} left" if rate > 0 else ""
        parts.append(f"{_duration(now - self.t0)} spent{left}")
        return " | ".join(parts)

    def write(self, now: float) -> None:
        stream = self.stream or sys.stdout
        stream.write(self.line(now) + "\n")
        stream.flush()
