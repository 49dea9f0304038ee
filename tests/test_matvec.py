"""The two-thread sparse product (facetlift.linalg.matvec)."""

import os
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from facetlift.linalg import matvec
from facetlift.linalg.cg import cg


def grid_matrix(n=300, seed=0):
    T = sp.diags([np.ones(n - 1), np.full(n, 2.5), np.ones(n - 1)], [-1, 0, 1])
    K = sp.kron(T, T, format="csr")
    K.data = K.data * (1 + 0.1 * np.random.default_rng(seed).random(K.nnz))
    return (K + K.T).tocsr()


@pytest.fixture
def split(monkeypatch):
    monkeypatch.setattr(matvec, "MIN_ROWS", 10)
    monkeypatch.setattr(matvec, "free_core", lambda: True)


def test_split_product_equals_scipys(split):
    K = grid_matrix()
    A = matvec.parallel(K)
    assert isinstance(A, matvec.SplitProduct)
    x = np.random.default_rng(1).normal(size=K.shape[0])
    np.testing.assert_array_equal(A @ x, K @ x)
    # the halves hold equal non-zeros, and a block of vectors is scipy's own product
    assert abs(K.indptr[A._cut] - K.nnz / 2) <= 9
    X = np.stack([x, 2 * x], axis=1)
    np.testing.assert_array_equal(A @ X, K @ X)
    np.testing.assert_array_equal(A @ x.astype(np.float32), K @ x.astype(np.float32))


def test_the_product_into_a_given_vector(split):
    K = grid_matrix()
    A = matvec.parallel(K)
    x = np.random.default_rng(4).normal(size=K.shape[0])
    out = np.full(K.shape[0], np.nan)
    y = A.product(x, out=out)
    assert y is out
    np.testing.assert_array_equal(out, K @ x)
    # (scipy's own product for another dtype, into the vector too)
    y = A.product(x.astype(np.float32), out=out)
    assert y is out
    np.testing.assert_array_equal(out, K @ x.astype(np.float32))
    # an `out` the kernel would write past or into `x` is refused, not written
    n = K.shape[0]
    for bad in (np.empty(n - 1), np.empty(n + 1), np.empty(n, np.float32),
                np.empty(2 * n)[::2], x):
        with pytest.raises(ValueError, match="`out` must be"):
            A.product(x, out=bad)


def test_cg_on_a_tall_two_thread_product_refuses_cleanly(split):
    # (a caller's non-square matrix: scipy's own shape error, no product into a buffer of
    # the wrong length)
    K = sp.random(600, 590, density=0.05, format="csr", random_state=1)
    assert isinstance(matvec.parallel(K), matvec.SplitProduct)
    with pytest.raises(ValueError):
        cg(K, np.ones(590), rtol=1e-8, maxiter=5)


def test_small_busy_or_other_matrices_are_left_alone(monkeypatch):
    K = grid_matrix(20)
    assert matvec.parallel(K) is K  # below MIN_ROWS
    monkeypatch.setattr(matvec, "MIN_ROWS", 10)
    monkeypatch.setattr(matvec, "free_core", lambda: False)
    assert matvec.parallel(K) is K  # no free core
    monkeypatch.setattr(matvec, "free_core", lambda: True)
    assert matvec.parallel(K.tocsc()) is not None and not isinstance(
        matvec.parallel(K.tocsc()), matvec.SplitProduct)
    assert not isinstance(matvec.parallel(K.astype(np.float32)), matvec.SplitProduct)


def test_cg_with_the_split_product_gives_the_same_iterates(split, monkeypatch):
    K = grid_matrix(120)
    b = np.random.default_rng(2).normal(size=K.shape[0])
    x1, i1 = cg(K, b, rtol=1e-10)
    monkeypatch.setattr(matvec, "MIN_ROWS", 10**12)
    x0, i0 = cg(K, b, rtol=1e-10)
    assert i1.iterations == i0.iterations
    np.testing.assert_array_equal(x1, x0)


@pytest.mark.skipif(not hasattr(os, "fork") or sys.platform == "darwin",
                    reason="fork start method only")
def test_a_forked_child_makes_its_own_worker(split):
    K = grid_matrix(100)
    x = np.ones(K.shape[0])
    expected = K @ x
    np.testing.assert_array_equal(matvec.parallel(K) @ x, expected)  # the parent's pool
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: a copied pool would wait for ever on the parent's thread
        try:
            ok = np.array_equal(matvec.parallel(K) @ x, expected)
            os.write(w, b"1" if ok else b"0")
        finally:
            os._exit(0)
    os.close(w)
    import select

    ready, _, _ = select.select([r], [], [], 30)
    if not ready:
        import signal

        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
    assert ready, "the forked child's product hung"
    try:
        assert os.read(r, 1) == b"1"
    finally:
        os.close(r)
        os.waitpid(pid, 0)


def test_wrong_lengths_tiny_matrices_and_a_pool_shut_down(split, monkeypatch):
    K = grid_matrix(40)
    A = matvec.parallel(K)
    with pytest.raises(ValueError, match="dimension mismatch"):  # scipy's own error
        A @ np.ones(K.shape[1] - 1)
    for n in (0, 1):  # (a split needs two rows)
        tiny = sp.csr_matrix((n, n))
        assert matvec.parallel(tiny) is tiny
    # the worker takes no new job (the interpreter shutting down): the caller does it all
    x = np.random.default_rng(3).normal(size=K.shape[0])

    class Closed:
        def submit(self, *a, **k):
            raise RuntimeError("cannot schedule new futures after interpreter shutdown")

    monkeypatch.setattr(matvec, "_pool", lambda: Closed())
    np.testing.assert_array_equal(A @ x, K @ x)


def test_a_kernel_that_disagrees_is_not_used(split, monkeypatch):
    def wrong(n_row, n_col, indptr, indices, data, x, y):
        y += 1.0

    monkeypatch.setattr(matvec, "_kernel", wrong)
    monkeypatch.setattr(matvec, "_CHECKED", {"ok": None})
    K = grid_matrix(30)
    assert matvec.parallel(K) is K
    assert matvec._kernel is None
