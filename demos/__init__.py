"""Runnable, documented demos of the transient engine (``python demos/demo_<name>.py``, serial or
under ``mpirun -n 2``); each docstring says what it shows. tests/test_demos.py runs every one."""
