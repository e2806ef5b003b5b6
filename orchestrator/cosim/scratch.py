"""Scratch folders in the temporary folder, named by their process, and the removal of a killed process's.

A process that is killed outright (``SIGKILL``: a sweep the user kills, a worker the OOM
killer takes, a CI job cancelled) runs no finalizer, so its temporary folders stayed
behind: a sweep's worker its run folder (the run's files so far), every process its
unzipped FMUs (~2 MB each, :func:`orchestrator.cosim.units._unzipped`) and a run's work
and record folders. Measured 2026-11-26: 56 run folders of killed sweep workers in this
machine's ``/tmp``, one per worker of each ``test_killing_the_sweep_leaves_no_worker_alive``.

Every scratch folder of ours is named ``turnout-<kind>-<pid>-<host>-XXXXXXXX``
(:func:`scratch_prefix`; ``<host>`` a short hash of the host name, since a temporary folder
may be shared by machines or containers whose process ids are not ours). The first scratch
folder a process makes first removes those of this host whose process no longer exists or is a
zombie (:func:`remove_orphans`, once per process). Only on POSIX, where ``os.kill(pid, 0)`` asks
whether a process exists (on Windows it would terminate it): elsewhere nothing is removed.
A process id reused by a new process keeps the dead one's folders until that one ends too.
"""
from __future__ import annotations

import hashlib
import os
import re
import shutil
import socket
import tempfile

__all__ = ["scratch_prefix", "scratch_dir", "make_scratch", "remove_orphans"]

PREFIX = "turnout-"
_NAME = re.compile(r"^turnout-[a-z]+-(\d+)-([0-9a-f]{8})-")
_swept: set = set()   # the temporary folders already swept by this process


def _host() -> str:
    """8 hex digits of the host name's hash (a scratch folder's host part)."""
    return hashlib.blake2b(socket.gethostname().encode(), digest_size=4).hexdigest()


def scratch_prefix(kind: str) -> str:
    """``turnout-<kind>-<pid>-<host>-``: the prefix of this process's scratch folders of ``kind`` (letters)."""
    if not kind.isalpha() or not kind.islower():
        raise ValueError(f"scratch folder kind {kind!r}: lower-case letters only")
    return f"{PREFIX}{kind}-{os.getpid()}-{_host()}-"


def _sweep_once(parent: str | None) -> None:
    folder = parent or tempfile.gettempdir()
    if folder not in _swept:
        _swept.add(folder)
        remove_orphans(folder)


def make_scratch(kind: str, parent: str | None = None) -> str:
    """A new scratch folder (``tempfile.mkdtemp``) of ``kind`` in ``parent`` (default: the temporary folder);
    the caller removes it. Sweeps the orphans of ``parent`` first (once per process)."""
    _sweep_once(parent)
    return tempfile.mkdtemp(prefix=scratch_prefix(kind), dir=parent)


def scratch_dir(kind: str) -> tempfile.TemporaryDirectory:
    """A new scratch folder of ``kind`` as a ``tempfile.TemporaryDirectory`` (removed by its cleanup)."""
    _sweep_once(None)
    return tempfile.TemporaryDirectory(prefix=scratch_prefix(kind))


def _exists(pid: int) -> bool:
    """The process runs: ``kill(pid, 0)`` finds it and, where ``/proc`` tells, it is not a zombie (a killed
    process whose parent died too waits there until an init that reaps it does: measured in a container)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:   # EPERM: it exists (another user's)
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            state = f.read().rpartition(b")")[2].split()[0]   # the field after "(comm)"
    except (OSError, IndexError):
        return True
    return state != b"Z"


def remove_orphans(parent: str | None = None) -> list[str]:
    """Remove the scratch folders in ``parent`` (default: the temporary folder) of this host's processes
    that no longer exist; returns their paths. Nothing on a system without POSIX ``kill``."""
    if os.name != "posix":
        return []
    host, me, removed = _host(), os.getpid(), []
    try:
        entries = list(os.scandir(parent or tempfile.gettempdir()))
    except OSError:
        return []
    for entry in entries:
        m = _NAME.match(entry.name)
        if m is None or m.group(2) != host or int(m.group(1)) == me or _exists(int(m.group(1))):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
            if not os.path.exists(entry.path):
                removed.append(entry.path)
    return removed
