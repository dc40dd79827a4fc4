"""The `dopt` command line."""

from typer.testing import CliRunner

from sb3_disagree.cli.app import app
from sb3_disagree.version import __version__

runner = CliRunner()


def test_version():
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0 and __version__ in result.output


def test_help_lists_the_app():
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0 and "Disagreement Options" in result.output


def test_cli_is_not_a_top_level_module():
    import importlib.util

    spec = importlib.util.find_spec("sb3_disagree.cli")
    assert spec is not None and spec.origin.replace("\\", "/").endswith("cli/__init__.py")
