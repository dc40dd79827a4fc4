"""Rendering without a display, arranged when a renderer is first built (never on importing the package)."""

import os


def arrange_headless() -> None:
    """
    Before MiniWorld (pyglet) or an EGL context is loaded: pyglet's headless (EGL) mode where there is no
    display, and llvmpipe on one thread per context (60x80 frames render faster on one thread than split)
    unless the caller chose otherwise.
    """
    os.environ.setdefault("LP_NUM_THREADS", "0")
    if os.environ.get("DISPLAY") or "PYGLET_HEADLESS" in os.environ:
        return
    import pyglet

    pyglet.options["headless"] = True
