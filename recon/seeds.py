"""The clinician's marks (seeds.json): the dataclasses and their validation.

Format (version 2; docs/seeds-format.md), pixel coordinates (col, row)
0-based as in the C-arm convention::

    {"version": 2,
     "segments": [{"name": "LAD", "a": [[c, r], ...], "b": [[c, r], ...]},
                  {"name": "D1", "parent": "LAD", "bifurcation": "LAD/D1",
                   "a": [[c, r], ...], "b": [[c, r], ...]}],
     "features": [{"name": "LAD/D1", "a": [c, r], "b": [c, r]}]}

In each segment the first point is proximal, the last distal, the points
between are waypoints; only the ends correspond between views. A branch
names its ``parent`` (an earlier segment) and its ``bifurcation`` (a
feature: the point where it leaves the parent, clicked in both views).
Version 1 is the same document without ``parent`` and ``bifurcation``; it
is read as a tree of unconnected segments, and a tree-free ``Seeds`` is
written as version 1. Reading and writing the file is
:mod:`recon.io.seeds_file`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from recon.errors import CoronaryError

__all__ = [
    "Segment",
    "Feature",
    "Seeds",
    "SeedsError",
    "seeds_from_dict",
    "SEEDS_VERSION",
    "MAX_NAME_CHARS",
]

#: The version this program writes for a tree (and the newest it reads).
SEEDS_VERSION = 2


class SeedsError(CoronaryError):
    """A seeds file or object that cannot be used; the message names what is wrong."""


@dataclass(frozen=True)
class Segment:
    """One vessel segment: clicks (K, 2) in view A and (L, 2) in view B, proximal first.

    ``parent`` is the name of the segment a branch leaves and
    ``bifurcation`` the name of the feature where it leaves it (both None
    for a root segment).
    """

    name: str
    a_px: tuple[tuple[float, float], ...]
    b_px: tuple[tuple[float, float], ...]
    # repr=False: a root segment's repr is what it was before the tree (the
    # phantom's regression hashes include the seeds' repr)
    parent: str | None = field(default=None, repr=False)
    bifurcation: str | None = field(default=None, repr=False)

    @property
    def is_branch(self) -> bool:
        return self.parent is not None

    @property
    def a(self) -> NDArray[np.float64]:
        return np.asarray(self.a_px, dtype=float).reshape(-1, 2)

    @property
    def b(self) -> NDArray[np.float64]:
        return np.asarray(self.b_px, dtype=float).reshape(-1, 2)


@dataclass(frozen=True)
class Feature:
    """A landmark seen in both views: (col, row) in A and in B."""

    name: str
    a_px: tuple[float, float]
    b_px: tuple[float, float]


@dataclass(frozen=True)
class Seeds:
    segments: tuple[Segment, ...] = field(default_factory=tuple)
    features: tuple[Feature, ...] = field(default_factory=tuple)

    @property
    def is_tree(self) -> bool:
        """True when some segment is a branch of another."""
        return any(s.is_branch for s in self.segments)

    def segment_index(self, name: str) -> int:
        """Index of the segment called ``name``; SeedsError when there is none."""
        for k, s in enumerate(self.segments):
            if s.name == name:
                return k
        raise SeedsError(f"seeds: no segment named {_shown(name)}")

    def feature(self, name: str) -> Feature:
        """The feature called ``name``; SeedsError when there is none."""
        for f in self.features:
            if f.name == name:
                return f
        raise SeedsError(f"seeds: no feature named {_shown(name)}")

    def to_dict(self) -> dict:
        """The JSON document: version 2 when some segment is a branch, else version 1."""
        segments = []
        for s in self.segments:
            entry: dict = {"name": s.name}
            if s.is_branch:
                entry["parent"] = s.parent
                entry["bifurcation"] = s.bifurcation
            entry["a"] = [list(p) for p in s.a_px]
            entry["b"] = [list(p) for p in s.b_px]
            segments.append(entry)
        return {
            "version": SEEDS_VERSION if self.is_tree else 1,
            "segments": segments,
            "features": [
                {"name": f.name, "a": list(f.a_px), "b": list(f.b_px)} for f in self.features
            ],
        }

    def correspondences(self) -> tuple[NDArray[np.float64], NDArray[np.float64], list[str]]:
        """Corresponding points of both views: segment ends then features.

        Returns points_a_px (K, 2), points_b_px (K, 2) and their names.
        """
        pa: list[tuple[float, float]] = []
        pb: list[tuple[float, float]] = []
        names: list[str] = []
        for s in self.segments:
            pa += [s.a_px[0], s.a_px[-1]]
            pb += [s.b_px[0], s.b_px[-1]]
            names += [f"{s.name} proximal", f"{s.name} distal"]
        for f in self.features:
            pa.append(f.a_px)
            pb.append(f.b_px)
            names.append(f.name)
        return np.asarray(pa, float).reshape(-1, 2), np.asarray(pb, float).reshape(-1, 2), names


# Most points one view of a segment may have (the ends and the waypoints
# between), and most segments and features in a file: far beyond what a
# clinician clicks, small enough to bound the work.
MAX_POINTS_PER_VIEW = 1000
MAX_SEGMENTS = 100
MAX_FEATURES = 1000
# Largest coordinate magnitude accepted before the image bounds are known.
_MAX_COORD_PX = 1e6


def _shown(value: object, limit: int = 40) -> str:
    """A short one-line rendering of a value for a message (no control characters)."""
    text = "".join(ch if ch.isprintable() else "?" for ch in repr(value)[: limit + 1])
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _finite(x: object) -> bool:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False
    try:
        return math.isfinite(float(x)) and abs(float(x)) <= _MAX_COORD_PX
    except OverflowError:
        return False


def _point(value: object, where: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2 or not all(map(_finite, value)):
        raise SeedsError(
            f"{where}: expected a point [col, row] of two finite numbers, got {_shown(value)}"
        )
    return (float(value[0]), float(value[1]))


def _entries(data: dict, key: str, source: str, limit: int) -> list:
    value = data.get(key) or []
    if not isinstance(value, list):
        raise SeedsError(f"{source}: '{key}' must be a list, got {type(value).__name__}")
    if len(value) > limit:
        raise SeedsError(f"{source}: {len(value)} {key}; at most {limit} are read")
    return value


#: The most characters of a name a seeds file keeps.
MAX_NAME_CHARS = 80


def _name(value: object, default: str) -> str:
    if value is None:
        return default
    text = "".join(ch if ch.isprintable() else " " for ch in str(value)).strip()
    return text[:MAX_NAME_CHARS] or default


def seeds_from_dict(data: object, source: str = "seeds") -> Seeds:
    """Validate a parsed seeds document; errors name ``source`` and the bad entry."""
    if not isinstance(data, dict):
        raise SeedsError(f"{source}: the top level must be a JSON object")
    version = data.get("version", 1)
    if isinstance(version, bool) or version not in (1, SEEDS_VERSION):
        raise SeedsError(
            f"{source}: unsupported version {_shown(version)} (this program reads 1 and 2)"
        )
    segments = []
    for k, s in enumerate(_entries(data, "segments", source, MAX_SEGMENTS)):
        where = f"{source}: segments[{k}]"
        if not isinstance(s, dict):
            raise SeedsError(f"{where} must be an object")
        name = _name(s.get("name"), f"segment {k + 1}")
        views = {}
        for key in ("a", "b"):
            pts = s.get(key)
            if not isinstance(pts, list) or len(pts) < 2:
                raise SeedsError(
                    f"{where} ({name}): '{key}' needs at least two points (proximal and distal)"
                )
            if len(pts) > MAX_POINTS_PER_VIEW:
                raise SeedsError(
                    f"{where} ({name}): '{key}' has {len(pts)} points; at most "
                    f"{MAX_POINTS_PER_VIEW} per view are read"
                )
            views[key] = tuple(_point(p, f"{where}.{key}[{i}]") for i, p in enumerate(pts))
        link = {}
        for key in ("parent", "bifurcation"):
            value = s.get(key)
            if value is not None and (version == 1 or not isinstance(value, str)):
                raise SeedsError(
                    f"{where} ({name}): '{key}' needs version 2 and a name (text), "
                    f"got {_shown(value)}"
                )
            link[key] = None if value is None else _name(value, "")
        segments.append(Segment(name=name, a_px=views["a"], b_px=views["b"], **link))
    features = []
    for k, f in enumerate(_entries(data, "features", source, MAX_FEATURES)):
        where = f"{source}: features[{k}]"
        if not isinstance(f, dict) or "a" not in f or "b" not in f:
            raise SeedsError(f"{where} must be an object with points 'a' and 'b'")
        features.append(
            Feature(
                name=_name(f.get("name"), f"feature {k + 1}"),
                a_px=_point(f["a"], f"{where}.a"),
                b_px=_point(f["b"], f"{where}.b"),
            )
        )
    _check_tree(segments, features, source)
    return Seeds(segments=tuple(segments), features=tuple(features))


def _check_tree(segments: list[Segment], features: list[Feature], source: str) -> None:
    """In a tree (some segment is a branch): segment names unique, each branch's parent an
    earlier segment and its bifurcation a feature. A tree-free list is not checked
    (version-1 files may repeat a name)."""
    if not any(s.is_branch for s in segments):
        return
    seen: set[str] = set()
    feature_names = {f.name for f in features}
    for k, s in enumerate(segments):
        where = f"{source}: segments[{k}] ({s.name})"
        if s.name in seen:
            raise SeedsError(f"{where}: another segment has the same name; names must differ")
        if (s.parent is None) != (s.bifurcation is None):
            raise SeedsError(f"{where}: a branch needs both 'parent' and 'bifurcation'")
        if s.parent is not None:
            if s.parent not in seen:
                raise SeedsError(
                    f"{where}: parent {_shown(s.parent)} is not the name of an earlier segment"
                )
            if s.bifurcation not in feature_names:
                raise SeedsError(
                    f"{where}: bifurcation {_shown(s.bifurcation)} is not the name of a feature"
                )
        seen.add(s.name)

