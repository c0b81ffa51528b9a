"""coronary3d's numerical pipeline: pure arrays and small frozen dataclasses.

The public API is re-exported here and loaded on first use, so that
``import recon`` (and the command line's start-up) stays light. For the same
reason, two modules that a library imports eagerly but a reconstruction
does not use are deferred to their first use (:data:`DEFERRED_MODULES`).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import threading
import types
from collections.abc import Callable
from typing import Any

__version__ = "0.1.0"

_EXPORTS = {
    "ViewGeometry": "recon.geometry",
    "triangulate": "recon.geometry",
    "epipolar_lines": "recon.geometry",
    "fundamental_matrix": "recon.geometry",
    "Seeds": "recon.seeds",
    "load_seeds": "recon.io.seeds_file",
    "save_seeds": "recon.io.seeds_file",
    "Centerline2D": "recon.types",
    "Centerline3D": "recon.types",
    "Matching": "recon.types",
    "Angiogram": "recon.types",
    "load_angiogram": "recon.io.angiogram",
    "LoadError": "recon.errors",
    "compute_vesselness": "recon.trace.centerline",
    "trace_segment": "recon.trace.centerline",
    "calibrate": "recon.pose.calibration",
    "cbocd_descriptor": "recon.correspond.cbocd",
    "match_centerlines": "recon.correspond.matching",
    "build_centerline_3d": "recon.correspond.triangulation",
    "build_surface": "recon.lumen.surface",
    "export_mesh": "recon.io.outputs",
    "measure_lumen": "recon.lumen.measure",
    "make_phantom": "recon.synth",
    "ReconstructionOptions": "recon.pipeline",
    "reconstruct_pair": "recon.pipeline",
}

__all__ = ["__version__", *_EXPORTS]


def lazy_exports(
    package: str, exports: dict[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A package's ``__getattr__`` and ``__dir__`` (PEP 562) that load each name of
    ``exports`` ({name: module}) from its module on first use."""

    def getattr_(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(module), name)

    def dir_() -> list[str]:
        return sorted({*globals_of(package), *exports})

    return getattr_, dir_


def globals_of(package: str) -> list[str]:
    """The names a loaded module holds."""
    return list(vars(sys.modules[package]))


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)


#: Modules imported at start-up by a library but used only on a path that a
#: reconstruction does not take: requests and tqdm, imported by pydicom's helper that
#: downloads its test files (``pydicom.data.download``). Each is imported on the first
#: use of one of its names. (networkx, which trimesh imports, cannot wait:
#: ``trimesh.base`` takes ``networkx.Graph`` at import.)
DEFERRED_MODULES = ("requests", "tqdm")


class _DeferredModule(types.ModuleType):
    """Stands in ``sys.modules`` for a module until one of its names is looked up.

    ``import name`` finds this stand-in, which carries the real module's spec
    (so the import system takes it as initialised); the first missing
    attribute imports the real module in its place and copies its names here,
    so a library that kept the stand-in sees the real module from then on.
    """

    _lock = threading.Lock()

    def __getattr__(self, attr: str) -> Any:
        with _DeferredModule._lock:
            if sys.modules.get(self.__name__) is self:
                del sys.modules[self.__name__]
                try:
                    real = importlib.import_module(self.__name__)
                except BaseException:
                    sys.modules[self.__name__] = self
                    raise
                self.__dict__.update(real.__dict__)
        return getattr(sys.modules[self.__name__], attr)


def _defer_import(name: str) -> None:
    """Put a :class:`_DeferredModule` for ``name`` in ``sys.modules`` (nothing when the
    module is imported already or not installed)."""
    if name in sys.modules:
        return
    spec = importlib.util.find_spec(name)
    if spec is None:
        return
    stand_in = _DeferredModule(name)
    stand_in.__spec__ = spec
    sys.modules[name] = stand_in


for _name in DEFERRED_MODULES:
    _defer_import(_name)
