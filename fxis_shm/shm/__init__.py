"""Shared memory: the per-camera rings and their memory ordering, object names, buffer pools,
copies out of the rings and the coordinator's camera handles. May import core and wire."""
