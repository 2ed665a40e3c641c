"""What crosses a socket: the request protocol's codec, image encodings (and their cache),
CurveZMQ keys and the default endpoints. May import core."""
