"""The weighing's linear algebra without the tall arrays (issue 43, item 7) against the paths
it replaces: the linear step's factor from the Gram matrix of [A b]
(:func:`quadsim.gap.evidence.gram_factor`) against the Householder QR of [A b] itself
(:func:`~quadsim.gap.evidence.qr_factor`), and the profiled cost from one pass over the
marginal's columns (:meth:`~quadsim.gap.evidence.Marginal.cost`) against the squared norm of
the profiled residual (:meth:`~quadsim.gap.evidence.Marginal.profile`). Random matrices
shaped as a flight's (N C rows, K shared columns, P parameters), with the parameters' columns
partly in the span of the shared ones (an explanation that a shared group nearly mimics: the
case where the Gram form cancels most); the tolerances are round-off's, far below what any
evidence or decision reads (a hundredth of a log unit)."""

from __future__ import annotations

import numpy as np
import pytest

from quadsim.gap.evidence import ChannelBlocks, Marginal, gram_factor, qr_factor


def _problem(seed: int, rows: int = 3000, shared: int = 12, params: int = 4,
             mimic: float = 0.999):
    rng = np.random.default_rng(seed)
    jac = rng.normal(size=(rows, shared)) * rng.uniform(0.01, 3.0, size=shared)
    s_ref = rng.uniform(0.5, 20.0, size=shared)
    extra = rng.normal(size=(rows, 2))
    marg = Marginal(jac, s_ref, extra)
    # each parameter's column: mostly a mix of the shared ones (times their spreads), the
    # rest its own; scaled as a well- and a poorly-determined parameter both
    mix = jac @ rng.normal(size=(shared, params))
    own = rng.normal(size=(rows, params))
    cols = (mimic * mix + (1.0 - mimic) * own) * np.geomspace(0.1, 300.0, params)
    base = rng.normal(size=rows) * 3.0 + mix[:, 0]
    start = rng.normal(size=params) * 0.3
    return marg, start, base, cols


@pytest.mark.parametrize("seed,mimic", [(1, 0.0), (2, 0.9), (3, 0.999), (4, 0.99999)])
def test_the_gram_factor_is_the_qr_factor(seed, mimic):
    """R up to its rows' signs (the same RᵀR), the unconstrained step -R^-1 Qᵀb, the
    remainder and AᵀA: equal to 1e-9 relative (the round-off of either, times the cancellation
    of the shared columns' share, up to ~1e10 here)."""
    marg, start, base, jac = _problem(seed, mimic=mimic)
    r1, qb1, rest1, h1 = qr_factor(marg, start, base, jac)
    r2, qb2, rest2, h2 = gram_factor(marg, start, base, jac)
    scale = float(np.max(np.abs(h1)))
    np.testing.assert_allclose(h2, h1, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(r2.T @ r2, r1.T @ r1, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(np.linalg.solve(r2, qb2), np.linalg.solve(r1, qb1),
                               rtol=1e-9, atol=1e-12)
    assert rest2 == pytest.approx(rest1, rel=1e-10)
    # and against the normal equations of A itself, formed densely
    aug, du = marg.profile(jac)
    aug0, du0 = marg.profile(base)
    a = np.vstack([aug, du, np.eye(len(start))])
    b = np.concatenate([aug0, du0, start])
    np.testing.assert_allclose(h2, a.T @ a, rtol=0, atol=1e-9 * scale)
    x = np.linalg.lstsq(a, -b, rcond=None)[0]
    np.testing.assert_allclose(-np.linalg.solve(r2, qb2), x, rtol=1e-9, atol=1e-12)
    assert rest2 == pytest.approx(float(np.sum((a @ x + b) ** 2)), rel=1e-10)


def test_the_gram_factor_without_shared_columns():
    """A marginal of no columns: A = [jac; I], the Gram matrix jacᵀjac + I."""
    rng = np.random.default_rng(5)
    marg = Marginal(np.zeros((500, 0)), np.zeros(0))
    jac, base, start = rng.normal(size=(500, 3)), rng.normal(size=500), np.zeros(3)
    r1, qb1, rest1, h1 = qr_factor(marg, start, base, jac)
    r2, qb2, rest2, h2 = gram_factor(marg, start, base, jac)
    np.testing.assert_allclose(h2, jac.T @ jac + np.eye(3), rtol=1e-13)
    np.testing.assert_allclose(np.linalg.solve(r2, qb2), np.linalg.solve(r1, qb1), rtol=1e-10)
    assert rest2 == pytest.approx(rest1, rel=1e-12)


def test_a_residual_in_the_span_is_refused_by_the_gram_factor():
    """b = 0 (the residual and the start zero): [A b] has no full rank, the Gram matrix is
    singular; the Gram form
    raises (linear_step then factors A itself) rather than return a made-up remainder."""
    rng = np.random.default_rng(6)
    marg = Marginal(np.zeros((400, 0)), np.zeros(0))
    jac = rng.normal(size=(400, 2))
    with pytest.raises(np.linalg.LinAlgError):
        gram_factor(marg, np.zeros(2), np.zeros(400), jac)


@pytest.mark.parametrize("seed", [7, 8])
def test_the_profiled_cost_is_the_profiled_residuals_norm(seed):
    """|r|^2 - bᵀA^-1 b against |r + j du|^2 + |du|^2 from the profile: 1e-12 relative."""
    marg, _, base, _ = _problem(seed)
    aug, du = Marginal(marg.j, np.ones(marg.j.shape[1])).profile(base)
    want = float(aug @ aug) + float(du @ du)
    fresh = Marginal(marg.j, np.ones(marg.j.shape[1]))
    assert fresh.cost(base) == pytest.approx(want, rel=1e-12)
    fresh.profile(base)                             # profiled already: its own norm
    assert fresh.cost(base) == want


def test_the_kept_moment_is_the_one_computed_anew():
    """jᵀ r and A^-1 jᵀ r kept from a profile or a cost of the same residual vector
    (:meth:`Marginal.moment`) against a marginal that computes them for the linear step:
    the step's factor the same to the bit; another vector is not answered from the kept."""
    marg, start, base, jac = _problem(9)
    fresh = Marginal(marg.j, np.ones(marg.j.shape[1]))
    fresh.profile(base)                             # keeps base's moment
    want = gram_factor(Marginal(marg.j, np.ones(marg.j.shape[1])), start, base, jac)
    got = gram_factor(fresh, start, base, jac)
    for a, b in zip(got, want):
        assert np.array_equal(a, b)
    other = base + 1.0
    rhs, x = fresh.moment(other)
    assert np.array_equal(rhs, fresh.j.T @ other)
    np.testing.assert_allclose((np.eye(fresh.j.shape[1]) + fresh.j.T @ fresh.j) @ x, rhs,
                               rtol=1e-10, atol=1e-10 * float(np.max(np.abs(rhs))))


def test_channel_blocks_give_the_dense_marginal():
    """The discrepancy's columns kept as :class:`ChannelBlocks` (each column in one channel's
    rows, products over those N rows only) against the same columns dense: j, A's factor and
    log det, jᵀr, j u and the profile of a vector and of columns, equal to round-off (1e-12
    of their scale); a column across two channels is not a block."""
    rng = np.random.default_rng(11)
    n, chans, k = 300, 10, 7
    jac, s_ref = rng.normal(size=(n * chans, k)), rng.uniform(0.1, 3.0, k)
    cube = np.zeros((n, chans, 6))
    for e, c in enumerate((0, 0, 2, 5, 5, 5)):
        cube[:, c, e] = rng.normal(size=n)
    extra = cube.reshape(n * chans, 6)
    blocks = ChannelBlocks.of(extra, chans)
    assert blocks is not None and list(blocks.ch) == [0, 0, 2, 5, 5, 5]
    assert np.array_equal(blocks.dense(), extra)
    dense, fast = Marginal(jac, s_ref, extra), Marginal(jac, s_ref, None, blocks=blocks)
    assert fast.shape == dense.j.shape and np.array_equal(fast.j, dense.j)
    np.testing.assert_allclose(fast.chol[0], dense.chol[0], rtol=0, atol=1e-12 * n)
    assert fast.logdet == pytest.approx(dense.logdet, rel=1e-12)
    for r in (rng.normal(size=n * chans), rng.normal(size=(n * chans, 3))):
        np.testing.assert_allclose(fast.jt(r), dense.j.T @ r, rtol=0, atol=1e-12 * n)
        for got, want in zip(fast.profile(r), dense.profile(r)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * n)
    for u in (rng.normal(size=k + 6), rng.normal(size=(k + 6, 4))):
        np.testing.assert_allclose(fast.j_times(u), dense.j @ u, rtol=0, atol=1e-12 * n)
    cube[:, 1, 0] = 1.0                               # column 0 now in two channels
    assert ChannelBlocks.of(cube.reshape(n * chans, 6), chans) is None
