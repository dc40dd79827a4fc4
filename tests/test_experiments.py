"""`dopt experiment run/report` on a tiny grid of the state apartment: local pool, resume, Ray."""

import json
import shutil
import tempfile

import numpy as np
import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from sb3_disagree.cli.app import app
from sb3_disagree.experiments import report
from sb3_disagree.experiments.curves import last_defined
from sb3_disagree.experiments.report import (CellSummary, cell_colors, goals_markdown, plot_goals, ratio_markdown,
                                             seeds_markdown, summarize, table_markdown)
from sb3_disagree.experiments.runner import run_experiment
from sb3_disagree.experiments.spec import SHIPPED, Experiment, load_experiment

STATE_ID = "sb3_disagree/ApartmentState-v0"
runner = CliRunner()


@pytest.fixture(scope="module")
def zoo(tmp_path_factory):
    root = tmp_path_factory.mktemp("zoo")
    for goal in ("shower", "toilet"):
        r = runner.invoke(app, ["priors", "train", "--goal", goal, "--env", STATE_ID, "--zoo", str(root), "--rounds", "1",
                                "--steps-per-round", "200", "--epochs", "1", "--episodes", "2"])
        assert r.exit_code == 0, r.output
    return root


def _grid(tmp_path, zoo, name="tiny", seeds=(0, 1)):
    spec = {"name": name, "goal": "bathtub", "env_id": STATE_ID, "priors": ["shower", "toilet"], "steps": 320,
            "seeds": list(seeds), "budgets": [160, 320], "final_episodes": 2, "trajectories": True,
            "run": {"n_envs": 2, "zoo": str(zoo), "eval_every": 160, "eval_episodes": 1, "finish": False},
            "acer": {"replay_start": 80},
            "cells": {"disagreement": {"mode": "disagreement"}, "beta-big": {"mode": "disagreement", "beta": 100.0},
                      "scratch": {"mode": "scratch"}}}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_run_report_and_skip_finished(zoo, tmp_path):
    path = _grid(tmp_path, zoo, seeds=(0,))
    out = tmp_path / "results"
    result = runner.invoke(app, ["experiment", "run", str(path), "--jobs", "1", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "3 to do" in result.output
    records = [json.loads(p.read_text()) for p in sorted(out.glob("*/seed-0/result.json"))]
    assert sorted(r["cell"] for r in records) == ["beta-big", "disagreement", "scratch"]
    assert all(r["steps"] >= 320 and 0 <= r["final_alone"]["success_rate"] <= 1 for r in records)
    # Written atomically, yet readable by others (a temporary file's private mode is not kept).
    assert all(p.stat().st_mode & 0o777 == 0o644 for p in out.glob("*/seed-0/result.json"))
    assert not list(out.glob("*/seed-0/.result.json.*"))
    # Each run keeps the few logged columns the report reads in curves.csv, the same values as progress.csv's.
    from sb3_disagree.experiments.curves import CURVE_KEYS, progress_curve

    run_dir = out / "disagreement" / "seed-0"
    curves = pd.read_csv(run_dir / "curves.csv")
    assert set(curves.columns) <= set(CURVE_KEYS) and "prior/usage" in curves
    grid = np.linspace(10, 320, 20)
    from_curves = progress_curve(run_dir, "prior/usage", grid)
    (run_dir / "curves.csv").rename(run_dir / "curves.bak")
    np.testing.assert_array_equal(from_curves, progress_curve(run_dir, "prior/usage", grid))
    (run_dir / "curves.bak").rename(run_dir / "curves.csv")
    # A huge beta follows the priors whenever the branch is entered; scratch never does.
    usage = {c: yaml.safe_load((out / c / "seed-0" / "config.yaml").read_text()) for c in ("beta-big", "scratch")}
    assert usage["beta-big"]["beta"] == 100.0 and usage["scratch"]["chosen_priors"] == []
    again = runner.invoke(app, ["experiment", "run", str(path), "--jobs", "1", "--out", str(out)])
    assert again.exit_code == 0 and "3 finished, 0 to do" in again.output
    report = runner.invoke(app, ["experiment", "report", str(path), "--out", str(out), "--figure", str(tmp_path / "f.png")])
    assert report.exit_code == 0, report.output
    assert (out / "tiny.png").stat().st_size > 0 and (tmp_path / "f.png").exists()
    text = (out / "report.md").read_text()
    assert "| scratch | 1 |" in text and "success at 0.32k" in text and "](tiny.png)" in text
    # Into a page's named block: written once, replaced on the next write, the rest of the page kept.
    page = tmp_path / "page.md"
    page.write_text("# Page\n\nkept\n")
    for _ in range(2):
        written = runner.invoke(app, ["experiment", "report", str(path), "--out", str(out), "--figure",
                                      str(tmp_path / "f.png"), "--section", str(page), "--note", "nothing else ran"])
        assert written.exit_code == 0, written.output
    text = page.read_text()
    assert text.count("<!-- tiny:start -->") == 1 and text.startswith("# Page\n\nkept\n")
    assert "| scratch | 1 |" in text and "](f.png)" in text and "nothing else ran" in text
    # The report can be restricted to seeds, but only to the experiment's own.
    assert runner.invoke(app, ["experiment", "report", str(path), "--out", str(out), "--seeds", "0"]).exit_code == 0
    report = runner.invoke(app, ["experiment", "report", str(path), "--out", str(out), "--seeds", "1"])
    assert report.exit_code == 2 and "not among" in report.output
    # A second report on some cells, under its own name, beside the full one and its page block.
    full = (out / "report.md").read_text()
    args = ["experiment", "report", str(path), "--out", str(out), "--cells", "scratch,beta-big", "--section", str(page)]
    named = runner.invoke(app, args + ["--name", "tiny-two"])
    assert named.exit_code == 0, named.output
    two = (out / "tiny-two.md").read_text()
    assert "| scratch | 1 |" in two and "| beta-big | 1 |" in two and "| disagreement |" not in two
    assert "--cells scratch,beta-big --name tiny-two" in two and "--jobs" not in two
    assert (out / "tiny-two.png").stat().st_size > 0 and (out / "report.md").read_text() == full
    text = page.read_text()
    assert text.count("<!-- tiny:start -->") == 1 and text.count("<!-- tiny-two:start -->") == 1
    for bad, message in ((["--name", "../x"], "a report's name"), (["--cells", "nope"], "not among")):
        refused = runner.invoke(app, args[:5] + bad)
        assert refused.exit_code == 2 and message in refused.output, refused.output
    assert not (tmp_path / "x.md").exists()


def test_runs_go_under_runs_experiments_by_default(zoo, tmp_path, monkeypatch):
    path = _grid(tmp_path, zoo, seeds=(0,))
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(app, ["experiment", "run", str(path), "--jobs", "1", "--cells", "scratch"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "runs" / "experiments" / "tiny" / "scratch" / "seed-0" / "result.json").exists()


def test_summary_numbers_match_the_runs(zoo, tmp_path, monkeypatch):
    experiment = load_experiment(str(_grid(tmp_path, zoo, seeds=(0,))))
    out = tmp_path / "results"
    run_experiment(experiment, out, jobs=1)
    grid, summaries = summarize(experiment, out)
    assert len(grid) == 50 and grid[-1] == 320
    for s in summaries:
        record = json.loads((out / s.cell / "seed-0" / "result.json").read_text())
        assert s.final_alone == record["final_alone"]["success_rate"]
        assert 0 <= s.auc <= 1
        assert s.cell != "scratch" or np.isnan(s.usage).all()
        assert list(s.alone_steps) == [160, 320] and ((0 <= s.alone_mean) & (s.alone_mean <= 1)).all()
        assert s.minutes == record["seconds"] / 60
    table = table_markdown(experiment, summaries)
    assert table.count("\n") == 1 + len(summaries)
    # Every row has as many columns as the header, the last one each run's wall-clock in minutes.
    header, _, *rows = table.splitlines()
    assert header.endswith("env steps/s | minutes per run |")
    assert {row.count("|") for row in rows} == {header.count("|")}
    assert rows[0].endswith(f" {summaries[0].minutes:.1f} |")
    # With one seed, that seed's curve is the mean curve.
    for s in summaries:
        np.testing.assert_array_equal(s.seed_final, [last_defined(s.mean)])  # nan where too few episodes ended
        assert s.seed_steps_to_90 == [s.steps_to_90]
        assert s.auc == np.mean(np.nan_to_num(s.mean, nan=0.0))  # a fixed budget: over the whole run
    # Runs that may wait past the budget (up to twice it) put the grid's end at 640; these stopped at 320, so their
    # curves end there (a rising line here, by hand): each seed's end is its last value, and the area is over the
    # 320 steps every run has, not the empty half counted as zero.
    spec = yaml.safe_load((tmp_path / "tiny.yaml").read_text())
    spec["run"].update(ready=0.9, extend=2.0, greedy_phase=160)
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(spec))
    monkeypatch.setattr(report, "success_curve", lambda folder, grid: grid / 640)
    grid, waiting = summarize(load_experiment(str(tmp_path / "tiny.yaml")), out)
    assert grid[-1] == 640 and len(grid) == 50
    for s in waiting:
        assert np.isnan(s.mean[25:]).all() and s.seed_final == pytest.approx([0.5])
        assert s.auc == pytest.approx(np.mean(np.arange(1, 26) * 12.8 / 640))  # 0.26, where zeros would give 0.13
    assert seeds_markdown(summaries).count("\n") == 1 + len(summaries)
    # A budget that no run of a cell reached reads "-", not nan.
    summaries[0].at_budgets[experiment.budgets[-1]] = float("nan")
    row = table_markdown(experiment, summaries).splitlines()[2]
    assert "nan" not in row and " - |" in row


def test_report_refuses_a_run_whose_monitor_files_miss_steps(zoo, tmp_path):
    experiment = load_experiment(str(_grid(tmp_path, zoo, seeds=(0,))))
    experiment.cells = {"scratch": experiment.cells["scratch"]}
    out = tmp_path / "results"
    run_experiment(experiment, out, jobs=1)
    summarize(experiment, out)  # 320 steps, 2 envs: no episode ended yet, which one episode per env allows
    result = out / "scratch" / "seed-0" / "result.json"
    record = json.loads(result.read_text())
    result.write_text(json.dumps({**record, "steps": 5_000}))  # as if the files had been cut short
    with pytest.raises(ValueError, match="hold episodes of 0 env steps, but the run took 5,000"):
        summarize(experiment, out)


def test_report_reads_training_curves_kept_in_one_file(zoo, tmp_path):
    """The report keeps every run's training curve in training-success.csv and reads it back, the same numbers,
    once the runs' monitor files are gone; a restricted report keeps the other seeds' rows."""
    import shutil

    from sb3_disagree.experiments.writeup import write_report

    experiment = load_experiment(str(_grid(tmp_path, zoo, seeds=(0, 1))))
    experiment.cells = {"scratch": experiment.cells["scratch"]}
    out = tmp_path / "results"
    run_experiment(experiment, out, jobs=1)
    for seed in (0, 1):  # 20 episodes of 8 steps in each env, as if they had ended: success on alternate ones
        for f in (out / "scratch" / f"seed-{seed}" / "monitor").glob("*.monitor.csv"):
            head = f.read_text().splitlines()[:2]
            f.write_text("\n".join(head + [f"0.0,8,{i},{(i + seed) % 2 == 0}" for i in range(20)]) + "\n")
    grid, before = summarize(experiment, out)
    assert np.nanmax(before[0].mean) > 0  # the curves have values to keep
    write_report(experiment, out)
    kept = pd.read_csv(out / "training-success.csv")
    assert list(kept["seed"]) == [0, 1] and kept.shape[1] == 2 + len(grid)
    for seed in (0, 1):
        shutil.rmtree(out / "scratch" / f"seed-{seed}" / "monitor")
    _, after = summarize(experiment, out)
    np.testing.assert_array_equal(before[0].mean, after[0].mean)
    for b, a in zip(before[0].seed_curves, after[0].seed_curves):
        np.testing.assert_array_equal(b, a)
    assert before[0].seed_steps_to_90 == after[0].seed_steps_to_90
    experiment.restrict(seeds=[0])
    write_report(experiment, out)
    assert list(pd.read_csv(out / "training-success.csv")["seed"]) == [0, 1]
    # A run with neither its monitor files nor a row: refused, naming it.
    kept[kept["seed"] == 0].to_csv(out / "training-success.csv", index=False)
    experiment = load_experiment(str(_grid(tmp_path, zoo, seeds=(0, 1))))
    experiment.cells = {"scratch": experiment.cells["scratch"]}
    with pytest.raises(ValueError, match="seed-1: no monitor files"):
        summarize(experiment, out)


def test_steps_ratio_is_bounded_where_a_curve_never_gets_there():
    grid = np.linspace(6_000, 300_000, 50)

    def cell(name, seeds, steps, mean_steps):
        nan = np.full(50, np.nan)
        return CellSummary(cell=name, seeds=seeds, mean=nan, low=nan, high=nan, usage=nan, steps_to_50=None,
                           steps_to_90=mean_steps, at_budgets={}, auc=0.0, final_alone=0.0, final_alone_seeds=[],
                           fps=0.0, seed_steps_to_90=steps)

    summaries = [cell("disagreement", [0, 1, 2, 3], [42_000, None, 60_000, None], 120_000),
                 cell("scratch", [0, 1, 2], [210_000, 150_000, None], None)]
    rows = ratio_markdown(grid, summaries).splitlines()[2:]
    assert rows == ["| 0 | 42k | 210k | 0.20 |",
                    "| 1 | not reached | 150k | > 2.00 |",
                    "| 2 | 60k | not reached | < 0.20 |",  # seed 3 has no scratch run: no row
                    "| mean curves | 120k | not reached | < 0.40 |"]
    assert ratio_markdown(grid, summaries[:1]) is None


def test_ray_backend_runs_two_tiny_runs(zoo, tmp_path):
    ray = pytest.importorskip("ray")
    experiment = load_experiment(str(_grid(tmp_path, zoo, seeds=(0, 1))))
    experiment.cells = {"disagreement": experiment.cells["disagreement"]}
    out = tmp_path / "results"
    # Ray's session files go to a folder of the test's own (a short path: Ray's sockets live in it), not /tmp/ray.
    session = tempfile.mkdtemp(prefix="ray-")
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, _temp_dir=session)  # one worker, imported once
    try:
        results = run_experiment(experiment, out, backend="ray")
    finally:
        ray.shutdown()
        shutil.rmtree(session, ignore_errors=True)
    assert sorted(r["seed"] for r in results) == [0, 1]
    for seed in (0, 1):
        folder = out / "disagreement" / f"seed-{seed}"
        for name in ("result.json", "model.zip", "progress.csv", "config.yaml"):
            assert (folder / name).exists(), name
        assert list((folder / "monitor").glob("*.monitor.csv"))


def test_continuing_an_experiment_extends_its_runs(zoo, tmp_path):
    """``continues``: each run starts from the other experiment's finished run and keeps its history."""
    import pandas as pd

    short = _grid(tmp_path, zoo, seeds=(0,))
    results = tmp_path / "results"
    assert runner.invoke(app, ["experiment", "run", str(short), "--jobs", "1", "--cells", "scratch",
                               "--out", str(results / "tiny")]).exit_code == 0
    spec = yaml.safe_load(short.read_text())
    spec.update(name="tiny-long", continues="tiny", steps=640, budgets=[320, 640])
    long = tmp_path / "tiny-long.yaml"
    long.write_text(yaml.safe_dump(spec))
    # Cells without a finished run to continue are refused before anything runs.
    result = runner.invoke(app, ["experiment", "run", str(long), "--jobs", "1", "--out", str(results / "tiny-long")])
    assert result.exit_code == 2 and "run first: dopt experiment run tiny" in result.output
    assert not (results / "tiny-long").exists()
    result = runner.invoke(app, ["experiment", "run", str(long), "--jobs", "1", "--cells", "scratch",
                                 "--out", str(results / "tiny-long")])
    assert result.exit_code == 0, result.output
    before, after = results / "tiny" / "scratch" / "seed-0", results / "tiny-long" / "scratch" / "seed-0"
    record = json.loads((after / "result.json").read_text())
    assert record["from_steps"] == 320 and record["steps"] == 640
    assert list(np.load(after / "evaluations.npz")["timesteps"]) == [160, 320, 480, 640]
    steps = pd.read_csv(after / "progress.csv")["time/total_timesteps"].dropna()
    assert steps.iloc[0] <= 320 < steps.iloc[-1]
    # The continued run is left as it was.
    assert json.loads((before / "result.json").read_text())["steps"] == 320
    # A continuation with other settings than the run it continues is refused.
    spec.update(name="tiny-other", cells={"scratch": {"mode": "scratch", "n_envs": 4}})
    other = tmp_path / "tiny-other.yaml"
    other.write_text(yaml.safe_dump(spec))
    result = runner.invoke(app, ["experiment", "run", str(other), "--jobs", "1", "--out", str(results / "tiny-other")])
    assert result.exit_code == 2 and "trained with other n_envs" in result.output
    # Any setting the continuation would silently not use counts, not only the method's own (here: evaluations).
    spec.update(name="tiny-eval", cells={"scratch": {"mode": "scratch"}}, run={**spec["run"], "eval_every": 80})
    other.write_text(yaml.safe_dump(spec))
    result = runner.invoke(app, ["experiment", "run", str(other), "--jobs", "1", "--out", str(results / "tiny-eval")])
    assert result.exit_code == 2 and "trained with other eval_every" in result.output


def test_a_cell_same_as_another_experiments_run_is_copied_not_trained(zoo, tmp_path, monkeypatch):
    """``same_as``: a finished run of the same configuration is taken as it is; another configuration is refused."""
    from sb3_disagree.experiments import runner as runner_module

    short = _grid(tmp_path, zoo, seeds=(0,))
    results = tmp_path / "results"
    assert runner.invoke(app, ["experiment", "run", str(short), "--jobs", "1", "--cells", "scratch",
                               "--out", str(results / "tiny")]).exit_code == 0
    spec = yaml.safe_load(short.read_text())
    spec.update(name="ablation", cells={"same": {"mode": "scratch", "same_as": "tiny/scratch"}})
    path = tmp_path / "ablation.yaml"
    path.write_text(yaml.safe_dump(spec))

    def no_training(*args, **kwargs):
        raise AssertionError("a run with a finished twin was trained")

    monkeypatch.setattr(runner_module, "train_and_evaluate", no_training)
    done = run_experiment(load_experiment(str(path)), results / "ablation", jobs=1)
    source, copy = results / "tiny" / "scratch" / "seed-0", results / "ablation" / "same" / "seed-0"
    assert [r["cell"] for r in done] == ["same"] and done[0]["copied_from"] == str(source)
    assert (copy / "progress.csv").read_bytes() == (source / "progress.csv").read_bytes()
    original = json.loads((source / "result.json").read_text())
    assert json.loads((copy / "result.json").read_text())["final_alone"] == original["final_alone"]
    # Another configuration under the same name is an error, before anything runs.
    spec.update(name="other", cells={"same": {"mode": "scratch", "alpha": 3, "same_as": "tiny/scratch"}})
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(ValueError, match="differs in alpha"):
        run_experiment(load_experiment(str(path)), results / "other", jobs=1)
    assert not (results / "other").exists()


@pytest.mark.parametrize("bad,message", [
    ({"cells": {}}, "at least one cell"),
    ({"cells": {"a": {"mode": "nonsense"}}}, "--mode"),
    ({"cells": {"a": {"gamma": 0.9}}}, "unknown run fields"),
    ({"run": {"env_id": "sb3_disagree/ApartmentState-v0"}, "cells": {"a": {}}}, "env_id is set at the top"),
    ({"cells": {"a": {"seed": 3}}}, "seed is set at the top"),
    ({"cells": {"a": {"beta": -1}}}, "--beta"),
    ({"typo": 1, "cells": {"a": {}}}, "unknown keys"),
    ({"cells": {"a": {"same_as": "fig3-bathtub"}}}, "same_as must read OTHER/CELL"),
])
def test_bad_experiment_files_are_clear_errors(tmp_path, bad, message):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({"goal": "bathtub", **bad}))
    result = runner.invoke(app, ["experiment", "run", str(path)])
    assert result.exit_code == 2 and message in result.output


def test_seeds_and_cells_can_be_restricted_but_not_invented(zoo, tmp_path):
    path = _grid(tmp_path, zoo, seeds=(0, 1))
    experiment = load_experiment(str(path))
    experiment.restrict(seeds=[1], cells=["scratch"])
    assert [(r.cell, r.seed) for r in experiment.runs()] == [("scratch", 1)]
    result = runner.invoke(app, ["experiment", "run", str(path), "--seeds", "7"])
    assert result.exit_code == 2 and "not among" in result.output


def test_unknown_experiment_name_lists_the_known_ones():
    result = runner.invoke(app, ["experiment", "run", "fig99-nothing"])
    assert result.exit_code == 2 and "no experiment named" in result.output


def test_shipped_experiments_load():
    names = {p.stem for p in SHIPPED.glob("*.yaml")}
    assert {"fig3-bathtub", "fig3-nightstand", "fig5-trajectories", "fig6-beta", "fig7-alpha", "fig9-office"} <= names
    for name in names:
        assert load_experiment(name).runs()


def test_a_cells_mode_picks_acers_defaults_and_the_grid_and_cell_go_on_top(tmp_path):
    from sb3_disagree.run import ACER_KWARGS, RunConfig

    spec = {"name": "modes", "goal": "bathtub", "priors": ["shower", "toilet"], "steps": 320, "seeds": [0],
            "budgets": [320], "acer": {"ent_coef": 0.02},
            "cells": {"kick": {"mode": "kickstart"}, "kick-01": {"mode": "kickstart", "acer": {"reward_scale": 0.1}},
                      "options": {"mode": "disagreement"}, "default": {}}}
    path = tmp_path / "modes.yaml"
    path.write_text(yaml.safe_dump(spec))
    acer = {r.cell: r.config.acer_kwargs for r in load_experiment(path).runs()}
    assert acer["kick"]["reward_scale"] == 1.0 and acer["default"]["reward_scale"] == 1.0  # as RunConfig's
    assert acer["kick-01"]["reward_scale"] == 0.1 and acer["options"]["reward_scale"] == 1.0  # disagreement's preset
    assert all(a["ent_coef"] == 0.02 and a["n_steps"] == ACER_KWARGS["n_steps"] for a in acer.values())
    assert acer["default"] == RunConfig(goal="bathtub", acer_kwargs={"ent_coef": 0.02}).acer_kwargs


def test_a_record_older_than_an_acer_setting_ran_at_acers_default():
    from sb3_disagree.experiments.spec import _differing
    from sb3_disagree.run import RunConfig

    pinned = RunConfig(goal="bathtub", mode="kickstart", acer_kwargs={"reward_scale": 0.1, "ema_decay": 0.0})
    saved = {**pinned.__dict__, "acer_kwargs": {k: v for k, v in pinned.acer_kwargs.items() if k != "ema_decay"}}
    assert _differing(saved, pinned) == []  # written before ema_decay existed: it ran without an average
    averaged = RunConfig(goal="bathtub", mode="kickstart", acer_kwargs={"reward_scale": 0.1, "ema_decay": 0.999})
    assert _differing(saved, averaged) == ["acer_kwargs"]
    assert _differing({**saved, "acer_kwargs": {**saved["acer_kwargs"], "reward_scale": 1.0}}, pinned) == ["acer_kwargs"]


def test_the_reports_acer_line_names_what_most_cells_have_and_what_each_sets_itself():
    from types import SimpleNamespace

    from sb3_disagree.experiments.writeup import acer_text

    def cell(name, **acer):
        return SimpleNamespace(cell=name, records=[{"config": {"acer_kwargs": {"n_steps": 20, **acer}}}])

    assert acer_text([cell("a", reward_scale=0.1), cell("b", reward_scale=0.1)]) == "{n_steps: 20, reward_scale: 0.1}"
    text = acer_text([cell("a", reward_scale=0.1), cell("b", reward_scale=1.0, distill_coef=1.0),
                      cell("c", reward_scale=0.1)])
    # a cell that does not name a setting another names ran at ACER's default (distill_coef 0)
    assert text == ("{distill_coef: 0.0, n_steps: 20, reward_scale: 0.1}; the cells' own: b {distill_coef: 1.0, "
                    "reward_scale: 1.0}")
    text = acer_text([cell("a"), cell("b", distill_coef=1.0), cell("c", distill_coef=1.0)])
    assert text == "{distill_coef: 1.0, n_steps: 20}; the cells' own: a {distill_coef: 0.0}"


def test_shipped_grids_still_make_their_committed_runs():
    """Every committed run's settings are what its grid makes today (a changed default is pinned in the grids
    whose results used the old one), so that rerunning a grid reproduces its table."""
    from dataclasses import asdict
    from pathlib import Path

    from sb3_disagree.run.presets import RESOLVED, acer_signature_defaults, trained_with

    results = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "experiments"
    acer, compared = acer_signature_defaults(), 0
    for path in sorted(SHIPPED.glob("*.yaml")):
        experiment = load_experiment(path)
        for run in experiment.runs():
            saved_path = results / experiment.name / run.cell / f"seed-{run.config.seed}" / "result.json"
            if not saved_path.exists() or experiment.continues:  # a continuation keeps its run's saved settings
                continue
            record, now = json.loads(saved_path.read_text())["config"], asdict(run.config)
            # a setting newer than the record ran at what the library had then (ACER's default, the mode's distillation)
            saved = trained_with(record, {})
            if now["mode"] != "ppo":  # SB3's PPO runs none of ACER's settings, whatever a record of it lists
                assert saved["acer_kwargs"] == {**acer, **now["acer_kwargs"]}, (experiment.name, run.cell)
            assert saved["mode"] == now["mode"]
            # what a mode's preset resolves: the saved value, or what the library ran with before it was saved
            assert {k: saved[k] for k in RESOLVED} == {k: now[k] for k in RESOLVED}, (
                experiment.name, run.cell)
            compared += 1
    assert compared >= 170  # the grids behind the results page


def test_the_policy_alone_table_reads_greedy_and_sampled_at_each_evaluation():
    from sb3_disagree.experiments.report import alone_markdown

    nan = np.full(3, np.nan)

    def cell(name, greedy):
        return CellSummary(cell=name, seeds=[0], mean=nan, low=nan, high=nan, usage=nan, steps_to_50=None,
                           steps_to_90=None, at_budgets={}, auc=0.0, final_alone=0.0, final_alone_seeds=[], fps=0.0,
                           alone_steps=np.array([25_000, 50_000]), alone_mean=np.array([0.2, 0.9]),
                           alone_greedy=np.array(greedy))

    assert alone_markdown([cell("old", [])]) is None  # runs that measured no greedy evaluation
    rows = alone_markdown([cell("finetune", [0.0, 0.5]), cell("old", [])]).splitlines()
    assert rows[0] == "| cell | 25k greedy / sampled | 50k greedy / sampled |"
    assert rows[2:] == ["| finetune | 0.00 / 0.20 | 0.50 / 0.90 |"]


@pytest.mark.parametrize("n", [3, 10, 11, 20, 21, 33, 60])
def test_every_cell_of_a_figure_has_its_own_colour(n):
    # The full alone-bathtub figure has over 30 cells: a colormap indexed past its 20 colours gave the rest one colour.
    colors = cell_colors(n)
    assert len(colors) == n and len(set(colors)) == n


def test_cell_colours_repeat_only_past_sixty():
    colors = cell_colors(61)
    assert len(set(colors)) == 60 and colors[60] == colors[0]


def test_a_list_of_goals_runs_every_cell_on_every_goal_with_its_own_priors(zoo, tmp_path):
    spec = yaml.safe_load(_grid(tmp_path, zoo).read_text())
    spec.update(name="goals", goal=["bathtub", "toilet"], priors="auto", trajectories=False)
    path = tmp_path / "goals.yaml"
    path.write_text(yaml.safe_dump(spec))
    experiment = load_experiment(str(path))
    runs = experiment.runs()
    assert [r.cell for r in runs[:6]] == ["beta-big@bathtub", "disagreement@bathtub", "scratch@bathtub",
                                          "beta-big@toilet", "disagreement@toilet", "scratch@toilet"]  # (sorted)
    assert {(r.cell.split("@")[1], r.config.goal, r.config.priors) for r in runs} == {
        ("bathtub", "bathtub", "auto"), ("toilet", "toilet", "auto")}
    assert runs[0].config.beta == 100.0 and len(runs) == 12  # two seeds
    experiment.restrict(seeds=[0], cells=["scratch", "beta-big@toilet"])  # a cell alone: on every goal
    assert [r.cell for r in experiment.runs()] == ["scratch@bathtub", "beta-big@toilet", "scratch@toilet"]
    with pytest.raises(ValueError, match="not among"):
        load_experiment(str(path)).restrict(cells=["nothing"])
    for bad in ({"priors": ["shower", "toilet"]}, {"goal": ["bathtub", "bathtub"]}, {"goal": ["bathtub", 3]}):
        path.write_text(yaml.safe_dump({**spec, **bad}))
        with pytest.raises(ValueError, match="list of goals|distinct words"):
            load_experiment(str(path))


def test_a_goals_table_reads_each_goals_priors_and_its_mean_and_lowest_goal(tmp_path):
    spec = {"name": "g", "goal": ["bathtub", "toilet", "bed"], "cells": {"a": {}, "b": {}}, "steps": 1000}
    experiment = Experiment(**spec)

    def cell(name, greedy, sampled, to_90, steps=(100_000, 100_000)):
        nan = np.full(50, np.nan)
        return CellSummary(cell=name, seeds=[0, 1], mean=nan, low=nan, high=nan, usage=nan, steps_to_50=None,
                           steps_to_90=to_90, at_budgets={}, auc=0.0, final_alone=float(np.mean(sampled)),
                           final_alone_seeds=sampled, fps=0.0, final_greedy_seeds=greedy,
                           records=[{"steps": s} for s in steps])

    for goal, priors in (("bathtub", ["shower", "toilet"]), ("toilet", ["bathtub", "shower"])):
        (tmp_path / f"a@{goal}" / "seed-0").mkdir(parents=True)
        (tmp_path / f"a@{goal}" / "seed-0" / "config.yaml").write_text(yaml.safe_dump({"chosen_priors": priors}))
    summaries = [cell("a@bathtub", [0.9, 0.8], [1.0, 1.0], 40_000, (127_440, 127_360)), cell("b@bathtub", [0.5, 0.7], [0.9, 1.0], None),
                 cell("a@toilet", [0.6, 0.4], [0.98, 0.96], 62_000, (100_000, 150_640))]  # bed not run; b not run on the toilet
    rows = goals_markdown(experiment, summaries, tmp_path).splitlines()
    assert rows[0].startswith("| goal | priors | a: greedy | a: sampled | a: 90% training success | a: env steps | "
                              "b: greedy |")
    assert rows[2] == ("| bathtub | shower, toilet | 0.85 (0.90, 0.80) | 1.00 (1.00, 1.00) | 40k | 127k | 0.60 (0.50, 0.70) | "
                       "0.95 (0.90, 1.00) | not reached | 100k |")
    assert rows[3] == ("| toilet | bathtub, shower | 0.50 (0.60, 0.40) | 0.97 (0.98, 0.96) | 62k | 100k, 151k | not run | "
                       "not run | not run | |")
    assert rows[4] == "| bed | - | not run | not run | not run | | not run | not run | not run | |"
    # a: greedy means 0.85 and 0.50, sampled 1.00 and 0.97; b: bathtub alone
    assert rows[5] == "| **mean over the goals run** | | **0.68** | **0.98** | | | **0.60** | **0.95** | | |"
    assert rows[6] == ("| **lowest goal** | | **0.50** (toilet; sampled: toilet) | **0.97** | | | **0.60** (bathtub; "
                       "sampled: bathtub) | **0.95** | | |")
    plot_goals(experiment, summaries, tmp_path / "goals.png", tmp_path)
    assert (tmp_path / "goals.png").stat().st_size > 0


def test_a_run_never_takes_more_torch_threads_than_its_cores(monkeypatch):
    from sb3_disagree.experiments.runner import torch_threads

    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert [torch_threads(True, 2), torch_threads(True, 1), torch_threads(False, 2), torch_threads(True, 16)] == [
        2, 1, 1, 2]  # two runs at a time on 2 cores: one thread each
    monkeypatch.setenv("OMP_NUM_THREADS", "1")  # lanes started side by side say so
    assert torch_threads(True, 2) == 1
