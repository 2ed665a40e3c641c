"""Process entry points (camera worker, coordinator) and camera backends.

Installed as ``fxis_shm.workers``.
"""
