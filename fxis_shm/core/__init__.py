"""The I/O-free core: nearest-time search, tuple selection, wait policy, sequences, the request
engine and clock mapping. Arrays and numbers in, decisions out; imports only ``fxis_shm.errors``."""
