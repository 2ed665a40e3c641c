"""Live views for people: the web dashboard and the Foxglove server, each a supervised child
that reads through the client API. May import service and below; not record."""
