"""The viewer's autosave of the marks: one versioned file per pair, replaced atomically;
a damaged, older or foreign autosave is kept aside under a new name, never overwritten."""

from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

from recon.io.files import atomic_write_bytes, read_json
from viewer_app.saved_names import read_names

if TYPE_CHECKING:
    from viewer_app.state import MarkState

__all__ = ["AUTOSAVE_VERSION", "Autosave", "default_autosave_path", "pair_key", "read_names"]


def pair_key(path_a: str | os.PathLike, path_b: str | os.PathLike) -> str:
    """Stable short key of an image pair (absolute paths)."""
    text = f"{Path(path_a).resolve()}\n{Path(path_b).resolve()}"
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def default_autosave_path(path_a: str | os.PathLike, path_b: str | os.PathLike) -> Path:
    """~/.cache/coronary3d/autosave/<pair key>.json (XDG_CACHE_HOME respected)."""
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "coronary3d" / "autosave" / f"{pair_key(path_a, path_b)}.json"


AUTOSAVE_VERSION = 2  # 1: before the key existed (same layout, no feature names)


class Autosave:
    """Autosave file of the marks of one pair.

    The file is a seeds.json document (readable by ``coronary3d reconstruct``)
    with extra keys: ``"autosave_version"`` (:data:`AUTOSAVE_VERSION`),
    ``"saved_at"`` (UTC, ISO 8601), ``"pair"`` (the absolute paths of A and
    B) and ``"viewer"`` (the full mark state). It is replaced atomically on
    every change. An autosave that cannot be restored whole (damaged, older
    than the seeds file given, for another pair, from a newer version) is
    never overwritten: :meth:`load_into` renames it aside first and
    :attr:`notice` says so, in one line, for the page.
    """

    def __init__(self, path: str | os.PathLike, path_a: str, path_b: str) -> None:
        self.path = Path(path)
        self.pair = [str(Path(path_a).resolve()), str(Path(path_b).resolve())]
        self.notice: str | None = None  # what load_into did that the user must know
        self.kept_aside: Path | None = None

    def save(self, state: MarkState) -> None:
        """Write the marks (atomically). Raises OutputError naming the file."""
        doc = state.to_dict()
        doc["autosave_version"] = AUTOSAVE_VERSION
        doc["saved_at"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        doc["pair"] = self.pair
        atomic_write_bytes(self.path, (json.dumps(doc, indent=2) + "\n").encode())

    def keep_aside(self, reason: str) -> Path | None:
        """Rename the autosave to ``<name>.<reason>-<UTC time>.json`` beside it; the new name
        (None when it could not be renamed: then the autosave is not written either)."""
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        for k in range(100):
            extra = f"-{k}" if k else ""
            target = self.path.with_name(f"{self.path.stem}.{reason}-{stamp}{extra}.json")
            if target.exists():
                continue
            try:
                os.rename(self.path, target)  # same folder: atomic, the content untouched
            except OSError:
                return None
            self.kept_aside = target
            return target
        return None

    def _aside(self, reason: str, why: str) -> bool:
        target = self.keep_aside(reason)
        if target is None:
            self.path = self.path.with_name(f"{self.path.stem}.new.json")
            self.notice = (f"{why}; it could not be renamed aside: marks are autosaved to "
                           f"{self.path}")
        else:
            self.notice = f"{why}; it was kept as {target}"
        return False

    def load_into(self, state: MarkState, seeds_path: str | os.PathLike | None) -> bool:
        """Restore the autosave into ``state`` if it is for this pair and newer than the seeds.

        Returns True if (some of) its marks were restored. Whatever cannot be
        restored whole is renamed aside first, with a line in :attr:`notice`.
        """
        from recon.errors import CoronaryError

        self.notice = None
        try:
            if not self.path.exists() and not self.path.is_symlink():
                return False
            if seeds_path is not None and Path(seeds_path).is_file():
                if self.path.stat().st_mtime <= Path(seeds_path).stat().st_mtime:
                    return self._aside("older", f"the autosave {self.path} is older than the "
                                       f"seeds file {Path(seeds_path).name}, whose marks are shown")
        except OSError as exc:
            return self._aside("unreadable", f"the autosave {self.path} cannot be read "
                               f"({exc.strerror})")
        try:
            doc = read_json(self.path, CoronaryError, "autosave")
        except CoronaryError as exc:
            return self._aside("damaged", f"the autosave could not be read ({exc})")
        if not isinstance(doc, dict):
            return self._aside("damaged", f"the autosave {self.path} is not a marks document")
        if doc.get("pair") != self.pair:
            return self._aside("other-pair", f"the autosave {self.path} is for another pair")
        version = doc.get("autosave_version", 1)
        if not isinstance(version, int) or version > AUTOSAVE_VERSION:
            return self._aside("newer", f"the autosave {self.path} was written by a newer "
                               f"coronary3d (version {version!r})")
        try:
            skipped = state.restore_dict(doc, source=str(self.path))
        except (ValueError, TypeError, RecursionError) as exc:
            return self._aside("damaged", f"the autosave could not be restored "
                               f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})")
        if skipped:
            target = self.keep_aside("damaged")
            kept = f"the original was kept as {target}" if target else \
                "the original could not be renamed aside"
            self.notice = (f"{skipped} damaged mark(s) of the autosave were skipped and the "
                           f"others restored; {kept}")
            if target is None:
                self.path = self.path.with_name(f"{self.path.stem}.new.json")
        return True
