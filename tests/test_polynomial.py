from math import comb

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sknlss._core._model import StateSpaceModel
from sknlss._terms._polynomial import (
    PolynomialTerms,
    evaluate_monomials,
    monomial_exponents,
    monomial_jacobian,
)

STRUCTURES = ["full", "states_only", "no_cross_products", "inputs_only", "empty"]


@pytest.mark.parametrize("n_states, n_inputs, d", [(2, 1, 3), (3, 1, 3), (2, 2, 4), (1, 0, 5)])
def test_full_count_matches_paper(n_states, n_inputs, d):
    # Paper: monomials of degree 2..d in n + n_u variables number
    # C(n + n_u + d, d) - 1 - (n + n_u).
    m = n_states + n_inputs
    exps = monomial_exponents(n_states, n_inputs, range(2, d + 1))
    assert exps.shape == (comb(m + d, d) - 1 - m, m)
    assert exps.dtype == np.int64


def test_structures_counts():
    n, nu = 2, 1
    assert len(monomial_exponents(n, nu, (2, 3), "states_only")) == 3 + 4
    assert len(monomial_exponents(n, nu, (2, 3), "inputs_only")) == 2
    assert len(monomial_exponents(n, nu, (2, 3), "no_cross_products")) == 6
    st_only = monomial_exponents(n, nu, (2, 3), "states_only")
    assert np.all(st_only[:, n:] == 0)
    in_only = monomial_exponents(n, nu, (2, 3), "inputs_only")
    assert np.all(in_only[:, :n] == 0)
    ncp = monomial_exponents(n, nu, (2, 3), "no_cross_products")
    assert np.all((ncp > 0).sum(axis=1) == 1)


def test_order_matches_reference_model(pnlss_tutorial_model):
    exps = monomial_exponents(2, 1, (2, 3))
    # x1^2, x1 x2, x1 u, x2^2, x2 u, u^2, x1^3, x1^2 x2, ...
    assert exps[:7].tolist() == [
        [2, 0, 0], [1, 1, 0], [1, 0, 1], [0, 2, 0], [0, 1, 1], [0, 0, 2], [3, 0, 0],
    ]
    assert exps[-1].tolist() == [0, 0, 3]
    assert np.asarray(pnlss_tutorial_model["E"]).shape[1] == len(exps)


def test_degree_forms_equivalent():
    a = monomial_exponents(2, 1, (3, 2))
    b = monomial_exponents(2, 1, [2, 3])
    np.testing.assert_array_equal(a, b)
    assert len(monomial_exponents(2, 1, 2)) == 6


@pytest.mark.parametrize(
    "bad, match",
    [
        (np.array([[1, 0]]), "shape"),
        (np.array([[1, 0, 0]]), "degree >= 2"),
        (np.array([[2, 0, 0], [2, 0, 0]]), "duplicate"),
        (np.array([[-1, 3, 0]]), "non-negative"),
        (np.array([[1.5, 0.5, 0]]), "integers"),
    ],
)
def test_explicit_exponents_validated(bad, match):
    with pytest.raises(ValueError, match=match):
        monomial_exponents(2, 1, 2, bad)


def test_explicit_exponents_returned():
    e = np.array([[0, 2, 0], [1, 1, 1]])
    out = monomial_exponents(2, 1, 2, e)
    np.testing.assert_array_equal(out, e)
    assert out.dtype == np.int64


def test_bad_degree_and_structure():
    with pytest.raises(ValueError, match=">= 2"):
        monomial_exponents(2, 1, 1)
    with pytest.raises(ValueError, match="structure"):
        monomial_exponents(2, 1, 2, "bogus")
    with pytest.raises(ValueError, match="degree"):
        monomial_exponents(2, 1, "a")


@settings(max_examples=30, deadline=None)
@given(
    n_states=st.integers(1, 3),
    n_inputs=st.integers(0, 2),
    max_deg=st.integers(2, 4),
    structure=st.sampled_from(STRUCTURES),
    n_samples=st.integers(1, 7),
)
def test_shapes(n_states, n_inputs, max_deg, structure, n_samples):
    exps = monomial_exponents(n_states, n_inputs, range(2, max_deg + 1), structure)
    m = n_states + n_inputs
    assert exps.shape[1] == m
    assert np.all(exps.sum(axis=1) >= 2)
    assert np.all(exps.sum(axis=1) <= max_deg)
    assert len(np.unique(exps, axis=0)) == len(exps)
    S = np.random.default_rng(0).normal(size=(n_samples, m))
    assert evaluate_monomials(S, exps).shape == (n_samples, len(exps))
    assert monomial_jacobian(S, exps).shape == (n_samples, len(exps), m)


def test_evaluate_values():
    S = np.array([[2.0, 3.0, 5.0], [0.0, -1.0, 2.0]])
    exps = np.array([[2, 0, 0], [1, 1, 1], [0, 0, 3]])
    np.testing.assert_allclose(
        evaluate_monomials(S, exps), [[4.0, 30.0, 125.0], [0.0, 0.0, 8.0]]
    )


@pytest.mark.parametrize("structure", STRUCTURES)
def test_jacobian_finite_differences(structure):
    rng = np.random.default_rng(1)
    exps = monomial_exponents(2, 2, (2, 3, 4), structure)
    S = rng.normal(size=(5, 4))
    S[0, 1] = 0.0  # derivative at zero of x^1 terms must be exact
    jac = monomial_jacobian(S, exps)
    h = 1e-6
    for j in range(4):
        dS = np.zeros(4)
        dS[j] = h
        fd = (evaluate_monomials(S + dS, exps) - evaluate_monomials(S - dS, exps)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, j], fd, rtol=1e-6, atol=1e-8)


def test_terms_continue_along_tangent_planes_beyond_their_box():
    rng = np.random.default_rng(3)
    exponents = monomial_exponents(2, 1, (2, 3))
    box = np.array([[-0.2, -0.1, -0.5], [0.1, 0.3, 0.4]])
    model = StateSpaceModel(2, 1, 1, PolynomialTerms(2, 1, exponents, exponents, box))
    values = {name: 0.3 * rng.standard_normal(shape) for name, shape in model.blocks}
    values["A"] = 0.5 * np.eye(2)
    U = rng.standard_normal((60, 1))
    Y, X, diverged = model.simulate(model.pack(values), U, np.array([0, 60]),
                                    x0=np.array([0.1, -0.2]))
    assert not diverged
    S = np.hstack([X, U])
    # Points beyond the box on either side, in one variable and in several at once.
    outside = (S < box[0]) | (S > box[1])
    assert np.any(S < box[0]) and np.any(S > box[1]) and np.any(outside.sum(axis=1) > 1)
    nearest = np.clip(S, *box)
    slopes = monomial_jacobian(nearest, exponents)
    eta = evaluate_monomials(nearest, exponents) + np.einsum("tkj,tj->tk", slopes, S - nearest)
    expected = X @ values["C"].T + U @ values["D"].T + eta @ values["F"].T
    np.testing.assert_allclose(Y, expected, rtol=1e-12, atol=1e-14)
