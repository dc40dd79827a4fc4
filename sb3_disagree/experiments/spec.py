"""
An experiment: a named grid of runs described by a small YAML file.

.. code-block:: yaml

    name: fig3-bathtub
    goal: bathtub
    priors: [shower, toilet]
    steps: 100000
    seeds: [0, 1, 2, 3, 4]
    budgets: [25000, 50000, 100000]   # success read at these steps in the report
    final_episodes: 50                # the new policy alone, evaluated at the end of each run
    run: {n_envs: 4}                  # RunConfig fields shared by every cell
    acer: {reward_scale: 0.1}         # ACER hyperparameters on top of the defaults
    cells:
      disagreement: {mode: disagreement}
      scratch: {mode: scratch}

Each cell's mapping overrides RunConfig fields (``mode``, ``alpha``, ``beta``, ...) and may hold its own
``acer`` mapping. Every (cell, seed) is one run, written under ``<results>/<cell>/seed-<seed>/``.

``continues: OTHER`` makes each run a continuation of OTHER's finished run of the same cell and seed (read
from the results folder beside this one) to this experiment's larger ``steps``: longer budgets without
repeating the first steps. The replay buffer is not kept at the end of a finished run, so a continuation
starts with an empty one. A continuation trains with the saved settings of the run it continues, so a grid
whose runs differ from them in anything but ``steps`` (and what only changes the output) is refused.

A cell may say ``same_as: OTHER/CELL`` where its runs are, seed for seed, runs another experiment already
makes with the same configuration (the ablations' defaults are Figure 3's runs): a finished run there is
copied (runs are deterministic given their configuration and seed) instead of trained again; one with
another configuration is an error, and one not finished yet is trained here.
"""

import json
from dataclasses import MISSING, asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional

import yaml

from sb3_disagree.files import safe_name
from sb3_disagree.run import RunConfig
from sb3_disagree.run.presets import acer_signature_defaults, trained_with

# Experiments shipped with the repository; a path to any YAML file works too.
SHIPPED = Path(__file__).resolve().parents[1] / "data" / "experiments"
RESULT = "result.json"
# RunConfig fields that change what a run writes, not what it learns: a copy (same_as) may differ in them.
OUTPUT_ONLY = ("record_trajectories", "checkpoint_every")


def _differing(saved: dict[str, Any], config: RunConfig, ignore: tuple[str, ...] = ()) -> list[str]:
    """The RunConfig fields in which a saved run's settings differ from ``config`` (a field newer than the
    record ran at its default), leaving out ``ignore`` and what only changes the output."""
    defaults = {k: f.default for k, f in RunConfig.__dataclass_fields__.items() if f.default is not MISSING}
    saved = trained_with(saved, defaults)  # what the record ran with where it does not name a setting
    wanted = asdict(config)
    wanted["acer_kwargs"] = {**acer_signature_defaults(), **wanted["acer_kwargs"]}
    if config.mode == "ppo":  # SB3's PPO runs none of ACER's settings, whatever a record of it lists
        ignore = (*ignore, "acer_kwargs")
    return [k for k in wanted if k not in (*ignore, *OUTPUT_ONLY) and saved.get(k) != wanted[k]]


@dataclass
class Run:
    """One cell and seed of an experiment, with the configuration it trains."""

    cell: str
    seed: int
    config: RunConfig
    final_episodes: int
    same_as: Optional[str] = None

    def folder(self, root: Path) -> Path:
        return root / self.cell / f"seed-{self.seed}"

    def finished(self, root: Path) -> bool:
        return (self.folder(root) / RESULT).exists()

    def source(self, root: Path, continues: Optional[str]) -> Optional[Path]:
        """The finished run this one continues (beside ``root``), or None; an error if it is not there or was
        trained with other settings than this run's."""
        if continues is None:
            return None
        source = self.folder(root.parent / continues)
        if not (source / RESULT).exists() or not (source / "model.zip").exists():
            raise FileNotFoundError(f"{self.cell} seed {self.seed} continues {source}, which is not a finished run "
                                    f"with its model; run first: dopt experiment run {continues}")
        # The continuation trains with the saved settings, so a grid that asks for others would be ignored.
        differ = _differing(yaml.safe_load((source / "config.yaml").read_text()), self.config, ignore=("steps",))
        if differ:
            raise ValueError(f"{source} was trained with other {', '.join(differ)} than {self.cell} seed {self.seed}")
        return source

    def copy_source(self, root: Path) -> Optional[Path]:
        """The finished run of ``same_as`` (beside ``root``) that this run would repeat, or None where there
        is none yet; an error if that run was trained with another configuration or evaluation."""
        if self.same_as is None:
            return None
        experiment, cell = self.same_as.split("/")
        source = root.parent / experiment / cell / f"seed-{self.seed}"
        if not (source / RESULT).exists():
            return None
        result = json.loads((source / RESULT).read_text())
        differ = _differing(result.get("config", {}), self.config)
        if result.get("final_alone", {}).get("episodes") != self.final_episodes:
            differ.append("final_episodes")
        if differ:
            raise ValueError(f"{self.cell} seed {self.seed} is same_as {self.same_as}, but {source} differs in "
                             f"{', '.join(differ)}")
        return source


@dataclass
class Experiment:
    """
    A named grid of runs.

    :param name: The experiment's name (its results folder)
    :param goal: The new goal, or a list of goals: each cell then runs on each goal, as the cell ``CELL@GOAL``, with
        the priors the embedding chooses for that goal (``priors: auto``)
    :param cells: Cell name -> overrides of RunConfig fields (and an ``acer`` mapping)
    :param seeds: Seeds of every cell
    :param steps: Env steps of every run
    :param priors: "auto" or the priors' goal labels
    :param env_id: Gymnasium id of the environment
    :param budgets: Steps at which the report reads the success rate
    :param final_episodes: Episodes of the final evaluation of the new policy alone
    :param run: RunConfig fields shared by every cell
    :param acer: ACER hyperparameters shared by every cell, on top of the defaults
    :param trajectories: Whether the report draws a recorded episode per cell (paper Figure 5)
    :param continues: The experiment whose finished runs these runs continue (same cells and seeds)
    """

    name: str
    goal: str
    cells: dict[str, dict[str, Any]]
    seeds: list[int] = field(default_factory=lambda: [0])
    steps: int = 100_000
    priors: Any = "auto"
    env_id: str = "sb3_disagree/Apartment-v0"
    budgets: list[int] = field(default_factory=list)
    final_episodes: int = 50
    run: dict[str, Any] = field(default_factory=dict)
    acer: dict[str, Any] = field(default_factory=dict)
    trajectories: bool = False
    continues: Optional[str] = None
    goals: list[str] = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.goal, list):
            return
        # A goals table: every cell on every goal, each goal with the priors the embedding chooses for it.
        if not self.goal or not all(isinstance(g, str) for g in self.goal) or len(set(self.goal)) < len(self.goal):
            raise ValueError(f"experiment {self.name!r}: goal must be a word or a list of distinct words, "
                             f"got {self.goal!r}")
        if self.priors != "auto" or self.trajectories or self.continues:
            raise ValueError(f"experiment {self.name!r}: a list of goals takes priors: auto (each goal's own), and "
                             "neither trajectories nor continues")
        if not isinstance(self.cells, dict) or not all(isinstance(v, (dict, type(None))) for v in self.cells.values()):
            return  # runs() says what is wrong with them
        self.goals = list(self.goal)
        self.cells = {f"{cell}@{goal}": {**(overrides or {}), "goal": goal}
                      for goal in self.goals for cell, overrides in self.cells.items()}
        self.goal = ", ".join(self.goals)

    def restrict(self, seeds: Optional[list[int]] = None, cells: Optional[list[str]] = None) -> None:
        """Keep only some of the seeds and cells (each must be part of the experiment)."""
        if seeds is not None:
            unknown = sorted(set(seeds) - set(self.seeds))
            if unknown:
                raise ValueError(f"seeds {unknown} are not among {self.name}'s seeds {self.seeds}")
            self.seeds = [s for s in self.seeds if s in seeds]
        if cells is not None:
            # In a goals table, a cell's name alone stands for it on every goal.
            bases = {c.split("@")[0] for c in self.cells} if self.goals else set()
            unknown = sorted(set(cells) - set(self.cells) - bases)
            if unknown:
                raise ValueError(f"cells {unknown} are not among {self.name}'s cells {list(self.cells)}")
            self.cells = {c: v for c, v in self.cells.items() if c in cells or (self.goals and c.split("@")[0] in cells)}

    def check(self) -> None:
        """The grid's own fields: of their types, counts and budgets positive."""
        def positive_ints(values: Any) -> bool:
            return isinstance(values, list) and all(isinstance(v, int) and not isinstance(v, bool) and v >= 0
                                                    for v in values)

        if not isinstance(self.name, str):
            raise ValueError(f"an experiment's name must be a word (it names its results folder), got {self.name!r}")
        safe_name(self.name, "an experiment's name")
        if not isinstance(self.goal, str):
            raise ValueError(f"experiment {self.name!r}: goal must be a word, got {self.goal!r}")
        for name in ("steps", "final_episodes"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"experiment {self.name!r}: {name} must be a positive integer, got {value!r}")
        if not positive_ints(self.seeds) or not self.seeds:
            raise ValueError(f"experiment {self.name!r}: seeds must be a list of integers >= 0, got {self.seeds!r}")
        if not positive_ints(self.budgets) or any(b < 1 for b in self.budgets):
            raise ValueError(f"experiment {self.name!r}: budgets must be a list of positive step counts, "
                             f"got {self.budgets!r}")
        for name in ("run", "acer", "cells"):
            if not isinstance(getattr(self, name), dict):
                raise ValueError(f"experiment {self.name!r}: {name} must be a mapping, got {getattr(self, name)!r}")
        if not isinstance(self.trajectories, bool):
            raise ValueError(f"experiment {self.name!r}: trajectories must be true or false")

    def runs(self) -> list[Run]:
        self.check()
        out = []
        # Seed-major order: an experiment stopped early has every cell for its first seeds.
        for seed in self.seeds:
            for cell, overrides in self.cells.items():
                safe_name(str(cell), f"experiment {self.name!r}: cell")
                if not isinstance(overrides, (dict, type(None))):
                    raise ValueError(f"experiment {self.name!r}, cell {cell!r}: a cell is a mapping of run fields, "
                                     f"got {overrides!r}")
                overrides = dict(overrides or {})
                same_as = overrides.pop("same_as", None)
                if same_as is not None and (not isinstance(same_as, str) or same_as.count("/") != 1):
                    raise ValueError(f"experiment {self.name!r}, cell {cell!r}: same_as must read OTHER/CELL, "
                                     f"got {same_as!r}")
                cell_acer = overrides.pop("acer", {})
                fields = {**self.run, **overrides}
                # The grid's and the cell's ACER settings; RunConfig adds the mode's, as dopt train's does.
                acer = {**self.acer, **cell_acer}
                unknown = set(fields) - set(RunConfig.__dataclass_fields__)
                if unknown:
                    raise ValueError(f"experiment {self.name!r}, cell {cell!r}: unknown run fields {sorted(unknown)}")
                # The grid's own fields are set once, at the top of the file, for every cell and seed.
                goal = fields.pop("goal") if self.goals else self.goal
                grid = dict(goal=goal, env_id=self.env_id, priors=self.priors, steps=self.steps, seed=seed,
                            acer_kwargs=acer)
                grid_wide = sorted(set(fields) & set(grid))
                if grid_wide:
                    raise ValueError(f"experiment {self.name!r}, cell {cell!r}: {', '.join(grid_wide)} is set at the "
                                     f"top of the experiment file, not in run or a cell")
                if self.trajectories:  # the report draws each cell's recorded episodes
                    fields.setdefault("record_trajectories", True)
                config = RunConfig(**grid, **fields)
                config.validate()
                out.append(Run(cell, seed, config, self.final_episodes, same_as))
        return out


def find_experiment(name_or_path: str, search: Optional[Path] = None) -> Path:
    """The YAML file of an experiment: a path, or a name in ``search`` (default: the shipped experiments)."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        if not path.exists():
            raise FileNotFoundError(f"no experiment file {path}")
        return path
    folder = search or SHIPPED
    candidate = folder / f"{name_or_path}.yaml"
    if not candidate.exists():
        known = sorted(p.stem for p in folder.glob("*.yaml")) if folder.exists() else []
        raise FileNotFoundError(f"no experiment named {name_or_path!r} in {folder}; known: {', '.join(known) or 'none'}")
    return candidate


def load_experiment(name_or_path: str, search: Optional[Path] = None) -> Experiment:
    """Read and check an experiment's YAML file."""
    path = find_experiment(name_or_path, search)
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not readable YAML ({' '.join(str(exc).split())[:200]})") from None
    if data is None:
        data = {}
    if not isinstance(data, dict) or not all(isinstance(k, str) for k in data):
        raise ValueError(f"{path}: an experiment is a mapping of named fields (name, goal, cells, ...), got "
                         f"{type(data).__name__}")
    data.setdefault("name", path.stem)
    unknown = set(data) - set(Experiment.__dataclass_fields__)
    if unknown:
        raise ValueError(f"{path}: unknown keys {sorted(unknown)}")
    if not data.get("goal"):
        raise ValueError(f"{path}: an experiment needs its goal ('goal: WORD')")
    if not data.get("cells"):
        raise ValueError(f"{path}: an experiment needs at least one cell under 'cells'")
    experiment = Experiment(**data)
    experiment.runs()  # checks every cell now rather than in a worker
    return experiment
