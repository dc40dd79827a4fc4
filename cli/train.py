"""``dopt train`` and ``dopt eval``: the method on the command line, with a live display."""

import math
import time
import typing
from pathlib import Path
from typing import Optional

import typer
from rich.live import Live
from rich.table import Table
from stable_baselines3.common.callbacks import BaseCallback

from sb3_disagree.cli.common import clean_errors, command_line, console
from sb3_disagree.cli.options import command, options_of, split


class LiveDisplay(BaseCallback):
    """Steps, env steps/s, recent success rate, prior usage and disagreement, refreshed every second."""

    def __init__(self, live: Live) -> None:
        super().__init__()
        self.total, self.live, self.last_draw, self.t0, self.n0 = 0, live, 0.0, time.perf_counter(), 0

    def _on_training_start(self) -> None:
        # learn() has made its budget absolute by now, also when a run resumes (as SB3's progress bar reads it).
        self.total = int(self.locals["total_timesteps"])
        self.t0, self.n0 = time.perf_counter(), self.model.num_timesteps

    def _on_step(self) -> bool:
        now = time.perf_counter()
        if now - self.last_draw >= 1.0:
            self.last_draw = now
            self.live.update(self.table(now))
        return True

    def table(self, now: float) -> Table:
        m = self.model
        behaviour = getattr(m, "behaviour", None)
        stats = getattr(behaviour, "last", {}) if behaviour is not None else {}
        success = m.ep_success_buffer
        t = Table(show_header=False, box=None)
        # the budget as it stands (a run whose greedy phase waits for it to be ready ends when the phase does)
        t.add_row("steps", f"{m.num_timesteps:,} / {getattr(m, '_total_timesteps', self.total):,}")
        t.add_row("env steps/s", f"{(m.num_timesteps - self.n0) / max(now - self.t0, 1e-9):.0f}")
        t.add_row("success (last 100 episodes)", f"{sum(success) / len(success):.2f}" if success else "-")
        t.add_row("prior usage", f"{stats['prior/usage']:.2f}" if "prior/usage" in stats else "-")
        t.add_row("disagreement", f"{stats['prior/disagreement']:.3f}" if "prior/disagreement" in stats else "-")
        return t


# dopt train's options: every RunConfig field (and the ACER and env settings it nests), None where not given, so
# that RunConfig resolves them as train(RunConfig(...)) does; grouped in panels, the essentials first.
PANELS = {
    "Run": ("goal", "env_id", "mode", "priors", "steps", "seed", "n_envs", "out", "resume", "force", "trust"),
    "Method": ("alpha", "beta", "entropy_offset", "jsrl_horizon", "init", "zoo", "embedding"),
    "Memory": ("frame_stack", "loop_flags"),
    "Finish": ("finish", "consistency_harvest", "greedy_phase", "greedy_epsilon", "ready", "extend",
               "consistency_epochs", "consistency_validation"),
    "ACER": ("reward_scale", "ema_decay", "average_ahead", "features_dtype", "overlap", "vec_env"),
    "Environment": ("collision_penalty", "reward_distance"),
    "Evaluation and logging": ("eval_every", "eval_episodes", "card_episodes", "checkpoint_every",
                               "record_trajectories", "progress_every"),
}
HELPS = {
    "goal": "The new goal word (with --resume: the run's own).",
    "env_id": "Gymnasium id of a navigation env (default sb3_disagree/Apartment-v0).",
    "mode": "kickstart (default), disagreement, disagreement-distill, room-sensor, jsrl, finetune, scratch or ppo.",
    "finish": "--bare: the mode without the finish, as the paper ran it (default: finished).",
    "priors": "auto (the two nearest the goal in the embedding), or their goals: a,b.",
    "steps": "Env steps to train (default 100000; with --resume, the new total).",
    "seed": "Seed of the policy and the envs (default 0).",
    "n_envs": "Parallel envs (default 4).",
    "alpha": "Disagreement window (default 10).",
    "beta": "Follow the priors while the window's disagreement is below this (default 0.1).",
    "entropy_offset": "Enter the prior branch when U(0,1) < H(pi) - this (default 0.1).",
    "jsrl_horizon": "jsrl: the guide's first horizon in steps (default 0: the priors' episode length).",
    "init": "scratch (default), or prior: start from the nearest prior's weights.",
    "zoo": "Zoo folder, 'greedy' or 'user' (default: the shipped zoo).",
    "embedding": "Word vectors file: word2vec, GloVe or fastText (default: MiniLM).",
    "frame_stack": "Frames the new policy sees (default: the mode's; 3 with loop flags).",
    "loop_flags": "The newest frame plus flags: does it equal each older one (default: the mode's).",
    "consistency_harvest": "Fit model.zip to the loop-free successful paths of the last this many steps.",
    "greedy_phase": "The last this many steps act by the argmax (default: the harvest's).",
    "greedy_epsilon": "The policy's own samples in the greedy phase (default 0.2).",
    "ready": "The greedy phase waits for this training success, the run training on (default: the mode's).",
    "extend": "The most the budget grows while the phase waits, times --steps (default: the mode's).",
    "consistency_epochs": "Passes over the harvest's labels (default 3).",
    "consistency_validation": "Greedy episodes that pick the fit's best epoch (default: the mode's).",
    "reward_scale": "Rewards in ACER's targets times this (default: the mode's).",
    "ema_decay": "model.zip acts with a moving average of the weights (default: the mode's).",
    "average_ahead": "Compute the replays' trust-region reference ahead (default: the mode's).",
    "features_dtype": "bfloat16: the CNN's passes in the updates in bfloat16 (default float32).",
    "overlap": "Replay updates in a second thread while collecting (default on).",
    "vec_env": "dummy (default) or subproc (a process per env).",
    "collision_penalty": "Subtracted from the reward on a blocked move (default 0).",
    "reward_distance": "euclidean (default) or geodesic: what the reward's distance follows.",
    "eval_every": "Evaluate the policy alone every this many steps (0: never).",
    "eval_episodes": "Episodes of each of those evaluations (default 20).",
    "card_episodes": "Episodes each way of the card's evaluation (default 20).",
    "checkpoint_every": "A checkpoint every this many steps (default 25000).",
    "record_trajectories": "Record env 0's training episodes (trajectories.jsonl).",
    "progress_every": "Seconds between progress lines off a terminal (default 30).",
    "out": "Root of the run folders.",
    "resume": "Continue this run folder from its newest intact checkpoint.",
    "force": "Replace a run already in the folder.",
    "trust": "Open a saved model or a pickled embedding as SB3 and gensim do (files you made).",
}
BOOLS = ("overlap", "loop_flags", "record_trajectories", "average_ahead")


def _run_options() -> list:
    import inspect

    from sb3_disagree.run import RunConfig, train as run

    panel_of = {name: panel for panel, names in PANELS.items() for name in names}
    params = [*options_of(RunConfig, skip=("acer_kwargs", "env_kwargs"), types={"priors": str}),
              *options_of(run, only=("out", "resume", "force", "trust"), types={"resume": Optional[Path], "out": Path}),
              *options_of(_cli_only)]
    out = []
    for p in sorted(params, key=lambda p: list(panel_of).index(p.name)):
        name = p.name
        kind = p.annotation if name in ("out", "resume", "force", "trust") else Optional[
            str if name == "priors" else typing.get_args(p.annotation)[0] if typing.get_args(p.annotation) else p.annotation]
        if kind in (Optional[typing.Any],):
            kind = Optional[str]
        flag = "--env" if name == "env_id" else "--" + name.replace("_", "-")
        decls = "--finish/--bare" if name == "finish" else f"{flag}/--no-{flag[2:]}" if name in BOOLS else flag
        default = p.default.default if name in ("out", "force", "trust", "resume") else None
        option = typer.Option(default, *([decls] if name not in ("force", "trust") else [flag]), help=HELPS[name],
                              rich_help_panel=panel_of[name], show_default=name == "out")
        out.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, annotation=kind, default=option))
    return out


def _cli_only(card_episodes: int = 20, progress_every: float = 30.0, reward_scale: Optional[float] = None,
              ema_decay: Optional[float] = None, features_dtype: Optional[str] = None,
              average_ahead: Optional[bool] = None,
              collision_penalty: Optional[float] = None, reward_distance: Optional[str] = None) -> None:
    """dopt train's settings that are not RunConfig's own fields: the ACER and env settings it nests, the card and the
    progress lines."""


@command(_run_options())
def train(**options) -> None:
    """Train a policy for a new goal from the priors: kickstarted (the default), disagreement options (--mode
    disagreement), or another peer method (--mode)."""
    with clean_errors():
        from sb3_disagree.run import RunConfig, check_resume, train as run, write_card

        out, resume, force, trust = (options.pop(k) for k in ("out", "resume", "force", "trust"))
        card_episodes, every = options.pop("card_episodes"), options.pop("progress_every")
        card_episodes = 20 if card_episodes is None else card_episodes
        every = 30.0 if every is None else every
        given = {k: v for k, v in options.items() if v is not None}
        acer = {k: given.pop(k) for k in ("reward_scale", "ema_decay", "features_dtype", "average_ahead") if k in given}
        env_kwargs = {k: given.pop(k) for k in ("collision_penalty", "reward_distance") if k in given}
        if acer:
            given["acer_kwargs"] = acer
        if env_kwargs:
            given["env_kwargs"] = env_kwargs
        if "priors" in given:
            given["priors"] = _priors(given["priors"])
        steps = given.get("steps")
        if resume is not None:
            from sb3_disagree.run.evaluation import read_config

            check_resume(resume, given, force)
            config = RunConfig(goal=read_config(resume)["goal"])  # the run's saved settings are what train() uses
        elif "goal" not in given:
            raise ValueError("--goal is required: the new goal word (or --resume RUN to continue a run)")
        else:
            config = RunConfig(**given)
            config.validate()
        display = _Display(every)
        with display as callback:
            run_dir, model, finished = run(config, out, resume=resume, callbacks=[callback], force=force,
                                           on_priors=_show_priors, steps=steps if resume is not None else None,
                                           on_round=_show_round, trust=trust)
        if card_episodes and finished:
            console.print(f"evaluating the new policy alone for its card ({card_episodes} episodes each way)")
        _show_evaluations(write_card(run_dir, model, card_episodes if finished else 0, command_line()))
        _show_end(run_dir, model, finished, config.goal)


def _show_round(r) -> None:
    where = f"a round: {r.env_steps:,} env steps" if r.env_steps else "the training's last episodes"
    kept = (f"; validated greedy {', '.join(f'{v:.2f}' for v in r.validation)} after each epoch, kept epoch {r.epoch}"
            if r.validation else "")
    fit = (f"fit loss {r.loss:.3f}, accuracy {r.accuracy:.2f}{kept}" if not math.isnan(r.loss)
           else "nothing to fit, the policy stays as trained")
    console.print(f"greedy consistency, {where}, {r.successes}/{r.episodes} episodes "
                  f"reached the goal, {r.labels:,} labels; {fit}")


def _priors(text: str):
    return "auto" if text == "auto" else split(text)


def _show_priors(names, sims) -> None:
    console.print("priors: " + ", ".join(f"[bold]{n}[/]" + (f" (similarity {s:.3f})" if s is not None else "")
                                         for n, s in zip(names, sims)))


class _Display:
    """The live table on a terminal; plain progress lines at a fixed interval elsewhere (a log file, a pipe, a
    batch scheduler)."""

    def __init__(self, every: float) -> None:
        self.every, self.live = every, None

    def __enter__(self) -> BaseCallback:
        if not console.is_terminal:
            from sb3_disagree.run.progress import ProgressLines

            return ProgressLines(self.every)
        self.live = Live(console=console, refresh_per_second=2, transient=False)
        self.live.__enter__()
        self.callback = LiveDisplay(self.live)
        return self.callback

    def __exit__(self, *exc) -> None:
        if self.live is not None:
            self.live.update(self.callback.table(time.perf_counter()))
            self.live.__exit__(*exc)


def _show_evaluations(evaluations: dict) -> None:
    for label, result in evaluations.items():
        console.print(f"the new policy alone, {label}: success {result.success_rate:.2f}, mean length "
                      f"{result.mean_length:.1f} over {result.episodes} episodes")


def _show_end(run_dir: Path, model, finished: bool, goal: str) -> None:
    if (run_dir / "evaluations.npz").exists():
        import numpy as np

        evals = np.load(run_dir / "evaluations.npz")
        console.print("the new policy alone (success): " + ", ".join(
            f"{t:,} steps {np.mean(s):.2f}" for t, s in zip(evals["timesteps"], evals["successes"])))
    import yaml

    saved = yaml.safe_load((run_dir / "config.yaml").read_text()) or {}
    if finished:
        phase = saved.get("consistency") or {}
        line = f"done: {model.num_timesteps:,} steps"
        start, budget = saved.get("greedy_start"), int(saved.get("steps") or 0)
        if start is not None and start > budget - int(saved.get("greedy_phase") or 0):
            line += f" (the greedy phase waited for {saved.get('ready')} training success: it began at {int(start):,})"
        if phase.get("env_steps"):
            line += f" of training and {int(phase['env_steps']):,} of the greedy-consistency phase"
        harvest = phase.get("harvest")  # labels from the training's own last episodes
        last = f"its last {min(int(saved.get('consistency_harvest') or 0), model.num_timesteps):,} training steps"
        if harvest and not harvest["labels"] and not phase.get("env_steps"):
            line += f" (no episode of {last} reached the goal: model.zip is the trained policy)"
        elif harvest:
            line += f" (model.zip fitted to the loop-free paths of the successful episodes of {last})"
        elif phase:
            line += " (model.zip is its policy)"
        console.print(line + f"; wrote {run_dir}")
        return
    if saved.get("finished"):
        console.print(f"[yellow]interrupted[/] in the greedy-consistency phase; {run_dir}/model.zip is the trained "
                      f"policy; redo the phase with: dopt train --goal {goal} --resume {run_dir}")
        raise typer.Exit(code=130)
    console.print(f"[yellow]interrupted[/] at {model.num_timesteps:,} steps; saved the model and replay buffer "
                  f"in {run_dir}; continue with: dopt train --goal {goal} --resume {run_dir}")
    raise typer.Exit(code=130)


def eval_run(
    run_or_model: Path = typer.Argument(..., help="A run folder or a model.zip."),
    episodes: int = typer.Option(100, "--episodes", min=1, max=100_000),
    deterministic: Optional[bool] = typer.Option(None, "--deterministic/--stochastic", help="Only greedy or only "
                                                 "sampled actions (default: both, side by side; greedy for "
                                                 "--video and --trajectory)."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Env seed of the first evaluation env "
                                       "(default: the run's seed + 20000, as the run's own final evaluation)."),
    video: Optional[Path] = typer.Option(None, "--video", help="Record the policy alone in episodes of its own: "
                                         "the agent's view beside the map (.gif or .mp4)."),
    video_episodes: int = typer.Option(3, "--video-episodes", min=1, max=100, help="Episodes the video records."),
    trajectory: Optional[Path] = typer.Option(None, "--trajectory", help="Draw an episode of the policy alone on "
                                              "the map (PNG)."),
    episode: int = typer.Option(1, "--episode", min=1, max=1000, help="Which of its episodes --trajectory draws."),
    trust: bool = typer.Option(False, "--trust", help="Open the model file as SB3 does, unpickling what it carries "
                               "(a file you made or trust)."),
) -> None:
    """Evaluate the new policy alone (no priors): success rate, episode length, return; watch it with --video."""
    with clean_errors():
        from sb3_disagree.run import evaluate_both, load_run
        from sb3_disagree.run.video import VIDEO_FORMATS

        if video is not None and video.suffix not in VIDEO_FORMATS:
            raise ValueError(f"--video {video}: give a file ending in {' or '.join(VIDEO_FORMATS)}")
        for target in (video, trajectory):
            if target is not None and not target.parent.is_dir():
                raise ValueError(f"{target}: the folder {target.parent} does not exist")
        labels = ("greedy", "sampled") if deterministic is None else ("greedy" if deterministic else "sampled",)
        config, model = load_run(run_or_model, trust)
        results = evaluate_both(model, config, episodes, seed, labels)
        for label, result in results.items():
            console.print(f"{config['goal']}: success {result.success_rate:.2f}, mean length {result.mean_length:.1f}, "
                          f"mean return {result.mean_return:.2f} over {episodes} episodes ({label} actions, no priors)")
        greedy = deterministic is None or deterministic
        if video is not None:
            _video(model, config, video, video_episodes, greedy, seed)
        if trajectory is not None:
            _draw(model, config, trajectory, episode, greedy, seed)


def _video(model, config: dict, out: Path, episodes: int, greedy: bool, seed: Optional[int]) -> None:
    from sb3_disagree.run.video import play, write_video

    played = play(model, config, episodes, greedy, seed, frames=True)
    frames = write_video(played, out)
    console.print(f"wrote {out}: {frames} frames of {episodes} episodes ({'greedy' if greedy else 'sampled'}), "
                  f"{sum(e.success for e in played)} reached the goal")


def _draw(model, config: dict, out: Path, episode: int, greedy: bool, seed: Optional[int]) -> None:
    from sb3_disagree.run.video import draw_played, play

    played = play(model, config, episode, greedy, seed)[-1]
    how = "greedy" if greedy else "sampled"
    outcome = "reached the goal" if played.success else "did not reach the goal"
    draw_played(played, config["env_id"], config["goal"], f"{config['goal']}: episode {episode}, {how}, {outcome} "
                f"in {played.length} steps", out)
    console.print(f"wrote {out}: episode {episode} of the policy alone ({how}), {outcome} in {played.length} steps")


def consistency(
    run: Path = typer.Argument(..., help="A finished ACER run folder (model.zip, config.yaml)."),
    rounds: int = typer.Option(3, "--rounds", help="Collect-and-fit rounds."),
    steps: int = typer.Option(20_000, "--steps", help="Env steps per round (over 4 envs)."),
    epochs: int = typer.Option(3, "--epochs", help="Passes over the aggregated labels per round."),
    learning_rate: float = typer.Option(3e-4, "--learning-rate"),
    episodes: int = typer.Option(100, "--episodes", help="Evaluation episodes each way after the phase (0: none)."),
    force: bool = typer.Option(False, "--force", help="Replace an earlier phase's folder."),
    name: str = typer.Option("consistent", "--name", help="The folder inside RUN the refined model goes to."),
    trust: bool = typer.Option(False, "--trust", help="Open the model file as SB3 does, unpickling what it carries "
                               "(a file you made or trust)."),
) -> None:
    """Greedy consistency: act greedily, sample only in loops, fit the loop-free paths that reach the goal;
    the refined model and its evaluation alone (greedy and sampled) go to RUN/consistent/ (--name)."""
    with clean_errors():
        _consistency(run, rounds, steps, epochs, learning_rate, episodes, force, name, trust)


def _consistency(run: Path, rounds: int = 3, steps: int = 20_000, epochs: int = 3, learning_rate: float = 3e-4,
                 episodes: int = 100, force: bool = False, name: str = "consistent", trust: bool = False) -> None:
    from sb3_disagree.run.consistency import refine_run

    console.print(f"greedy consistency: {rounds} rounds of {steps:,} env steps")
    result = refine_run(run, rounds, steps, epochs, learning_rate, episodes, force, name, on_round=_show_round,
                        trust=trust)
    for label, key in (("greedy", "final_alone_greedy"), ("sampled", "final_alone")):
        if key in result:
            console.print(f"the refined policy alone, {label}: success {result[key]['success_rate']:.2f} over "
                          f"{episodes} episodes")
    console.print(f"wrote {Path(run) / name}: {result['env_steps']:,} env steps in {result['seconds']:.0f} s")
