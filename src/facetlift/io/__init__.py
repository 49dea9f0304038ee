"""Reading normal maps, masks and intrinsics; writing depth maps, meshes and previews.

Formats and the libraries behind them (imported on first use, so ``import facetlift`` stays
cheap):

================  =====================================  ======================================
what              formats                                library
================  =====================================  ======================================
normal maps       PNG 8/16 bit, TIFF, OpenEXR, ``.npy``  imagecodecs (libpng), tifffile, OpenEXR
masks             PNG, TIFF, ``.npy``                    imagecodecs, tifffile
intrinsics ``K``  text, 3 x 3                            numpy
rotations         text, ``.npy``, JSON; 3x3, 3x4, 4x4    numpy
depth maps        ``.npy``, OpenEXR, TIFF, ``.npz``      numpy, OpenEXR, tifffile
height maps       PNG 16 bit, OpenEXR                    imagecodecs, OpenEXR
meshes            PLY (binary), OBJ, STL                 numpy (facetlift's own writers)
colours           PNG, JPEG, TIFF, OpenEXR, ``.npy``     imagecodecs, tifffile, OpenEXR
previews          PNG                                    imagecodecs; matplotlib for colormaps
reports           PNG (panels)                           matplotlib
gradient fields   ``.npy``, OpenEXR, TIFF, ``.mat``      numpy, OpenEXR, tifffile, scipy.io
================  =====================================  ======================================

Integer normal maps are decoded per channel as ``n = v / maxval * 2 - 1`` (``maxval`` 255 or
65535) with R, G, B = x, y, z in the facetlift convention (x right, y up, z toward the viewer;
see :mod:`facetlift.conventions`). Pillow is not used for PNG because it silently reduces
16-bit RGB PNGs to 8 bits. A pixel of an integer map whose decoded vector has a length outside
:data:`ENCODED_LENGTH_RANGE` does not encode a normal (black, white or mid-grey background
fill) and decodes as NaN, i.e. a missing sample. A two-channel map (BC5, "RG") is read with
``encoding="xy"``: R, G = x, y, and z is rebuilt (:func:`facetlift.frames.decode_xy`). A float
map storing ``(n + 1) / 2`` in [0, 1] is read with ``normal_range="unsigned"``: decoded as
``2 v - 1`` first, its fill marked NaN as an integer map's
(:func:`facetlift.frames.decode_unsigned`).

Every writer is atomic: it writes a temporary file in the target directory, flushes it to disk
and renames it over the target, so a failed write never leaves a partial file behind.
:class:`OutputSet` does the same for all outputs of one run (a staging folder, moved into place
when everything succeeded).

matplotlib is needed only for the colour panel of :func:`write_preview` (``colormap=``) and comes
with the ``plot`` extra (``pip install 'facetlift[plot]'``); the shaded preview does without it.

Modules: :mod:`~facetlift.io.images` (normal maps, masks, depth maps),
:mod:`~facetlift.io.dataset` (``K.txt``, dataset folders), :mod:`~facetlift.io.meshes`,
:mod:`~facetlift.io.colors`, :mod:`~facetlift.io.preview`, :mod:`~facetlift.io.surface`
(:func:`save_surface`) and
:mod:`~facetlift.io.atomic` (:func:`atomic_path`). Everything public is importable from
``facetlift.io`` itself.
"""

from .atomic import OutputSet, atomic_path, sweep
from .colors import COLOR_FORMATS, read_colors
from .dataset import read_dataset, read_K, read_rotation
from .images import (
    DEPTH_FORMATS,
    ENCODED_LENGTH_RANGE,
    MASK_FORMATS,
    NORMAL_READ_FORMATS,
    NORMAL_WRITE_FORMATS,
    png_text,
    read_depth,
    read_mask,
    read_normals,
    read_prior,
    read_weights,
    write_depth,
    write_mask,
    write_normals,
)
from .meshes import MESH_FORMATS, write_mesh, write_points
from .preview import (
    HEIGHT_FORMATS,
    read_height,
    shade,
    write_discontinuities,
    write_height,
    write_preview,
)
from .report import write_report
from .surface import SURFACE_FORMATS, load_surface, save_surface

__all__ = [
    "COLOR_FORMATS",
    "DEPTH_FORMATS",
    "HEIGHT_FORMATS",
    "ENCODED_LENGTH_RANGE",
    "MASK_FORMATS",
    "MESH_FORMATS",
    "NORMAL_READ_FORMATS",
    "NORMAL_WRITE_FORMATS",
    "OutputSet",
    "SURFACE_FORMATS",
    "atomic_path",
    "read_K",
    "read_colors",
    "png_text",
    "read_dataset",
    "read_height",
    "read_depth",
    "read_prior",
    "read_rotation",
    "read_weights",
    "read_mask",
    "read_normals",
    "save_surface",
    "load_surface",
    "shade",
    "sweep",
    "write_depth",
    "write_mask",
    "write_mesh",
    "write_points",
    "write_normals",
    "write_discontinuities",
    "write_height",
    "write_preview",
    "write_report",
]
