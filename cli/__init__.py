"""The ``dopt`` command line (installed as ``sb3_disagree.cli``)."""
