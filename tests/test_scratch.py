"""Scratch folders named by their process (orchestrator.cosim.scratch): a killed process's are removed."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from orchestrator.cosim import scratch


def _dead_pid() -> int:
    """The id of a process that has ended (a child that printed its pid and exited)."""
    out = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                         check=True)
    return int(out.stdout)


@pytest.mark.skipif(os.name != "posix", reason="orphans are found with POSIX kill(pid, 0) only")
def test_only_the_folders_of_this_hosts_ended_processes_are_removed(tmp_path):
    host = scratch._host()
    dead = _dead_pid()
    folders = {
        "dead, this host": tmp_path / f"turnout-run-{dead}-{host}-abc",
        "dead, fmu kind": tmp_path / f"turnout-fmu-{dead}-{host}-def",
        "dead, another host": tmp_path / f"turnout-run-{dead}-{'0' * 8 if host != '0' * 8 else '1' * 8}-ghi",
        "this process": tmp_path / f"turnout-run-{os.getpid()}-{host}-jkl",
        "a live process": tmp_path / f"turnout-job-{os.getppid()}-{host}-mno",
        "not ours": tmp_path / f"other-run-{dead}-{host}-pqr",
    }
    for f in folders.values():
        (f / "sub").mkdir(parents=True)
        (f / "sub" / "file.bin").write_bytes(b"x" * 10)
    (tmp_path / f"turnout-run-{dead}-{host}-file").write_text("a file, not a folder")
    removed = scratch.remove_orphans(str(tmp_path))
    assert sorted(removed) == sorted(str(folders[k]) for k in ("dead, this host", "dead, fmu kind"))
    assert {k for k, f in folders.items() if f.exists()} == {"dead, another host", "this process",
                                                             "a live process", "not ours"}
    assert (tmp_path / f"turnout-run-{dead}-{host}-file").exists()


def test_a_scratch_folder_is_named_by_its_process_and_sweeps_its_parent_first(tmp_path):
    dead = _dead_pid()
    orphan = tmp_path / f"turnout-record-{dead}-{scratch._host()}-xyz"
    orphan.mkdir()
    made = scratch.make_scratch("fmu", str(tmp_path))
    try:
        assert os.path.basename(made).startswith(f"turnout-fmu-{os.getpid()}-{scratch._host()}-")
        assert orphan.exists() == (os.name != "posix")
    finally:
        os.rmdir(made)
    with pytest.raises(ValueError, match="lower-case letters"):
        scratch.scratch_prefix("run-1")
