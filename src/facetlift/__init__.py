"""facetlift: surfaces from normal maps and gradient fields.

>>> import facetlift
>>> surface = facetlift.integrate(normals, mask)          # doctest: +SKIP
>>> surface.depth, surface.to_mesh(), surface.save("out.ply")  # doctest: +SKIP

Conventions: :mod:`facetlift.conventions`. Methods: ``facetlift.METHODS`` or
``facetlift methods``. Architecture: docs/architecture.md.

Importing facetlift loads nothing heavy: the names below are imported on first use
(PEP 562), so ``import facetlift`` and ``facetlift --version`` stay fast.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

#: public name -> (module, attribute); attribute None: the module itself
_LAZY = {
    "integrate": ("api", "integrate"),
    "integrate_gradients": ("api", "integrate_gradients"),
    "batch": ("batch", None),  # the module, callable as facetlift.batch(...)
    "solve": ("api", "solve"),
    "Orthographic": ("camera", "Orthographic"),
    "Pinhole": ("camera", "Pinhole"),
    "SolverError": ("errors", "SolverError"),
    "MemoryLimitError": ("errors", "MemoryLimitError"),
    "InputFileNotFound": ("errors", "InputFileNotFound"),
    "FrameWarning": ("errors", "FrameWarning"),
    "CameraWarning": ("errors", "CameraWarning"),
    "ConvergenceWarning": ("errors", "ConvergenceWarning"),
    "LayoutWarning": ("frames", "LayoutWarning"),
    "UnusableNormalsWarning": ("problem", "UnusableNormalsWarning"),
    "METHODS": ("methods", "REGISTRY"),
    "Problem": ("problem", "Problem"),
    "clean_mask": ("problem", "clean_mask"),
    "gradients_from_normals": ("problem", "gradients_from_normals"),
    "normals_from_gradients": ("problem", "normals_from_gradients"),
    "prepare": ("api", "prepare"),
    "Surface": ("surface", "Surface"),
}

__all__ = sorted(_LAZY)


#: Public submodules reachable as attributes after a plain ``import facetlift`` (loaded on
#: first use, like numpy's): ``facetlift.io.read_normals(...)``.
_SUBMODULES = ("io", "synthetic", "metrics", "frames", "camera", "conventions", "linalg",
               "memory", "jobs", "methods", "operators", "bench", "errors", "problem",
               "surface", "domain", "api", "describe", "options", "perspective", "photometric")


def __getattr__(name: str):
    if name in _LAZY:
        module, attr = _LAZY[name]
        value = importlib.import_module(f".{module}", __name__)
        value = value if attr is None else getattr(value, attr)
        globals()[name] = value  # later look-ups skip this function
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)  # (binds itself as an attribute)
    raise AttributeError(f"module 'facetlift' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | set(_SUBMODULES))
