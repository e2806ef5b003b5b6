"""pythonfmu co-simulation slaves (thin: FMU variables -> ``src/`` model objects) and their build.

* :mod:`fmus.base` -- ``CosimSlave``, the base class fixing pythonfmu's weak points.
* :mod:`fmus.vehicle_fmus` -- ``Bogie`` and ``QuarterVehicle`` slaves.
* :mod:`fmus.build` -- ``build_fmu(kind, out_dir)``.
* ``fmus/shim/fmi2_python_shim.c`` -- the FMUs' Linux binary: finds and starts Python, forwards
  to pythonfmu's wrapper (compiled by :mod:`fmus.build`).

Nothing is imported here, so ``import fmus.build`` stays cheap.
"""
