"""Sparse SPD solver backends agree with each other and fail loudly."""

import numpy as np
import pytest
import scipy.sparse as sp

from facetlift import linalg
from facetlift.linalg import SolverError


def _spd(n=400, seed=0):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.01, random_state=np.random.RandomState(seed))
    K = (A @ A.T + sp.eye(n) * 2.0).tocsr()
    return K, rng.standard_normal(n)


@pytest.mark.parametrize("backend", linalg.available_backends())
def test_backends_agree(backend):
    K, b = _spd()
    ref = np.linalg.solve(K.toarray(), b)
    if backend == "pcg":
        d = K.diagonal()
        x = linalg.solve(K, b, backend, preconditioner=lambda r: r / d)
    else:
        x = linalg.solve(K, b, backend)
    assert np.allclose(x, ref, rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize("backend", linalg.available_backends())
def test_factor_reuse(backend):
    K, b = _spd()
    d = K.diagonal()
    f = linalg.factorize(K, backend, preconditioner=lambda r: r / d)
    for k in range(3):
        rhs = b * (k + 1)
        assert np.allclose(K @ f.solve(rhs), rhs, atol=1e-7)


def test_unknown_backend_is_named():
    K, b = _spd(10)
    with pytest.raises(ValueError, match="`backend` must be one of"):
        linalg.solve(K, b, "cholmod-please")


def test_pcg_needs_preconditioner():
    K, b = _spd(10)
    with pytest.raises(ValueError, match="needs a `preconditioner`"):
        linalg.solve(K, b, "pcg")
    with pytest.raises(ValueError, match="needs a `preconditioner`"):
        linalg.factorize(K, "pcg")


def test_pcg_factor_warm_starts():
    K, b = _spd()
    d = K.diagonal()
    f = linalg.factorize(K, "pcg", preconditioner=lambda r: r / d)
    x1 = f.solve(b)
    f.solve(b)
    assert linalg.pcg.last_iterations <= 1
    assert np.allclose(K @ x1, b, atol=1e-8)


def test_singular_matrix_raises_solver_error():
    K = sp.csr_matrix(np.zeros((5, 5)))
    with pytest.raises(SolverError):
        linalg.factorize(K, "superlu")


def test_pcg_non_convergence_raises():
    K, b = _spd(200)
    with pytest.raises(SolverError, match="did not converge"):
        linalg.pcg(K, b, lambda r: r, rtol=1e-14, maxiter=1)
