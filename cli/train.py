"""``dopt train`` and ``dopt eval``: the method on the command line, with a live display."""

import math
import time
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
        t.add_row("steps", f"{m.num_timesteps:,} / {self.total:,}")
        t.add_row("env steps/s", f"{(m.num_timesteps - self.n0) / max(now - self.t0, 1e-9):.0f}")
        t.add_row("success (last 100 episodes)", f"{sum(success) / len(success):.2f}" if success else "-")
        t.add_row("prior usage", f"{stats['prior/usage']:.2f}" if "prior/usage" in stats else "-")
        t.add_row("disagreement", f"{stats['prior/disagreement']:.3f}" if "prior/disagreement" in stats else "-")
        return t


def _run_options() -> list:
    from sb3_disagree.run import RunConfig, train as run
    from sb3_disagree.run.config import DOPT_TRAIN_FRAME_STACK, DOPT_TRAIN_HARVEST, DOPT_TRAIN_VALIDATION

    helps = {"goal": "The new goal word (required, but with --resume: the run's own)",
             "steps": "Env steps to train (default 100000); with --resume, the run's new total (default: its saved "
                      "one)", "priors": "auto (the two nearest the goal in the embedding), or the priors' goals: a,b",
             "consistency_harvest": "model.zip is fitted to the loop-free paths of the successful episodes of the "
                                    f"last this many training steps, no env step more (default: {DOPT_TRAIN_HARVEST} for "
                                    "--mode kickstart, 0 (off) for the others)",
             "greedy_phase": "The last this many env steps act by the new policy's argmax, --greedy-epsilon of its "
                             "samples (default: the harvest's steps for a new --mode kickstart run, else 0)",
             "consistency_validation": "Each greedy-consistency fit (the harvest's) is validated after every "
                                       "epoch over this many greedy episodes and keeps its best epoch (default: "
                                       f"{DOPT_TRAIN_VALIDATION} for --mode kickstart with a harvest, else 0 (off))",
             "frame_stack": "The new policy sees its last this many observations (its memory; default: "
                            f"{DOPT_TRAIN_FRAME_STACK} with --loop-flags, else 1)",
             "loop_flags": "The new policy's CNN sees the newest frame, and flags say whether it equals each older "
                           "frame of the stack: pressed against a wall, turning back and forth (default: on for "
                           "--mode kickstart on image observations)"}
    return [*options_of(RunConfig, skip=("acer_kwargs", "env_kwargs"),
                        types={"goal": Optional[str], "priors": str, "steps": Optional[int], "consistency_harvest": Optional[int],
                               "frame_stack": Optional[int], "loop_flags": Optional[bool],
                               "greedy_phase": Optional[int], "consistency_validation": Optional[int]},
                        flags={"env_id": "--env", "loop_flags": "--loop-flags/--no-loop-flags"}, helps=helps,
                        # dopt train overlaps the replay updates (faster on two cores); --no-overlap for the
                        # sequential loop the experiments use. It fits model.zip to the loop-free paths of its own
                        # last episodes, acted greedily by the current weights (DOPT_TRAIN_HARVEST); None: resolved in
                        # train. Its new kickstarting runs see three frames, with loop flags (DOPT_TRAIN_FRAME_STACK),
                        # and validate the harvest's fit epoch by epoch (DOPT_TRAIN_VALIDATION).
                        defaults={"goal": None, "overlap": True, "steps": None, "consistency_harvest": None,
                                  "frame_stack": None, "loop_flags": None, "greedy_phase": None,
                                  "consistency_validation": None}),
            *options_of(run, only=("out", "resume", "force", "trust"), types={"resume": Optional[Path], "out": Path}),
            *options_of(_cli_only, flags={"average_ahead": "--average-ahead/--no-average-ahead"})]


def _cli_only(card_episodes: int = 20, progress_every: float = 30.0, reward_scale: Optional[float] = None,
              ema_decay: Optional[float] = None, features_dtype: Optional[str] = None,
              average_ahead: Optional[bool] = None,
              collision_penalty: Optional[float] = None, reward_distance: Optional[str] = None) -> None:
    """
    :param reward_scale: Rewards in ACER's updates are multiplied by this (default: the mode's; 1.0 for
        kickstarting, 0.1 for the others). At 1.0 kickstarting's policy is sharper, its argmax a real choice
        (docs/results.md)
    :param ema_decay: The saved model acts with a moving average of the policy's weights, of this decay per update
        (default: the mode's; 0.999 for kickstarting, 0 (the last weights) for the others); learning is unchanged
        (docs/acer.md, item 22)
    :param features_dtype: "bfloat16": the CNN's passes in ACER's updates run in bfloat16 (faster on CPUs with
        bfloat16 instructions); heads, losses, acting and the saved weights stay float32 ("float32", the
        default: all float32; 9b0ec2d:docs/results.md, "bfloat16 features")
    :param average_ahead: With the overlapped loop, the trust region's reference for the replay updates is computed
        by the rollout thread before it hands them over (faster on two cores; the reference up to ceil(replay_ratio)
        updates older; docs/acer.md, item 24). Default: on for a new --mode kickstart run with the overlapped loop,
        where it was measured (docs/results.md), else off
    :param collision_penalty: Subtracted from the env's reward on a blocked move_forward (the env's
        collision_penalty; default 0, the paper's reward); what counts as success is unchanged
    :param reward_distance: What the env's reward distance follows: "euclidean" (the apartment's default, the
        paper's straight line) or "geodesic" (the shortest free path; the office scans always use it); what counts
        as success is unchanged
    :param card_episodes: Episodes each way (greedy, sampled) of the evaluation on the model card written beside
        model.zip (0: none)
    :param progress_every: Seconds between progress lines when the output is not a terminal
    """


@command(_run_options())
def train(**options) -> None:
    """Train a policy for a new goal from the priors: kickstarted (the default), disagreement options (--mode
    disagreement), or another peer method (--mode)."""
    with clean_errors():
        from sb3_disagree.run import RunConfig, check_resume, train as run, write_card

        out, resume, force, card_episodes, every, trust = (
            options.pop(k) for k in ("out", "resume", "force", "card_episodes", "progress_every", "trust"))
        if options["goal"] is None:
            if resume is None:
                raise ValueError("--goal is required: the new goal word (or --resume RUN to continue a run)")
            from sb3_disagree.run.evaluation import read_config

            options["goal"] = read_config(resume)["goal"]
        options["acer_kwargs"] = {k: v for k in ("reward_scale", "ema_decay", "features_dtype") if (v := options.pop(k)) is not None}
        _default_ahead(options, resume)
        options["env_kwargs"] = {k: v for k in ("collision_penalty", "reward_distance") if (v := options.pop(k)) is not None}
        steps = options["steps"]
        budget = 100_000 if steps is None else steps
        _default_harvest(options, resume, budget)
        _default_memory(options, resume)
        config = RunConfig(**{**options, "steps": budget, "priors": _priors(options["priors"])})
        config.validate() if resume is None else check_resume(config, resume, force)
        display = _Display(every)
        with display as callback:
            run_dir, model, finished = run(config, out, resume=resume, callbacks=[callback], force=force,
                                           on_priors=_show_priors, steps=steps if resume is not None else None,
                                           on_round=_show_round, trust=trust)
        if card_episodes and finished:
            console.print(f"evaluating the new policy alone for its card ({card_episodes} episodes each way)")
        _show_evaluations(write_card(run_dir, model, card_episodes if finished else 0, command_line()))
        _show_end(run_dir, model, finished, config.goal)


def _default_harvest(options: dict, resume: Optional[Path], budget: int) -> None:
    """dopt train's harvest where none is given: ``DOPT_TRAIN_HARVEST`` for a new run of the default mode
    (kickstarting, where it was measured), acted greedily: a new kickstarting run's harvest, whatever its length, is
    a greedy phase too unless ``--greedy-phase`` says otherwise, and its fits are validated
    (``DOPT_TRAIN_VALIDATION`` episodes) where there is a fit. None for the other modes, and none asked of a resumed
    run (it keeps its saved settings).

    :param budget: The run's env steps (a harvest longer than the budget is acted greedily throughout)
    """
    from sb3_disagree.run.config import DOPT_TRAIN_HARVEST, DOPT_TRAIN_VALIDATION

    new_kickstart = resume is None and options["mode"] == "kickstart"
    if options["consistency_harvest"] is None:
        options["consistency_harvest"] = DOPT_TRAIN_HARVEST if new_kickstart else 0
    if options["greedy_phase"] is None:
        options["greedy_phase"] = min(options["consistency_harvest"], budget) if new_kickstart else 0
    if options["consistency_validation"] is None:
        fitted = options["consistency_harvest"]
        options["consistency_validation"] = DOPT_TRAIN_VALIDATION if new_kickstart and fitted else 0


def _default_ahead(options: dict, resume: Optional[Path]) -> None:
    """dopt train's ``average_ahead`` where none is given: on for a new run of the default mode (kickstarting, where
    it was measured) in the overlapped loop it needs; off otherwise, and a resumed run keeps its saved setting. Moves
    the option into ``acer_kwargs`` (only when on, as ACER's default is off)."""
    ahead = options.pop("average_ahead")
    if ahead is None:
        ahead = resume is None and options["mode"] == "kickstart" and options["overlap"]
    if ahead:
        options["acer_kwargs"]["average_ahead"] = True


def _default_memory(options: dict, resume: Optional[Path]) -> None:
    """dopt train's memory where none is given: ``DOPT_TRAIN_FRAME_STACK`` frames with loop flags for a new run of
    the default mode (kickstarting, where they were measured) on image observations; one frame otherwise, and a
    resumed run keeps its saved memory."""
    from sb3_disagree.run.config import DOPT_TRAIN_FRAME_STACK, image_observations

    stack, flags = options["frame_stack"], options["loop_flags"]
    if flags is None:
        flags = (stack is None and resume is None and options["mode"] == "kickstart"
                 and image_observations(options["env_id"]))
    if stack is None:
        stack = DOPT_TRAIN_FRAME_STACK if flags else 1
    options["frame_stack"], options["loop_flags"] = stack, bool(flags)


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
            from sb3_disagree.callbacks import ProgressLines

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
