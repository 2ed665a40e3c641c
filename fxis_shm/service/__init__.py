"""The running service: coordinator, streams, supervisor, configuration, camera kinds and the
specs of child processes (started by module name, never imported). May import every layer below."""
