"""The output folder of a job: created, and a user told when it held an earlier run's results."""
from __future__ import annotations

import warnings
from pathlib import Path

from orchestrator.inputs.errors import UserInputError, UserInputWarning

MARKER = "summary.json"   # what every finished `turnout run` leaves in its folder


def prepare_out_dir(out_dir: Path, marker: str = MARKER) -> Path:
    """Create ``out_dir``; warn (:class:`UserInputWarning`) when it holds an earlier run's ``marker`` file.

    The earlier files are replaced as the new run writes them (a re-run of the same scenario is
    the usual case, so this is a warning, not an error).

    Raises
    ------
    UserInputError
        ``out_dir`` exists and is not a folder.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserInputError(f"--out {out_dir}: exists and is not a folder")
    if (out_dir / marker).is_file():
        warnings.warn(f"{out_dir}: held the results of an earlier run; they are replaced", UserInputWarning,
                      stacklevel=2)
    out_dir.mkdir(parents=True, exist_ok=True)
    return out_dir


__all__ = ["prepare_out_dir", "MARKER"]
