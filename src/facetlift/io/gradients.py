"""Gradient fields (p, q) as ``.npy``, OpenEXR or TIFF files, and MATLAB ``.mat`` files holding
gradients or normals by variable name (scipy.io, imported on first use).

The layout of (p, q) (which axis each one differentiates along, and which way) is a *gradient
frame*, converted by :func:`facetlift.frames.gradients_to_facetlift`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._warnings import warn
from ._paths import _existing, _suffix
from .images import load_mat, read_mask, read_plane

GRADIENT_FORMATS = (".npy", ".exr", ".tif", ".tiff", ".pfm")


def read_gradient(path, arg: str = "p") -> np.ndarray:
    """One (H, W) float component of a gradient field: ``.npy``, a one-channel OpenEXR file,
    a float TIFF or a one-channel PFM.

    Raises
    ------
    ValueError
        Missing or unreadable file, several channels, not 2-D, or an integer pixel type (a
        gradient has no integer encoding); a ``.mat`` file (it holds p and q together: the
        command line takes it as NORMALS).
    """
    if str(path).lower().endswith(".mat"):  # (said only "unsupported gradient format", an
        # audit)
        raise ValueError(f"`{arg}`: {path} is a MATLAB file, which holds p and q together: "
                         "give it as the input itself (facetlift integrate FILE.mat, with "
                         "--mat-keys P,Q where its variables are not p and q), not --gradients")
    a = read_plane(path, GRADIENT_FORMATS, "gradient", arg)
    if a.dtype.kind != "f":
        raise ValueError(
            f"`{arg}`: {path} has pixel type {a.dtype}; gradients must be floating point"
        )
    return a.astype(np.float64)


def read_gradients(p_path, q_path, mask_path=None) -> dict:
    """``{"p", "q", "mask"}`` from two gradient files (:func:`read_gradient`) and an optional
    mask image; the arrays are as stored (see :func:`facetlift.integrate_gradients` for their
    frame)."""
    p = read_gradient(p_path, "p")
    q = read_gradient(q_path, "q")
    if q.shape != p.shape:
        raise ValueError(f"`q`: {q_path} has shape {q.shape}, but `p` has {p.shape}")
    mask = None if mask_path is None else read_mask(mask_path, p.shape, of="the gradient field")
    return {"p": p, "q": q, "mask": mask}


def read_mat(path, keys=None) -> dict:
    """Read gradients or normals from a MATLAB ``.mat`` file (v4 to v7; v7.3 is HDF5).

    Parameters
    ----------
    path : str or Path
    keys : sequence of str, optional
        Variable names: ``(p, q)`` or ``(p, q, mask)`` for a gradient field, ``(normals,)`` or
        ``(normals, mask)`` for a normal map (an (H, W, 3) variable). Default: ``p`` and
        ``q`` (and ``mask``, in any case, when present) if the file has them, else its only
        (H, W, 3) variable (and ``mask``).

    Returns
    -------
    dict
        ``{"p", "q", "mask"}`` or ``{"normals", "mask"}``, float64 arrays as stored (mask
        bool or None).

    Raises
    ------
    ValueError
        Unreadable or v7.3 file, a missing variable (the message lists those present), or
        arrays of the wrong shape.
    """
    arg = "path"
    f = _existing(path, arg)
    _suffix(f, (".mat",), "MATLAB", arg)
    data = load_mat(f, arg, "pass the arrays to facetlift.integrate_gradients")
    names = sorted(k for k in data if not k.startswith("__"))
    keys = _default_keys(data, names) if keys is None else list(keys)
    missing = [k for k in keys if k not in data]
    if missing or not 1 <= len(keys) <= 3:
        raise ValueError(
            f"`mat_keys`: {f} has variables {names}; asked for {keys} (give p,q[,mask] or "
            "normals[,mask])"
        )
    arrays = [np.asarray(data[k]) for k in keys]
    for k, a in zip(keys, arrays, strict=True):
        if a.dtype.kind not in "biuf":
            raise ValueError(f"`mat_keys`: variable {k!r} of {f} is not numeric ({a.dtype})")
    if arrays[0].ndim == 3:
        if len(keys) > 2 or arrays[0].shape[-1] != 3:
            raise ValueError(
                f"`mat_keys`: variable {keys[0]!r} of {f} has shape {arrays[0].shape}; a "
                "normal map is (H, W, 3), followed by at most a mask"
            )
        out = {"normals": arrays[0].astype(np.float64)}
        rest = arrays[1:]
    else:
        if len(keys) < 2:
            raise ValueError(f"`mat_keys`: a gradient field needs p and q; got {keys}")
        for k, a in zip(keys[:2], arrays[:2], strict=True):
            if a.dtype.kind != "f":  # (as a .npy or TIFF's: int16 slopes * 1000 came out
                # as huge slopes, 99 % of them grazing, an audit)
                raise ValueError(f"`mat_keys`: variable {k!r} of {f} has type {a.dtype}; "
                                 "gradients must be floating point (slopes: scale integer "
                                 "ones back first)")
        p, q = (a.astype(np.float64) for a in arrays[:2])
        if p.ndim != 2 or q.shape != p.shape:
            raise ValueError(
                f"`mat_keys`: {keys[0]!r} and {keys[1]!r} of {f} must be (H, W) arrays of one "
                f"shape; got {p.shape} and {q.shape}"
            )
        out = {"p": p, "q": q}
        rest = arrays[2:]
    shape = next(iter(out.values())).shape[:2]
    out["mask"] = None
    if rest:
        m = rest[0]
        if m.shape != shape:
            raise ValueError(f"`mat_keys`: the mask of {f} has shape {m.shape}; expected {shape}")
        out["mask"] = _mat_mask(m, f"the mask of {f}")
    return out


def _mat_mask(m: np.ndarray, name: str) -> np.ndarray:
    """A .mat file's mask as bool: above 0 inside; NaN outside (MATLAB code marks the
    background so), counted in a warning; negatives outside with a warning, as every other
    mask. ``m != 0`` took a NaN or a -1 background inside: the whole image was integrated,
    its missing samples filled in as surface, without a word (a review)."""
    from ..problem import negatives_outside

    if m.dtype.kind not in "biuf":
        raise ValueError(f"`mat_keys`: {name} has type {m.dtype}; a mask is numeric or "
                         "logical")
    if m.dtype.kind == "f":
        nan = int(np.count_nonzero(np.isnan(m)))
        if nan:
            warn(f"{name} holds {nan} NaN values: they count as outside (MATLAB's mark of a "
                 "background), the values above 0 as inside")
            m = np.where(np.isnan(m), 0.0, m)
    return negatives_outside(m, name)


def _default_keys(data: dict, names: list[str]) -> list[str]:
    # (the mask's name in any case: MATLAB code's Mask was left unread without a word, the
    # whole image integrated, a review)
    mask = ["mask"] if "mask" in data else [k for k in names if k.lower() == "mask"][:1]
    if "p" in data and "q" in data:
        return ["p", "q"] + mask
    maps = [k for k in names if np.ndim(data[k]) == 3 and np.shape(data[k])[-1] == 3]
    if len(maps) == 1:
        return maps + mask
    return ["p", "q"]  # reported as missing, with the variables present


def is_mat(path) -> bool:
    return Path(path).suffix.lower() == ".mat"
