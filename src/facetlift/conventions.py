"""Coordinate conventions used everywhere in facetlift.

Every docstring in the package points here; ``docs/conventions.md`` says the same in longer form.

Arrays
    Images are indexed ``(row, col)``: ``H`` rows, ``W`` columns.

Normals
    A normal map is an ``(H, W, 3)`` float array. Its components are ``x`` along the columns
    (to the right), ``y`` *up* (against the row index) and ``z`` toward the viewer. This is the
    usual normal-map convention of DiLiGenT and BiNI. Normal maps stored in other frames
    (DirectX: ``y`` down; OpenCV camera frame: ``y`` down and ``z`` away) are read with
    ``normal_frame=`` (:mod:`facetlift.frames`; ``y_down=True`` is ``"directx"``).

Gradients
    ``p = dz/dx`` and ``q = dz/dy`` are the slopes of the *height* ``z`` (toward the viewer) along
    ``x`` (right) and ``y`` (up), in height units per world unit. They give the normal
    ``n = (-p, -q, 1) / |(-p, -q, 1)|``, and back ``p = -n_x / n_z``, ``q = -n_y / n_z``.

Depth
    Depth is distance along the viewing axis: larger is farther; NaN outside the domain. For an
    orthographic view it is defined up to an additive constant per connected component, and
    ``height = -depth``; facetlift fixes the constant so that each component's mean facet depth
    is zero. For a perspective camera, depth is the positive z-depth along the optical axis,
    defined up to a global scale.

Pixels, facets and vertices
    Pixel ``(r, c)`` is the quad facet whose corners are the vertices ``(r, c)``, ``(r, c+1)``,
    ``(r+1, c+1)``, ``(r+1, c)`` of an ``(H+1) x (W+1)`` vertex grid, in that order. The facet
    centre is the mean of its four corners (for a perspective camera the geometric mean of
    their depths: the mean of the log-depths), and ``Surface.depth[r, c]`` is the depth
    there.
    With pixel size ``h``, vertex ``(i, j)`` lies at ``x = j*h``, ``y = -i*h`` (orthographic).
    Two pixels belong to one connected component when they share a vertex (8-connectivity).

Intrinsics
    A perspective camera is a 3x3 matrix ``K`` in the OpenCV layout
    ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` with ``cx`` a column and ``cy`` a row counted from
    the top, pixel centres at integer indices. Back-projection of pixel ``(row, col)`` at depth
    ``Z`` gives camera coordinates ``X = (col - cx) Z / fx``, ``Y = (row - cy) Z / fy`` (OpenCV
    frame: x right, y down, z forward).
"""

#: Default threshold on ``n . (0, 0, 1)`` below which a normal is an outlier (cos 85 deg).
OUTLIER_EPS = 0.0871557

#: Corner order of a facet as (row offset, column offset) from its pixel (r, c).
CORNER_OFFSETS = ((0, 0), (0, 1), (1, 1), (1, 0))
