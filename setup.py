"""Builds the one compiled part, the ring's memory-ordering helper (fxis_shm/shm/_ordered.c).
Everything else is in pyproject.toml. The helper is optional: without a C compiler the
install goes on, and the rings then work on x86-64 only (fxis_shm/shm/ordering.py)."""

from setuptools import Extension, setup

setup(ext_modules=[Extension("fxis_shm.shm._ordered", ["fxis_shm/shm/_ordered.c"], optional=True)])
