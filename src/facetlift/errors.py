"""The exceptions facetlift raises besides ``ValueError`` (bad input, naming the argument):
:class:`SolverError`, :class:`MemoryLimitError`, :class:`InputFileNotFound` (also a
``ValueError``) and, from :func:`facetlift.batch`,
:class:`WorkersDied`; and the warning categories a caller may filter or turn into errors
(``warnings.simplefilter("error", facetlift.FrameWarning)``): :class:`FrameWarning`,
:class:`CameraWarning`, :class:`ConvergenceWarning` (and
:class:`facetlift.problem.UnusableNormalsWarning`, :class:`facetlift.frames.LayoutWarning`, a
FrameWarning). The others are plain ``UserWarning``.

Kept in a module without heavy imports, so the command line can catch them cheaply.
"""

from __future__ import annotations


class InputFileNotFound(FileNotFoundError, ValueError):
    """An input file that does not exist: a ``FileNotFoundError`` (an ``OSError``) as Python
    code expects of a missing file, and the ``ValueError`` that every other bad input raises
    (the message names the argument)."""


class SolverError(RuntimeError):
    """The solver failed: a singular matrix, no convergence, a backend error, or a result that
    is not finite inside the mask."""


class WorkersDied(RuntimeError):
    """The local worker processes of a batch died before finishing (killed, out of memory, or
    started from a script without a ``__main__`` guard); the batch log keeps what finished, so
    ``resume=True`` goes on. The command line reports it in one line, exit code 1."""


class MemoryLimitError(MemoryError):
    """The planned peak memory of a job exceeds the limit (``max_memory``): the message names
    the estimate, the limit and what to do instead."""


class OutputMemoryError(MemoryError):
    """Memory ran out writing an output after the solve had finished: the message names the
    output (the command line then gives no advice about the map's size)."""


class FrameWarning(UserWarning):
    """The input is probably not in the frame or encoding it was read in: far more
    integrable with y (or x) flipped, a gradient field in the other layout
    (:class:`facetlift.frames.LayoutWarning`), or integer normals decoded as a PNG encoding;
    the weaker signs are :class:`FrameHint`."""


class FrameHint(FrameWarning):
    """A weaker sign of a wrong frame, which right inputs can give too: more integrable
    flipped by a small margin (correlated errors on a flat view), or normals pointing into the
    object all round its silhouette (an inside-out map, or a concave surface masked alone).
    The command line's ``--strict`` does not fail on these."""


class CameraWarning(UserWarning):
    """The camera is probably not the image's: K's principal point outside the image or at
    its edge, focal lengths in mm (a field of view past 150 deg), the axes of an old BiNI
    K.txt, or a field of view in radians or past a pinhole's. A wrong K bends the whole
    surface, so the command line's hint on depth jumps (:func:`facetlift.hints.jump_hint`)
    points at this warning instead. A calibration file's lens distortion or rectified
    projection, which K leaves out, is a plain UserWarning: nearly every real calibration has
    some, with the right K (a review: the bear with its own K and k1 = -0.01 lost its jump
    hint)."""


class ConvergenceWarning(UserWarning):
    """An iterative method stopped at its iteration cap before its own stopping rule, or a
    linear solve did not converge; the result is returned (``info["converged"]`` False where
    the method reports it)."""
