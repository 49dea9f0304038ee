"""Discrete operators on the image grid, without policy: the facet stencil of the vertex grid
(:mod:`~facetlift.operators.stencil`) and the pixel graph (:mod:`~facetlift.operators.graph`)."""
