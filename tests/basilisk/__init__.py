"""Basilisk's reference values for the space environment's models, committed as fixtures.

Each model has a script here, ``<model>.py``, that builds the shared cases in Basilisk and prints
their values as JSON; that output is committed beside it as ``<model>.json``, and the tests compare
Zenorbit's models against it (``tests/unit/test_space_*.py``; the rigid spacecraft's,
``tests/unit/test_dynamics_rigid.py``). Remake them with

    python -m tests.basilisk [MODEL ...]      # all models without arguments

which runs each script in Basilisk's own virtual environment (``bsk`` from PyPI, made on first use
in ``~/.cache/zenorbit/basilisk``, or ``ZENORBIT_BASILISK_VENV``): Basilisk never shares a process
or an environment with the project. A script reads only its own cases (the ``CASES`` it declares,
repeated in the JSON so that a test uses exactly the inputs Basilisk had) and needs nothing but
Basilisk and numpy.
"""
