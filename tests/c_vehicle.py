"""Build the third-party C vehicle FMU of ``tests/fixtures/c_vehicle`` (a test fixture).

:func:`build_c_vehicle_fmu` compiles ``c_quarter_vehicle.c`` with the system C compiler
against the FMI 2.0 headers shipped with FMPy (``fmpy/c-code``) and zips it with its
``modelDescription.xml`` into an FMI 2.0 co-simulation FMU.  The FMU implements the
rigid quarter vehicle of :mod:`vehicle.quarter` in other conventions than ours (wheel
positions, velocities and contact forces positive DOWNWARD; see the C source and
``README.md`` next to it), so that the scenario ``ports`` mapping (DESIGN.md 4.4) can be
tested with an FMU not built by this package.

Everything is written below ``out_dir``; nothing is cached elsewhere.
"""
from __future__ import annotations

import hashlib
import platform
import subprocess
import sys
import uuid
import zipfile
from pathlib import Path

from fmus.build import find_c_compiler
from fmus.build import fmi2_headers_dir as _package_headers_dir

FIXTURE_DIR = Path(__file__).resolve().parent / "fixtures" / "c_vehicle"
C_SOURCE = FIXTURE_DIR / "c_quarter_vehicle.c"
XML_TEMPLATE = FIXTURE_DIR / "modelDescription.xml.in"
MODEL_IDENTIFIER = "c_quarter_vehicle"

# FMI 2.0 platform folder and shared-library suffix per (system, 64-bit machine)
_PLATFORMS = {"Linux": ("linux64", ".so"), "Darwin": ("darwin64", ".dylib")}


def fmi2_headers_dir() -> Path:
    """Folder with ``fmi2Functions.h`` & co. inside the installed FMPy package (:func:`fmus.build.fmi2_headers_dir`)."""
    path = _package_headers_dir()
    if path is None:
        raise FileNotFoundError("FMI 2.0 headers not found in the installed fmpy package")
    return path


def fmu_platform() -> tuple[str, str]:
    """(binaries sub-folder, shared-library suffix) for this machine.

    Raises RuntimeError where the FMU cannot be built (32-bit, Windows, ...).
    """
    system = platform.system()
    if system not in _PLATFORMS or sys.maxsize <= 2**32:
        raise RuntimeError(f"building the C vehicle FMU is not supported on {system} ({platform.machine()})")
    return _PLATFORMS[system]


def fmu_guid() -> str:
    """GUID of the FMU: derived from the C source and the XML template, so it changes with them."""
    digest = hashlib.sha256(C_SOURCE.read_bytes() + b"\0" + XML_TEMPLATE.read_bytes()).hexdigest()
    return "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"turnout-cosim/c_quarter_vehicle/{digest}")) + "}"


def build_c_vehicle_fmu(out_dir: Path) -> Path:
    """Compile the C vehicle and package it as ``out_dir/c_quarter_vehicle.fmu``.

    Parameters
    ----------
    out_dir : Path
        Output folder (created if missing).  Receives the FMU and a ``c_quarter_vehicle_build``
        folder with the compiled library; an existing FMU of the same name is replaced.

    Returns
    -------
    Path
        The ``.fmu`` file.

    Raises
    ------
    RuntimeError
        No C compiler, unsupported platform, or the compilation failed (the compiler's
        output is in the message).
    """
    out_dir = Path(out_dir)
    compiler = find_c_compiler()
    if compiler is None:
        raise RuntimeError("no C compiler found (looked for cc and gcc on PATH)")
    plat, suffix = fmu_platform()
    guid = fmu_guid()

    build = out_dir / f"{MODEL_IDENTIFIER}_build"
    build.mkdir(parents=True, exist_ok=True)
    library = build / f"{MODEL_IDENTIFIER}{suffix}"
    cmd = [compiler, "-shared", "-fPIC", "-O2", "-std=c99", "-Wall", "-Wextra",
           "-fvisibility=hidden",          # export the FMI functions only (FMI2_Export)
           f"-I{fmi2_headers_dir()}", f'-DFMU_GUID="{guid}"',
           "-o", str(library), str(C_SOURCE), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling {C_SOURCE.name} failed ({' '.join(cmd)}):\n{proc.stderr}")

    xml = XML_TEMPLATE.read_text(encoding="utf-8").replace("@FMU_GUID@", guid)
    fmu = out_dir / f"{MODEL_IDENTIFIER}.fmu"
    tmp = fmu.with_suffix(".fmu.part")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.write(library, f"binaries/{plat}/{MODEL_IDENTIFIER}{suffix}")
    tmp.replace(fmu)
    return fmu
