"""Sub-commands of the `antarium` command line (see `antarium.cli.COMMANDS`).

The checks here run at the start of a command, before its work, so that bad input costs nothing: each raises one
ValueError naming the option, what was wrong and what is allowed (`antarium.cli.main` prints it in one line).
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Sequence
from pathlib import Path

from antarium.core.numbers import check_number

#: the ports a TCP or UDP option may name; 0 asks the OS for a free one
PORT_RANGE = (0, 65535)


def require_seconds(args: argparse.Namespace, *names: str) -> None:
    """ValueError naming the first of the options `names` (attribute names of `args`) that is given but is not a
    finite number of seconds > 0; options left at None are not given."""
    for name in names:
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"--{name.replace('_', '-')} must be a positive number of seconds, got {value:g}")


def require_port(args: argparse.Namespace, *names: str) -> None:
    """ValueError naming the first of the options `names` (attribute names of `args`) that is given but is not a
    port number in `PORT_RANGE`."""
    for name in names:
        value = getattr(args, name)
        if value is not None:
            check_number(f"--{name.replace('_', '-')}", value, *PORT_RANGE, integer=True)


def check_output(path: str | os.PathLike, option: str, *, suffixes: Sequence[str] = (), folder: bool = False,
                 make_folders: bool = True) -> Path:
    """`path` as an absolute Path when a command can write there: a file (a folder when `folder`) that is new or
    that it may overwrite. Otherwise one ValueError naming `option` and what is allowed. Commands call it for every
    output before their work, so that a bad name throws no work away and leaves nothing half-written.

    suffixes: the endings a file name must have (any when empty), lowercase with the dot; the name must carry one,
    for writers that would append it silently. make_folders: the writer makes missing folders on the way (else
    the folder must exist). Either way the nearest existing one must be a folder this user may write in; a file
    in an existing folder is tried (opened for appending; a new one removed again)."""
    text = os.fspath(path)
    what = "folder" if folder else "file"
    if not text.strip():
        raise ValueError(f"{option} needs a {what} name, got {text!r}")
    target = Path(text).expanduser()
    if folder:
        if target.exists() and not target.is_dir():
            raise ValueError(f"{option} {text!r} is a file, not a folder; give a new or an existing folder")
        parent = target
    else:
        if suffixes and target.suffix.lower() not in suffixes:
            raise ValueError(f"{option} file must end in {' or '.join(suffixes)}, got {target.name!r}")
        if target.is_dir():
            example = target / f"out{suffixes[0]}" if suffixes else target / "out"
            raise ValueError(f"{option} {text!r} is a folder; give a file name (e.g. {str(example)!r})")
        parent = target.parent
    existing = next(p for p in (parent, *parent.parents) if p.exists() or p == p.parent)
    if not existing.is_dir():
        raise ValueError(f"{option} {text!r}: {str(existing)!r} is a file, not a folder")
    if existing != parent and not make_folders:
        raise ValueError(f"{option}: folder {str(parent)!r} does not exist")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {text!r}: no permission to write in folder {str(existing)!r}")
    if target.exists() and not os.access(target, os.W_OK):
        raise ValueError(f"{option} {text!r}: no permission to overwrite it")
    if not folder and existing == parent:  # tried: a folder may say it is writable and refuse files (/proc)
        existed = target.exists()
        try:
            with open(target, "a"):
                pass
        except OSError as exc:
            raise ValueError(f"{option} {text!r}: cannot write there ({exc.strerror}); give a file in a folder "
                             "where files can be made") from None
        if not existed:
            target.unlink()
    if folder and not target.exists():  # tried the same way: made, then removed again (with what it made)
        made = [p for p in (target, *target.parents) if not p.exists()]
        try:
            target.mkdir(parents=True)
        except OSError as exc:
            raise ValueError(f"{option} {text!r}: cannot make the folder ({exc.strerror}); give a folder where "
                             "folders can be made") from None
        for p in made:
            p.rmdir()
    return target.absolute()  # what the command reports is where it wrote, whatever folder it ran in
