"""The shape of the code is a contract (DESIGN.md §2): imports run one way and never in a circle.

The contracts live in ``pyproject.toml`` (``[tool.importlinter]``) and are checked by
import-linter's ``lint-imports``:

- ``orchestrator``: cli -> studies -> inverse -> sweeps -> results -> cosim -> inputs;
- ``track`` and ``vehicle`` never import ``orchestrator`` or ``fmus``; ``fmus`` never imports ``orchestrator``;
- no two siblings of any package import each other, directly or round a loop.

A contract that cannot fail proves nothing, so the second test copies the tree, adds one
upward import and one circle, and requires ``lint-imports`` to report both.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT = shutil.which("lint-imports", path=str(Path(sys.executable).parent)) or shutil.which("lint-imports")


def _lint(tree: Path) -> subprocess.CompletedProcess:
    """``lint-imports`` on the packages of ``tree`` (its pyproject.toml), those shadowing any installed copy."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree / "src"), str(tree)]))
    return subprocess.run([LINT, "--config", str(tree / "pyproject.toml"), "--no-cache"], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=300)


pytestmark = pytest.mark.skipif(LINT is None, reason="import-linter is not installed (extra 'test')")


def test_the_layering_contracts_hold():
    run = _lint(ROOT)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "4 kept, 0 broken" in run.stdout, run.stdout


def test_an_upward_import_and_a_circle_break_the_contracts(tmp_path):
    for name in ("orchestrator", "src", "fmus"):
        shutil.copytree(ROOT / name, tmp_path / name, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    # an input module that reaches up into the inverse problem ...
    errors = tmp_path / "orchestrator" / "inputs" / "errors.py"
    errors.write_text(errors.read_text() + "\n\ndef _late():\n    from orchestrator.inverse import causes  # noqa\n")
    # ... and a model module that imports its importer (track.frf is imported by nothing in track.model)
    model = tmp_path / "src" / "track" / "model.py"
    model.write_text(model.read_text() + "\n\ndef _late():\n    from track import frf  # noqa\n")
    frf = tmp_path / "src" / "track" / "frf.py"
    assert "from .model import" in frf.read_text() or "from track.model import" in frf.read_text()
    run = _lint(tmp_path)
    assert run.returncode != 0
    assert "orchestrator.inputs is not allowed to import orchestrator.inverse" in run.stdout, run.stdout
    assert "No cycles are allowed in track" in run.stdout, run.stdout
