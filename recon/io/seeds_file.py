"""Read and write the clinician's marks (seeds.json, format in :mod:`recon.seeds`)."""

from __future__ import annotations

import json
import os
from pathlib import Path

from recon.io.files import atomic_write_bytes, read_json
from recon.seeds import Seeds, SeedsError, seeds_from_dict

__all__ = ["load_seeds", "save_seeds"]


def load_seeds(path: str | os.PathLike) -> Seeds:
    """Read and validate a seeds.json file. Raises SeedsError naming the file."""
    return seeds_from_dict(read_json(path, SeedsError, "seeds file"), source=str(Path(path)))


def save_seeds(seeds: Seeds, path: str | os.PathLike) -> None:
    """Write seeds atomically (temporary file in the same folder, then rename).

    Raises :class:`~recon.errors.OutputError` naming the file when it cannot be written.
    """
    atomic_write_bytes(Path(path), (json.dumps(seeds.to_dict(), indent=2) + "\n").encode())
