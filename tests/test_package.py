"""The package as SB3 users meet it: envs registered on import, cheaply; nothing changed in the process."""

import subprocess
import sys


def test_import_registers_every_env_without_loading_a_renderer_or_touching_the_environment():
    code = """
import os, sys
import gymnasium as gym, stable_baselines3, torch  # what they set is theirs (gymnasium hides pygame's prompt)
before = dict(os.environ)
import sb3_disagree
gym.register_envs(sb3_disagree)
heavy = [m for m in ("pyglet", "miniworld", "moderngl", "OpenGL") if m in sys.modules]
assert not heavy, heavy
assert dict(os.environ) == before
for env_id in ("Apartment-v0", "ApartmentState-v0", "Office-v0", "OfficeState-v0"):
    assert "sb3_disagree/" + env_id in gym.registry
env = gym.make("sb3_disagree/ApartmentState-v0", goal="bathtub")
obs, info = env.reset(seed=0)
assert obs.shape == (4,) and info["goal_room"] == "bathroom"
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


def test_the_wheel_works_alone_from_another_folder(tmp_path):
    """Build the wheel, install it (no dependencies) into a fresh venv that sees this environment's packages,
    and run the main commands from a folder with no repository: zoo, scenes and grids come from the wheel."""
    import os
    import re
    import site
    import sysconfig
    from pathlib import Path

    from readme import block_with

    repo = Path(__file__).resolve().parents[1]
    dist = tmp_path / "dist"
    # The README's two commands: the wheel built here without isolation (this environment's setuptools), then
    # installed without its dependencies (torch first, as the README says; this environment has them).
    make_wheel, install_both = block_with("pip wheel")
    assert make_wheel == "pip wheel --no-deps -w dist ."
    torch_first, install_wheel = install_both.split(" && ")
    assert torch_first == "pip install " + re.search(r"^TORCH\s*\?=\s*(\S+)", (repo / "Makefile").read_text(), re.M)[1]
    assert install_wheel == "pip install dist/sb3_disagree-*.whl"
    # Nothing of this process's own path may leak into the commands (the wheel's copy must be what imports).
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    pip_wheel = [str(dist) if t == "dist" else str(repo) if t == "." else t for t in make_wheel.split()]
    import shutil

    shutil.rmtree(repo / "build", ignore_errors=True)  # setuptools' build folder keeps files the tree has dropped
    build = subprocess.run([sys.executable, "-m", *pip_wheel, "--no-build-isolation", "-q"], capture_output=True,
                           text=True, timeout=300, env=env)
    assert build.returncode == 0, build.stderr
    (wheel,) = dist.glob("sb3_disagree-*.whl")
    assert wheel.stat().st_size < 60e6
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    # This environment's packages (torch, SB3, ...) but not its editable install of this repository.
    ours = {sysconfig.get_paths()["purelib"], *site.getsitepackages()}
    (Path(purelib) / "outer.pth").write_text("\n".join(sorted(ours)) + "\n")
    install = subprocess.run([str(python), "-m", "pip", "install", "--no-deps", "--no-index", "-q", str(wheel)],
                             capture_output=True, text=True, timeout=300, env=env)
    assert install.returncode == 0, install.stderr
    work = tmp_path / "elsewhere"
    work.mkdir()
    dopt = str(venv / "bin" / "dopt")

    def run(*args):
        result = subprocess.run(args, cwd=work, capture_output=True, text=True, timeout=600, env=env)
        assert result.returncode == 0, (args, result.stdout[-2000:], result.stderr[-2000:])
        return result.stdout

    where = run(str(python), "-c", "import sb3_disagree, sb3_disagree.priors.zoo as z; print(sb3_disagree.__file__, z.DEFAULT_ZOO)")
    assert str(repo) not in where and str(venv) in where
    assert "chosen" in run(dopt, "priors", "list", "--goal", "bathtub")
    assert "3+flags" in run(dopt, "priors", "list", "--zoo", "greedy", "--goal", "bathtub")  # shipped beside it
    assert "fig3-bathtub" in run(dopt, "experiment", "list")
    assert "CartPole-v1" in run(str(python), "-c", "from sb3_disagree.rl_zoo import HYPERPARAMS; "
                                                   "print((HYPERPARAMS / 'acer.yml').read_text())")
    out = run(dopt, "train", "--goal", "bathtub", "--steps", "400", "--card-episodes", "1", "--ready", "0")  # RGB
    assert "done: 400 steps" in " ".join(out.split())
    assert (work / "runs" / "sb3_disagree__Apartment-v0" / "bathtub" / "kickstart-0" / "README.md").exists()
    run(str(python), "-c", "import gymnasium as gym, sb3_disagree; env = gym.make('sb3_disagree/Office-v0', "
                           "goal='table', obs_width=32, obs_height=24); print(env.reset(seed=0)[0].shape)")


def test_acer_trains_and_tunes_through_rl_zoo3(tmp_path):
    """rl-zoo3's own train with the project's hyperparameter file, then a 2-trial optimisation."""
    import csv

    import pytest

    from readme import block_with

    pytest.importorskip("rl_zoo3")
    # The README's command, no --conf-file: the package's own hyperparams/acer.yml (as from a wheel).
    (command,) = block_with("python -m sb3_disagree.rl_zoo")
    common = [sys.executable, *command.split()[1:], "--seed", "0"]
    result = subprocess.run([*common, "-n", "2000", "-f", str(tmp_path / "train"), "--eval-freq", "-1"],
                            capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    (model,) = (tmp_path / "train" / "acer").glob("CartPole-v1_*/CartPole-v1.zip")
    from sb3_disagree import ACER

    loaded = ACER.load(model)
    assert loaded.num_timesteps >= 2000 and loaded.replay_ratio == 8  # acer.yml's CartPole entry
    result = subprocess.run([*common, "-n", "1000", "-f", str(tmp_path / "opt"), "-optimize", "--n-trials", "2",
                             "--n-jobs", "1", "--sampler", "random", "--pruner", "none", "--n-evaluations", "1",
                             "--eval-episodes", "2"], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    (report,) = (tmp_path / "opt" / "acer").glob("report_CartPole-v1_2-trials-*.csv")
    rows = list(csv.DictReader(report.open()))
    assert len(rows) == 2 and all(r["state"] == "COMPLETE" for r in rows)
    assert {"params_learning_rate", "params_replay_ratio", "params_trust_region"} <= set(rows[0])


def test_every_env_documents_gymnasiums_sections():
    from sb3_disagree.envs.apartment import ApartmentEnv
    from sb3_disagree.envs.scan import ScanEnv

    sections = ("Description", "Action Space", "Observation Space", "Rewards", "Starting State", "Episode End",
                "Arguments")
    for env in (ApartmentEnv, ScanEnv):
        positions = [env.__doc__.index(f"## {name}") for name in sections]
        assert positions == sorted(positions), env


def _import_graph():
    """Every module of the package (the CLI included) -> the package's modules it imports, anywhere in it."""
    import ast
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    files = {}
    for path in [*(repo / "sb3_disagree").rglob("*.py"), *(repo / "cli").rglob("*.py")]:
        rel = path.relative_to(repo).with_suffix("").parts
        name = ".".join(("sb3_disagree", "cli", *rel[1:]) if rel[0] == "cli" else rel).removesuffix(".__init__")
        files[name] = path
    graph, private = {}, []
    for name, path in files.items():
        graph[name] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sb3_disagree"):
                targets = [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
                graph[name] |= {t for t in targets if t in files and t != name}
                private += [f"{name}: {node.module}.{a.name}" for a in node.names
                            if a.name.startswith("_") and not a.name.startswith("__")]
            elif isinstance(node, ast.Import):
                graph[name] |= {a.name for a in node.names if a.name in files and a.name != name}
    return graph, private


def test_the_package_has_no_import_cycle_and_imports_no_private_name():
    graph, private = _import_graph()
    assert not private, private
    state: dict[str, int] = {}  # 1 on the path, 2 done

    def visit(module, path):
        state[module] = 1
        for other in graph[module]:
            assert state.get(other) != 1, " -> ".join([*path, module, other])
            if other not in state:
                visit(other, [*path, module])
        state[module] = 2

    for module in graph:
        if module not in state:
            visit(module, [])


def test_the_architecture_page_names_every_module():
    """docs/architecture.md's tree names every module of the package and of the command line, each in its folder."""
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    tree = (repo / "docs" / "architecture.md").read_text().split("```")[1]
    named, folders = set(), []  # folders: (indent, name) of the enclosing folders
    for line in tree.splitlines():
        if not line.strip():
            continue
        indent, entry = len(line) - len(line.lstrip()), line.split()[0]
        if not (entry.endswith("/") or entry.endswith(".py")):
            continue  # a description's continuation
        folders = [f for f in folders if f[0] < indent]
        if entry.endswith("/"):
            folders.append((indent, entry.rstrip("/")))
        else:
            named.add("/".join([f[1] for f in folders] + [entry]))
    modules = {str(p.relative_to(repo)) for root in ("sb3_disagree", "cli") for p in (repo / root).rglob("*.py")}
    assert modules <= named, sorted(modules - named)
