"""Output files: checked writable before the work, written atomically, never half-written.

Every file the project writes for a user (ride logs and sidecars, JSON reports,
figures, policies) goes through this module:

* :func:`check_writable` before the work starts: the directory exists and takes
  a new file (a probe file is created and removed, which catches a read-only
  or full file system, a name too long for it and a missing permission even
  for root), the target is not a directory or a device (``/dev/full``), and an
  existing file is replaced only when asked to;
* :func:`atomic_write_text` and :func:`atomic_path` after the work: the content
  goes to a temporary file in the same directory, which replaces the target by
  ``os.replace`` only once it is complete; on any error the temporary file is
  removed and the old target is untouched.

Errors are :class:`OutputError` (a ``ValueError``) naming the option or the
path and what is wrong.

>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> check_writable(d / "report.json", "--json")
>>> atomic_write_text(d / "report.json", "{}\\n")
>>> (d / "report.json").read_text()
'{}\\n'
>>> check_writable(d / "report.json", "--json")  # doctest: +ELLIPSIS
Traceback (most recent call last):
ptw_env.outputs.OutputError: --json: .../report.json exists; pass --overwrite to replace it
>>> check_writable("/dev/full", "--json", overwrite=True)
Traceback (most recent call last):
ptw_env.outputs.OutputError: --json: /dev/full is not a regular file; outputs are written as new regular files
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
import tempfile
from pathlib import Path
from typing import Iterator


class OutputError(ValueError):
    """An output path that cannot take the result (the message names the option and the path)."""


def _describe(exc: OSError) -> str:
    return os.strerror(exc.errno) if exc.errno else str(exc)


def check_writable(path: str | os.PathLike, option: str = "output", overwrite: bool = False) -> None:
    """Refuse, before any work, an output that cannot be written or must not be replaced.

    Parameters
    ----------
    path : path-like
        The file to be written.
    option : str
        What names it in a message (``--json``, ``--plot``...).
    overwrite : bool
        Whether an existing regular file may be replaced.

    Raises
    ------
    OutputError
        The directory is missing or not writable, the path is too long, the
        target is a directory or a device, or it exists and ``overwrite`` is False.
    """
    p = Path(path)
    where = f"{option}: {p}"
    try:
        st = p.stat()
    except FileNotFoundError:
        st = None
    except OSError as exc:
        if exc.errno == errno.ENOTDIR:
            raise OutputError(f"{where}: a parent of it is not a directory") from None
        raise OutputError(f"{where}: {_describe(exc)}") from None
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{where} is a directory; give a file name")
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{where} is not a regular file; outputs are written as new regular files")
        if not overwrite:
            raise OutputError(f"{where} exists; pass --overwrite to replace it")
    parent = p.parent
    if not parent.is_dir():
        raise OutputError(f"{where}: directory {parent} does not exist")
    try:  # the temporary name atomic writes will use: same directory, longer name
        fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{p.name}.", suffix=".tmp")
    except OSError as exc:
        raise OutputError(f"{where}: cannot create a file in {parent} ({_describe(exc)})") from None
    os.close(fd)
    os.unlink(probe)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix) that replaces ``path`` when the block ends cleanly.

    >>> import tempfile, pathlib
    >>> target = pathlib.Path(tempfile.mkdtemp()) / "fig.txt"
    >>> with atomic_path(target) as tmp:
    ...     _ = tmp.write_text("done")
    >>> target.read_text()
    'done'
    """
    p = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.stem}.", suffix=p.suffix or ".tmp")
    except OSError as exc:
        raise OutputError(f"{p}: cannot create a file in {p.parent} ({_describe(exc)})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, p)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` atomically (module docstring)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
