"""The ``dopt`` command line (installed as ``sb3_disagree.cli``)."""

import sys


def main() -> None:
    """The ``dopt`` command: Ctrl-C while it starts (its imports take seconds) is one line and exit code 130."""
    try:
        from sb3_disagree.cli.app import main as run
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        raise SystemExit(130) from None
    run()
