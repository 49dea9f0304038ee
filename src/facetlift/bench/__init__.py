"""Reproduce the experiments of Xie et al. (CVPR 2014, Sec. 5): tables and figures.

:func:`run_bench` runs the registered methods (``facetlift.methods.REGISTRY``) on synthetic
ground truth (:mod:`facetlift.synthetic`) and on the normal maps of a data folder, and writes CSV
and Markdown tables and PNG figures into one output folder:

``table1``  timings of the DGP loop (factorization, local and global step) at 128, 256, 512
``fig4``    convergence with and without mean subtraction
``fig5``    a fraction of the normals perturbed by up to 20 degrees, kept as inliers or removed
``maps``    error maps of every method on a saddle, a sharp-crease surface and a face (Figs. 6-8)
``fig9``    mean normalised error of every method over >= 20 models, noise-free and 5-degree
            noise; also on the largest jump-free region of every rendered mesh (``continuous``)
``fig10``   angular error of every method on real normal maps without ground truth
``bear``    MADE on the perspective DiLiGenT bear for the methods that take perspective input
``discontinuities``  the discontinuity development benchmark (:mod:`.discontinuities`):
            pinhole, wide-angle, tabletop (several objects), vessel (open vessels seen from
            above the rim) and orthographic scenes with jumps x 4 normal conditions,
            against BiNI and the oracle with the true jumps cut; and the real normal maps
``heldout`` the same runs on every mesh from random views drawn from a seed (a test set no
            default was chosen on; ``Settings.heldout_views``, ``heldout_seed``)

A method whose module is missing or that raises is recorded as ``unavailable`` / ``failed`` in
the tables; the run goes on. Every file is written atomically.

Layout: :mod:`.runner` (the experiment registry, :func:`run_bench`, the report), :mod:`.core`
(settings, one method on one input, the context every experiment gets), one module per group
of experiments (:mod:`.paper`: Table 1, Figs. 4-5; :mod:`.maps`: Figs. 6-8; :mod:`.fig9`;
:mod:`.real`: Fig. 10 and the bear), :mod:`.tables` (CSV and Markdown) and :mod:`.plots` (every
figure; matplotlib is imported only when drawing).
"""

from .core import Run, Settings, Spec, default_specs, method_status, run_method
from .runner import EXPERIMENTS, default_data_dir, run_bench

__all__ = [
    "EXPERIMENTS",
    "Run",
    "Settings",
    "Spec",
    "default_data_dir",
    "default_specs",
    "method_status",
    "run_bench",
    "run_method",
]
