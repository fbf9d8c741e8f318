"""A pickle that runs code when loaded: what a store must never unpickle."""

from pathlib import Path


class Planted:
    """Unpickling this runs code: it writes ``marker``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (Path.write_text, (self.marker, "code ran"))
