"""facetlift: surfaces from normal maps and gradient fields.

>>> import facetlift
>>> surface = facetlift.integrate(normals, mask)          # doctest: +SKIP
>>> surface.depth, surface.to_mesh(), surface.save("out.ply")  # doctest: +SKIP

Conventions: :mod:`facetlift.conventions`. Methods: ``facetlift.methods.REGISTRY``.
Importing facetlift loads numpy and scipy only; methods and I/O load on first use.
"""

from .api import integrate, solve
from .camera import Orthographic, Pinhole
from .linalg import SolverError
from .methods import REGISTRY as METHODS
from .problem import Problem, clean_mask, gradients_from_normals, normals_from_gradients, prepare
from .surface import Surface

__version__ = "0.1.0"

__all__ = [
    "METHODS",
    "Orthographic",
    "Pinhole",
    "Problem",
    "SolverError",
    "Surface",
    "clean_mask",
    "gradients_from_normals",
    "integrate",
    "normals_from_gradients",
    "prepare",
    "solve",
]
