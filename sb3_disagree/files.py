"""Writing files so that a reader never sees half of one: a temporary file beside it, then a rename."""

import os
import tempfile
from pathlib import Path
from typing import Union

MAX_NAME = 100  # bytes of a word that names a folder (file systems take 255, and runs nest a few such names)


def write_atomic(path: Union[str, Path], data: Union[bytes, str], mode: int = 0o644) -> None:
    """
    Replace ``path`` with ``data`` in one rename, so that an interrupted write leaves the old file or none.

    :param path: The file to write (its folder is created)
    :param data: Its contents; text is written as UTF-8
    :param mode: Permissions of the new file (``mkstemp`` would leave it readable by its owner only)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode() if isinstance(data, str) else data)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def safe_name(word: str, what: str) -> str:
    """
    ``word`` when it can name a folder inside another (no separator, not empty, not ``.`` or ``..``), so that
    a path built from a user's word stays under its root; a ValueError naming ``what`` otherwise.

    :param word: The user's word (a goal, a cell name, a label)
    :param what: What it is, for the message (e.g. "--goal")
    """
    if not isinstance(word, str) or not word.strip() or word.strip(".") == "" or any(c in word for c in "/\\\0"):
        raise ValueError(f"{what} {word!r} cannot name a folder: use a word without '/', '\\\\' or leading dots only")
    if len(word.encode()) > MAX_NAME:
        raise ValueError(f"{what} is {len(word.encode())} bytes long: a folder's name takes at most {MAX_NAME}")
    return word
