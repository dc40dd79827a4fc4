"""Recording a run's episodes (positions and per-step tags) for the trajectory pictures."""

import json
from pathlib import Path
from typing import Any, Optional

import numpy as np
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




def read_episodes(run_dir: Path) -> list[dict[str, Any]]:
    """The recorded episodes of a run (``trajectories.jsonl``), oldest first; [] if none were recorded."""
    path = Path(run_dir) / "trajectories.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def draw_episode(record: dict[str, Any], env_id: str, goal: str, out: Optional[Path] = None) -> np.ndarray:
    """
    A recorded episode on the map of its env, each step coloured by whether it followed a prior.

    :param record: One line of ``trajectories.jsonl``
    :param env_id: The run's env (one with a ``layout``: the apartment)
    :param goal: The run's goal (marked on the map)
    :param out: Also write the picture here (PNG)
    :return: The picture (H, W, 3)
    """
    from sb3_disagree.envs.topdown import draw_trajectory
    from sb3_disagree.envs.vec import make_task

    layout = getattr(make_task(env_id, goal).unwrapped, "layout", None)
    if layout is None:
        raise ValueError(f"{env_id} has no map to draw episodes on")
    # positions[i] is where step i ended; the segment from i to i + 1 is step i + 1's action.
    return draw_trajectory(layout, record["positions"], record["tags"][1:], goal=goal, out=out)
