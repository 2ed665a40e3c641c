"""The caller's side: ``Client`` (one service or several), same-host reads straight from the
rings, clock tracking, frames as NumPy arrays, streams and events. May import shm, formats, wire, core."""
