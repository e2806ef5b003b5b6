"""pythonfmu co-simulation slaves (thin: FMU variables -> ``src/`` model objects) and their build.

* :mod:`fmus.base` -- ``CosimSlave``, the base class fixing pythonfmu's weak points.
* :mod:`fmus.vehicle_fmus` -- ``Bogie`` and ``QuarterVehicle`` slaves.
* :mod:`fmus.build` -- ``build_fmu(kind, out_dir)``.

Nothing is imported here, so ``import fmus.build`` stays cheap.
"""
