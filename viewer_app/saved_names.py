"""The names a saved viewer state holds (segment names, landmark names, branch links),
read leniently: an entry that cannot be read is skipped, never the whole document.

Below both :mod:`viewer_app.state` (which restores them) and :mod:`viewer_app.autosave`
(whose documents carry them), so that neither imports the other at run time.
"""

from __future__ import annotations

__all__ = ["read_names"]


def read_names(doc: dict, viewer: dict, segments: int) -> tuple[
        list[str], dict[int, str], dict[str, tuple[str, str]]]:
    """The names an autosave's ``viewer`` part holds, each entry that cannot be read
    skipped: the segment names (at least ``segments``, "Segment N" for those missing),
    the landmark names by group, and the branch links (name -> (parent, bifurcation);
    from the seeds part ``doc`` for an autosave older than the links)."""
    names_in = viewer.get("segment_names")
    names = [n for n in names_in if isinstance(n, str)] if isinstance(names_in, list) else []
    names += [f"Segment {k + 1}" for k in range(len(names), segments)]
    features_in = viewer.get("feature_names")
    feature_names = {}
    if isinstance(features_in, dict):
        for key, name in features_in.items():
            if isinstance(key, str) and key.isdigit() and isinstance(name, str):
                feature_names[int(key)] = name
    links_in = viewer.get("segment_links")
    links = {}
    if isinstance(links_in, dict):
        for name, link in links_in.items():
            if (isinstance(link, list) and len(link) == 2
                    and all(isinstance(x, str) for x in (name, *link))):
                links[name] = (link[0], link[1])
    elif links_in is None:  # an autosave from before the links: its seeds part has them
        for entry in doc.get("segments") or ():
            link = [entry.get(k) for k in ("name", "parent", "bifurcation")] \
                if isinstance(entry, dict) else []
            if link and all(isinstance(x, str) for x in link):
                links[link[0]] = (link[1], link[2])
    return names, feature_names, links
