"""Recording a run's episodes (positions and per-step tags) for the trajectory pictures."""

import json
from pathlib import Path

from stable_baselines3.common.callbacks import BaseCallback

class RecordTrajectories(BaseCallback):
    """Write each episode of env 0 as a JSON line: positions after each step, their tags, success."""

    def __init__(self, path: Path, every: int = 1) -> None:
        super().__init__()
        self.path, self.every = path, every
        self.positions: list = []
        self.tags: list = []
        self.episodes = 0

    def _on_step(self) -> bool:
        infos, dones = self.locals["infos"], self.locals["dones"]
        tags = self.locals.get("tags")
        info = infos[0]
        if "position" in info:
            self.positions.append(list(info["position"]))
            self.tags.append(str(tags[0]) if tags is not None else "explore")
        if dones[0]:
            self.episodes += 1
            if self.episodes % self.every == 0:
                self._write(complete=True, success=bool(info.get("is_success", False)))
            self.positions, self.tags = [], []
        return True

    def _on_training_end(self) -> None:
        self._write(complete=False, success=False)  # the episode under way, so a short run still shows its path

    def _write(self, complete: bool, success: bool) -> None:
        if not self.positions:
            return
        record = {"timesteps": self.num_timesteps, "complete": complete, "success": success,
                  "positions": self.positions, "tags": self.tags}
        with open(self.path, "a") as f:
            f.write(json.dumps(record) + "\n")


