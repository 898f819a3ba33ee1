"""One module per published method; each composes the shared pieces."""
