"""The figure process of `turnout run` (orchestrator.results.figure_writer): figures drawn by a second
process land where the in-process path puts them; a figure that fails is reported, never raised, so the
results written before it stay."""
from types import SimpleNamespace

import numpy as np
import pytest

from orchestrator.results import run_figures
from orchestrator.results.figure_writer import FigureWriter


def _signals(n=200, m=2):
    t = np.linspace(0.0, 0.02, n)
    z = 1e-4 * np.sin(200 * t)[:, None] * np.ones(m)
    return SimpleNamespace(t=t, x=np.outer(t, np.ones(m)), z=z, Fz=1e5 + 1e4 * z, rail_z=0.5 * z,
                           parts=np.zeros((n, m, 2)))


@pytest.fixture(scope="module")
def layout():
    from track.layout import build_layout
    from track.params import LayoutParams
    return build_layout(LayoutParams())


@pytest.mark.parametrize("background", [True, False])
def test_figures_are_written_and_failures_reported(tmp_path, layout, background):
    """Three figures land in the folder; a figure whose folder does not exist comes back as one line
    naming it (FileNotFoundError), and close() returns normally."""
    w = FigureWriter(background=background)
    assert w.background is background
    w.submit("layout", run_figures.layout, tmp_path, layout)
    w.submit("contact_forces", run_figures.contact_forces, tmp_path, "test", _signals())
    w.submit("broken", run_figures.contact_forces, tmp_path / "missing" / "folder", "test", _signals())
    w.submit("displacements", run_figures.displacements, tmp_path, "test", _signals())
    failed = w.close()
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["contact_forces.png", "displacements.png", "layout.png"]
    assert len(failed) == 1 and failed[0].startswith("broken: ") and "No such file" in failed[0], failed
    # the figure process's own peak memory is reported (it is not the main process's); 20 MB is a floor
    # no Python process that has imported numpy and matplotlib stays under (measured ~150 MB), so a
    # value read from the wrong place (kB taken as MB would be ~1e5, bytes ~1e8) or a zero fails
    assert (w.peak_rss_mb is not None and 20.0 < w.peak_rss_mb < 5000.0) if background else w.peak_rss_mb is None


_PROBE = """
import atexit, sys
atexit.register(open, {handler!r}, "w")            # an exit handler registered after the warm-up's
class _Probe:
    def __del__(self):                              # runs when the interpreter tears its modules down
        open({teardown!r}, "w").close()
sys.modules["__main__"].probe = _Probe()
"""


def test_the_figure_process_ends_after_its_exit_handlers_without_teardown(tmp_path):
    """The figure process ends at once after its exit handlers (figure_writer._end_at_once): an
    ``atexit`` handler registered in it runs; an object that only the interpreter's teardown would
    free is never freed. close() returns once the process has ended (it joins it), so both files are
    settled when it returns."""
    w = FigureWriter(background=True)
    code = _PROBE.format(handler=str(tmp_path / "handler"), teardown=str(tmp_path / "teardown"))
    w.submit("probe", exec, code)
    assert w.close() == []
    assert (tmp_path / "handler").exists()
    assert not (tmp_path / "teardown").exists()
