"""Scenarios and files that travel by value, so that a worker on another machine can run them.

A task of a sweep, a diagnosis or a calibration carries no path of the client: the
worker's working folder and file system may be another machine's. It carries a
:class:`PortableScenario` instead: the validated raw scenario plus the bytes of every
file it names (each value at a key the scenario schema declares a file path: the sensor
layout, a third-party vehicle FMU, ...: found by walking the schema, so a file key added
to the schema travels too). Measured data travel as a :class:`FileValue`.

On the worker, :meth:`FileValue.local_path` writes a file once into the worker's own
temporary folder, ``<tempfile.gettempdir()>/turnout-files/<digest>/<name>``: named by
the content's digest, so it is never stale, and shared by the worker processes of one
machine (written to a temporary name and renamed, so a reader never sees half a file).
:meth:`PortableScenario.scenario` validates the raw scenario again with its file keys
pointing there.
"""
from __future__ import annotations

import copy
import functools
import hashlib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Mapping

__all__ = ["FileValue", "PortableScenario", "FILES_DIR", "file_keys"]

FILES_DIR = "turnout-files"  # <worker temp folder>/turnout-files/<digest>/<name>
DIGEST_CHARS = 24  # hex digits of the SHA-256 that name a shipped file's folder (96 bits)


@dataclass(frozen=True)
class FileValue:
    """The content of one file, to be recreated where a worker can read it.

    Attributes
    ----------
    name : str
        The file's base name (its suffix tells readers the format: ``.csv``, ``.fmu``, ...).
    data : bytes
        Its content.
    digest : str
        SHA-256 of ``data`` (hex, :data:`DIGEST_CHARS` digits): names its folder on the worker.
    """

    name: str
    data: bytes
    digest: str

    @classmethod
    def read(cls, path: str | os.PathLike) -> FileValue:
        """The file at ``path`` (read once per content: cached by path, size and modification time)."""
        p = Path(path).resolve()
        st = p.stat()
        return _read_file(str(p), st.st_size, st.st_mtime_ns)

    def local_path(self, root: str | os.PathLike | None = None) -> Path:
        """The file recreated under ``root`` (default: this process's temporary folder); written once.

        Returns
        -------
        Path
            ``root/turnout-files/<digest>/<name>``.
        """
        folder = Path(tempfile.gettempdir() if root is None else root) / FILES_DIR / self.digest
        path = folder / self.name
        if not path.is_file():
            folder.mkdir(parents=True, exist_ok=True)
            tmp = folder / f".{self.name}.{os.getpid()}.tmp"
            tmp.write_bytes(self.data)
            os.replace(tmp, path)  # atomic: another process that wrote it first wrote the same bytes
        return path


@functools.lru_cache(maxsize=64)
def _read_file(path: str, size: int, mtime_ns: int) -> FileValue:
    """:meth:`FileValue.read` of one version of a file (``size`` and ``mtime_ns`` key the cache)."""
    data = Path(path).read_bytes()
    return FileValue(Path(path).name, data, hashlib.sha256(data).hexdigest()[:DIGEST_CHARS])


def file_keys(raw: Mapping) -> Iterator[tuple[tuple, str]]:
    """The file paths a raw scenario names: ``(key tokens, path)`` for every value at a file key of the schema.

    A built-in keyword where a file may be given (``vehicle.fmu: bogie``) is not a file.
    """
    from orchestrator.inputs.schema import SCHEMA
    from orchestrator.inputs.schema_nodes import FilePath, Invalid, Nullable, node_at

    def walk(value: Any, toks: tuple) -> Iterator[tuple[tuple, str]]:
        if isinstance(value, Mapping):
            for k, v in value.items():
                yield from walk(v, toks + (k,))
        elif isinstance(value, (list, tuple)):
            for i, v in enumerate(value):
                yield from walk(v, toks + (i,))
        elif isinstance(value, str):
            try:
                node = node_at(SCHEMA, toks)
            except Invalid:  # below a free-form mapping: not a schema key
                return
            node = node.inner if isinstance(node, Nullable) else node
            if isinstance(node, FilePath) and value not in node.keywords:
                yield toks, value

    return walk(raw, ())


@dataclass(frozen=True)
class PortableScenario:
    """A validated raw scenario with the files it names, by value (module docstring).

    Attributes
    ----------
    raw : dict
        The validated raw scenario (``Scenario.raw``: file paths absolute on the client).
    files : dict
        Key path text (``sensors``, ``vehicle.fmu``) -> :class:`FileValue` of the file named there.
    source : str
        Where the scenario came from on the client (named in error messages).
    """

    raw: dict
    files: dict
    source: str = "<variant>"

    @classmethod
    def of(cls, raw: Mapping, source: str = "<variant>",
           base_dir: str | os.PathLike | None = None) -> PortableScenario:
        """The raw scenario ``raw`` and its files, read now (relative paths from ``base_dir``, default cwd).

        Raises
        ------
        OSError
            A file it names cannot be read (the scenario was validated, so it existed then).
        """
        from orchestrator.inputs import keypath

        base = Path.cwd() if base_dir is None else Path(base_dir)
        files = {keypath.join(toks): FileValue.read(base / os.path.expanduser(p)) for toks, p in file_keys(raw)}
        return cls(copy.deepcopy(dict(raw)), files, source)

    def scenario(self, root: str | os.PathLike | None = None):
        """The :class:`~orchestrator.inputs.scenario.Scenario`, its files recreated under ``root`` (a worker's
        temporary folder by default: :meth:`FileValue.local_path`)."""
        from orchestrator.inputs import keypath
        from orchestrator.inputs.scenario import scenario_from_dict

        raw = copy.deepcopy(self.raw)
        for key, value in self.files.items():
            keypath.set(raw, key, str(value.local_path(root)))
        folder = Path(tempfile.gettempdir() if root is None else root)
        return scenario_from_dict(raw, source=self.source, base_dir=folder)
