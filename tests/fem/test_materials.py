"""Constitutive models of parsolve.fem.materials: Hooke, Mazars damage, von Mises plasticity."""

from __future__ import annotations

import numpy as np
import pytest

from parsolve.fem.materials.base import elastic_matrix, lame
from parsolve.fem.materials.mazars import Mazars
from parsolve.fem.materials.von_mises import VonMises

HYPS = ["plane_stress", "plane_strain", "3d"]
NV = {"plane_stress": 3, "plane_strain": 3, "3d": 6}
E, NU = 30e3, 0.2
MZ = dict(eps_d0=1e-4, At=0.9, Bt=1e4, Ac=1.2, Bc=1.5e3, beta=1.06)


# --------------------------------------------------------------------------- helpers
def fd_tangent(mat, eps: np.ndarray, state: dict, rel: float = 1e-7) -> np.ndarray:
    """Central differences of ``mat.update`` (independent of the code under test)."""
    nq, nv = eps.shape
    h = rel * np.abs(eps).max(axis=1)
    T = np.empty((nq, nv, nv))
    for j in range(nv):  # loop over components, not points
        d = np.zeros_like(eps)
        d[:, j] = h
        sp = mat.update(eps + d, state)[0]
        sm = mat.update(eps - d, state)[0]
        T[:, :, j] = (sp - sm) / (2.0 * h[:, None])
    return T


def assert_tangent(mat, eps: np.ndarray, state: dict, tol: float = 1e-5) -> None:
    before = {k: v.copy() for k, v in state.items()}
    T = mat.update(eps, state)[1]
    Tfd = fd_tangent(mat, eps, state)
    err = np.linalg.norm(T - Tfd, axis=(1, 2)) / np.linalg.norm(Tfd, axis=(1, 2))
    assert err.max() < tol, err
    for k in state:  # update never modifies the converged state
        np.testing.assert_array_equal(state[k], before[k])


def voigt(T: np.ndarray, hyp: str) -> np.ndarray:
    """Symmetric tensors (m, 3, 3) -> Voigt strains with engineering shear."""
    if hyp == "3d":
        return np.stack([T[:, 0, 0], T[:, 1, 1], T[:, 2, 2],
                         2 * T[:, 1, 2], 2 * T[:, 0, 2], 2 * T[:, 0, 1]], axis=1)
    return np.stack([T[:, 0, 0], T[:, 1, 1], 2 * T[:, 0, 1]], axis=1)


def random_tensors(rng, eigs: np.ndarray, hyp: str) -> np.ndarray:
    """Symmetric tensors with prescribed eigenvalues (in-plane rotation in 2D)."""
    m = eigs.shape[0]
    if hyp == "3d":
        Q = np.linalg.qr(rng.normal(size=(m, 3, 3)))[0]
    else:
        a = rng.uniform(0, np.pi, m)
        Q = np.zeros((m, 3, 3))
        Q[:, 0, 0] = Q[:, 1, 1] = np.cos(a)
        Q[:, 0, 1], Q[:, 1, 0] = -np.sin(a), np.sin(a)
        Q[:, 2, 2] = 1.0
    return np.einsum("mij,mj,mkj->mik", Q, eigs, Q)


def strains_from_effective_stress(sig_eigs: np.ndarray, hyp: str, rng) -> np.ndarray:
    """Voigt strains whose effective stress C eps has the given principal values."""
    nv = NV[hyp]
    if hyp == "3d":
        S = voigt(random_tensors(rng, sig_eigs, hyp), hyp)
        S[:, 3:] /= 2  # stress Voigt has plain shear
    else:
        S = voigt(random_tensors(rng, np.c_[sig_eigs[:, :2], np.zeros(len(sig_eigs))], hyp), hyp)
        S[:, 2] /= 2
    C = elastic_matrix(E, NU, hyp)
    assert S.shape[1] == nv
    return np.linalg.solve(C, S.T).T


def Dt_closed(eps, eps_d0, At, Bt):
    """Textbook D_t(kappa) for the uniaxial closed form."""
    k = np.maximum(eps, eps_d0)
    return 1 - eps_d0 * (1 - At) / k - At * np.exp(-Bt * (k - eps_d0))


# --------------------------------------------------------------------------- elastic_matrix
def test_elastic_matrix_known_values():
    E_, nu = 210e3, 0.3
    ps = E_ / (1 - nu**2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    np.testing.assert_allclose(elastic_matrix(E_, nu, "plane_stress"), ps, rtol=1e-14)
    c = E_ / ((1 + nu) * (1 - 2 * nu))
    pe = c * np.array([[1 - nu, nu, 0], [nu, 1 - nu, 0], [0, 0, (1 - 2 * nu) / 2]])
    np.testing.assert_allclose(elastic_matrix(E_, nu, "plane_strain"), pe, rtol=1e-14)
    C3 = elastic_matrix(E_, nu, "3d")
    S = np.zeros((6, 6))  # compliance with engineering shear
    S[:3, :3] = -nu / E_
    S[[0, 1, 2], [0, 1, 2]] = 1 / E_
    S[[3, 4, 5], [3, 4, 5]] = 2 * (1 + nu) / E_
    np.testing.assert_allclose(C3 @ S, np.eye(6), atol=1e-13)
    np.testing.assert_allclose(C3[np.ix_([0, 1, 5], [0, 1, 5])], pe, rtol=1e-14)
    lam, mu = lame(E_, nu)
    assert C3[0, 1] == pytest.approx(lam) and C3[5, 5] == pytest.approx(mu)
    # plane stress = 3D with sigma_zz = 0 condensed out
    Ci = np.linalg.inv(S[np.ix_([0, 1, 5], [0, 1, 5])])
    np.testing.assert_allclose(Ci, ps, rtol=1e-12)


@pytest.mark.parametrize("args", [(1.0, 0.3, "2d"), (-1.0, 0.3, "3d"), (1.0, 0.5, "3d")])
def test_elastic_matrix_rejects(args):
    with pytest.raises(ValueError):
        elastic_matrix(*args)


# --------------------------------------------------------------------------- Mazars
def test_mazars_uniaxial_closed_form():
    eps_d0, At, Bt = 1e-4, 0.8, 1.2e4
    m = Mazars(E, 0.0, "plane_stress", eps_d0, At, Bt, 1.3, 1e3)
    e = np.linspace(0, 1e-3, 201)
    eps = np.c_[e, np.zeros_like(e), np.zeros_like(e)]
    sig, T, st = m.update(eps, m.init_state(e.size))
    D = np.where(e <= eps_d0, 0.0, Dt_closed(e, eps_d0, At, Bt))
    np.testing.assert_allclose(sig[:, 0], E * e * (1 - D), rtol=1e-13, atol=0)
    np.testing.assert_array_equal(sig[e <= eps_d0, 0], E * e[e <= eps_d0])
    np.testing.assert_array_equal(sig[:, 1:], 0.0)
    np.testing.assert_allclose(st["D"], D, rtol=1e-13, atol=1e-16)
    # analytic tangent: d/de [E e (1 - D_t(e))]
    load = e > eps_d0
    el = e[load]
    dD = eps_d0 * (1 - At) / el**2 + At * Bt * np.exp(-Bt * (el - eps_d0))
    np.testing.assert_allclose(T[load, 0, 0], E * (1 - D[load] - el * dD), rtol=1e-12)
    np.testing.assert_array_equal(T[~load], np.broadcast_to(m.C, T[~load].shape))
    # incremental path gives the same curve (history only through kappa)
    state = m.init_state(1)
    for i, ei in enumerate(e):
        s, _, state = m.update(np.array([[ei, 0.0, 0.0]]), state)
        assert s[0, 0] == pytest.approx(sig[i, 0], rel=1e-14, abs=1e-14)


def test_mazars_irreversibility():
    m = Mazars(E, 0.0, "plane_stress", **MZ)
    one = lambda x: np.array([[x, 0.0, 0.0]])  # noqa: E731
    e1 = 3e-4
    _, _, s1 = m.update(one(e1), m.init_state(1))
    D1 = s1["D"][0]
    assert 0 < D1 < 1
    sig, T, s0 = m.update(one(0.0), s1)
    np.testing.assert_array_equal(sig, 0.0)
    assert s0["D"][0] == D1 and s0["kappa"][0] == s1["kappa"][0]
    np.testing.assert_allclose(T[0], (1 - D1) * m.C, rtol=1e-15)
    state = s0
    for x in np.linspace(0, e1, 7)[1:]:  # elastic reload with the damaged stiffness
        sig, T, state = m.update(one(x), state)
        assert sig[0, 0] == pytest.approx((1 - D1) * E * x, rel=1e-14)
        assert state["D"][0] == D1
        np.testing.assert_allclose(T[0], (1 - D1) * m.C, rtol=1e-15)
    _, _, s2 = m.update(one(1.2 * e1), state)
    assert s2["D"][0] > D1
    # compression after tension: D never decreases
    _, _, s3 = m.update(one(-5 * e1), s2)
    assert s3["D"][0] == s2["D"][0]


@pytest.mark.parametrize("hyp", HYPS)
def test_mazars_bounded_damage(hyp):
    m = Mazars(E, NU, hyp, 1e-4, 1.2, 1e4, 1.2, 1e3)  # A > 1: formula exceeds 1 at large kappa
    eps = np.zeros((1, NV[hyp]))
    eps[0, 0] = 1.0
    sig, T, st = m.update(eps, m.init_state(1))
    assert st["D"][0] == 1.0
    np.testing.assert_array_equal(sig, 0.0)
    np.testing.assert_array_equal(T, 0.0)


@pytest.mark.parametrize("hyp", HYPS)
def test_mazars_tangent_elastic(hyp):
    rng = np.random.default_rng(1)
    m = Mazars(E, NU, hyp, **MZ)
    eps = rng.normal(size=(20, NV[hyp]))
    eq = m._split(eps)[0]  # may be 0 (all principal strains negative): then any scale is elastic
    eps *= (0.7 * MZ["eps_d0"] / np.maximum(eq, 1e-2 * np.abs(eps).max(1)))[:, None]
    st0 = m.init_state(20)
    sig, T, st = m.update(eps, st0)
    np.testing.assert_allclose(sig, eps @ m.C, rtol=1e-14)
    np.testing.assert_array_equal(st["D"], 0.0)
    np.testing.assert_array_equal(T, np.broadcast_to(m.C, T.shape))
    assert_tangent(m, eps, st0)


def _not_near_kinks(m, eps, margin=1e-3):
    e = m._principal(eps)
    st = m.lam * e.sum(1)[:, None] + 2 * m.mu * e
    if m.hypothesis == "plane_stress":
        st = st[:, :2]  # sigma~_zz is identically 0: no kink
    if m.hypothesis == "plane_strain":
        e = e[:, :2]  # eps_zz is identically 0: no kink
    scale = np.abs(e).max(1)
    return (np.abs(e).min(1) > margin * scale) & (np.abs(st).min(1) > margin * m.E * scale)


@pytest.mark.parametrize("hyp", HYPS)
def test_mazars_tangent_loading_mixed(hyp):
    """alpha_t and alpha_c both in (0, 1): finite-difference tangent of the loading branch."""
    rng = np.random.default_rng(2)
    m = Mazars(E, NU, hyp, **MZ)
    eps = rng.normal(size=(200, NV[hyp]))
    eq, at, pure = m._split(eps)
    eps, eq = eps[eq > 0], eq[eq > 0]
    eps *= (rng.uniform(1.5, 6.0, len(eq)) * MZ["eps_d0"] / eq)[:, None]
    eq, at, pure = m._split(eps)
    keep = ~pure & _not_near_kinks(m, eps) & (at > 0.05) & (at < 0.95)
    assert keep.sum() >= 10
    eps = eps[keep]
    st0 = m.init_state(len(eps))
    _, _, st = m.update(eps, st0)
    assert np.all(st["D"] > 0)
    assert_tangent(m, eps, st0)
    # from an already damaged state, loading further (kappa grows from kappa_old > eps_d0)
    assert_tangent(m, 1.3 * eps, st)


@pytest.mark.parametrize("hyp", HYPS)
def test_mazars_tangent_loading_pure(hyp):
    """Pure tension (alpha_t = 1) and pure compression (alpha_c = 1): analytic tangent."""
    rng = np.random.default_rng(3)
    m = Mazars(E, NU, hyp, **MZ)
    n = 20
    s = E * MZ["eps_d0"] * rng.uniform(1.5, 5.0, n)
    tens = strains_from_effective_stress(s[:, None] * rng.uniform(0.1, 1.0, (n, 3)), hyp, rng)
    comp = strains_from_effective_stress(-10 * s[:, None] * np.c_[np.ones(n), rng.uniform(
        0.01, 0.1, (n, 2))], hyp, rng)
    for eps, at_exp in ((tens, 1.0), (comp, 0.0)):
        eps *= (rng.uniform(1.5, 5.0, n) * MZ["eps_d0"] / m._split(eps)[0])[:, None]
        eq, at, pure = m._split(eps)
        assert np.all(pure) and np.all(at == at_exp)
        st0 = m.init_state(n)
        assert_tangent(m, eps, st0)
        _, _, st = m.update(eps, st0)
        assert_tangent(m, 1.2 * eps, st)
    if hyp != "plane_stress":  # positive principal strains: alpha_t = 1 by the strain rule
        eps = voigt(random_tensors(rng, rng.uniform(1.5e-4, 5e-4, (n, 3)), hyp), hyp)
        assert np.all(m._split(eps)[1] == 1.0)
        assert_tangent(m, eps, m.init_state(n))


@pytest.mark.parametrize("hyp", HYPS)
def test_mazars_tangent_unloading(hyp):
    rng = np.random.default_rng(4)
    m = Mazars(E, NU, hyp, **MZ)
    n = 30
    s = E * MZ["eps_d0"] * rng.uniform(2.0, 4.0, n)
    eps1 = strains_from_effective_stress(s[:, None] * rng.uniform(0.2, 1.0, (n, 3)), hyp, rng)
    _, _, st = m.update(eps1, m.init_state(n))
    assert np.all(st["D"] > 0)
    eps = rng.normal(size=(n, NV[hyp]))
    eq = np.maximum(m._split(eps)[0], 1e-2 * np.abs(eps).max(1))
    eps *= (rng.uniform(0.1, 0.8, n) * st["kappa"] / eq)[:, None]
    sig, T, st2 = m.update(eps, st)
    np.testing.assert_array_equal(st2["D"], st["D"])
    np.testing.assert_array_equal(st2["kappa"], st["kappa"])
    np.testing.assert_allclose(T, (1 - st["D"])[:, None, None] * m.C, rtol=1e-14)
    np.testing.assert_allclose(sig, (1 - st["D"])[:, None] * (eps @ m.C), rtol=1e-14)
    assert_tangent(m, eps, st)


def test_mazars_plane_stress_out_of_plane():
    """Plane stress uses eps_zz = -nu/(1-nu)(exx+eyy): sigma~_zz = 0 and uniaxial alpha_t = 1."""
    m = Mazars(E, NU, "plane_stress", **MZ)
    e = 3e-4
    eps = np.array([[e, -NU * e, 0.0]])  # uniaxial stress
    eq, at, pure = m._split(eps)
    assert at[0] == 1.0 and pure[0]
    assert eq[0] == pytest.approx(e, rel=1e-14)
    sig = m.update(eps, m.init_state(1))[0]
    assert sig[0, 0] == pytest.approx(E * e * (1 - Dt_closed(e, 1e-4, 0.9, 1e4)), rel=1e-12)
    assert abs(sig[0, 1]) < 1e-12 * abs(sig[0, 0])
    mp = Mazars(E, NU, "plane_strain", **MZ)
    eps = np.array([[1e-5, 2e-5, 0.0]])
    _, _, st = mp.update(eps, mp.init_state(1))
    lam = lame(E, NU)[0]
    assert mp.out_of_plane_stress(eps, st)[0] == pytest.approx(lam * 3e-5)


# --------------------------------------------------------------------------- von Mises
EV, NUV, SY, HV = 200e3, 0.3, 250.0, 10e3


def von_mises_q(sig6: np.ndarray) -> np.ndarray:
    s = sig6.copy()
    s[:, :3] -= s[:, :3].mean(1, keepdims=True)
    return np.sqrt(1.5 * ((s[:, :3] ** 2).sum(1) + 2 * (s[:, 3:] ** 2).sum(1)))


def stress6(mat, eps, sig, st):
    if mat.hypothesis == "3d":
        return sig
    out = np.zeros((len(sig), 6))
    out[:, [0, 1, 5]] = sig
    out[:, 2] = mat.out_of_plane_stress(eps, st)
    return out


def test_von_mises_rejects_plane_stress():
    with pytest.raises(ValueError):
        VonMises(EV, NUV, "plane_stress", SY, HV)


def test_von_mises_uniaxial_bilinear():
    m = VonMises(EV, NUV, "3d", SY, HV)
    state = m.init_state(1)
    lat = 0.0
    ey = SY / EV
    for exx in np.linspace(0, 8 * ey, 41)[1:]:
        # uniaxial stress: Newton on the lateral strain (eyy = ezz) with the tangent
        for _ in range(20):
            eps = np.array([[exx, lat, lat, 0, 0, 0]])
            sig, T, new = m.update(eps, state)
            if abs(sig[0, 1]) < 1e-10 * SY:
                break
            lat -= sig[0, 1] / (T[0, 1, 1] + T[0, 1, 2])
        else:
            pytest.fail("lateral Newton did not converge")
        state = new
        exact = EV * exx if exx <= ey else SY + EV * HV / (EV + HV) * (exx - ey)
        assert sig[0, 0] == pytest.approx(exact, rel=1e-10)
        np.testing.assert_allclose(sig[0, 1:], 0.0, atol=1e-9 * SY)
        if exx > ey:
            # p equals the axial plastic strain, and the uniaxial tangent is E H/(E+H)
            assert state["p"][0] == pytest.approx(state["eps_p"][0, 0], rel=1e-10)
            Tc = T[0, :3, :3]
            slope = Tc[0, 0] - Tc[0, 1:] @ np.linalg.solve(Tc[1:, 1:], Tc[1:, 0])
            assert slope == pytest.approx(EV * HV / (EV + HV), rel=1e-10)


@pytest.mark.parametrize("hyp", ["plane_strain", "3d"])
def test_von_mises_on_yield_surface(hyp):
    rng = np.random.default_rng(5)
    m = VonMises(EV, NUV, hyp, SY, HV)
    n = 50
    eps = rng.normal(size=(n, NV[hyp])) * 5e-3
    sig, _, st = m.update(eps, m.init_state(n))
    assert np.all(st["p"] > 0)
    for eps_, st_ in ((eps, m.init_state(n)), (eps * 1.7 + 1e-3, st)):
        sig, _, new = m.update(eps_, st_)
        q = von_mises_q(stress6(m, eps_, sig, new))
        R = SY + HV * new["p"]
        assert np.all(new["p"] > st_["p"])
        np.testing.assert_allclose(q, R, rtol=1e-10)
        # plastic strain is deviatoric
        ep = new["eps_p"]
        assert np.allclose(ep[:, 0] + ep[:, 1] + ep[:, 2], 0.0, atol=1e-15)


def test_von_mises_volumetric_elastic():
    m = VonMises(EV, NUV, "3d", SY, HV)
    a = np.array([1e-3, 1e-1, -1e-1])
    eps = a[:, None] * np.array([1, 1, 1, 0, 0, 0.0])
    sig, T, st = m.update(eps, m.init_state(3))
    K = EV / (3 * (1 - 2 * NUV))
    np.testing.assert_allclose(sig[:, :3], 3 * K * a[:, None] * np.ones((1, 3)), rtol=1e-13)
    np.testing.assert_allclose(sig[:, 3:], 0.0, atol=1e-9)
    np.testing.assert_array_equal(st["p"], 0.0)
    np.testing.assert_array_equal(st["eps_p"], 0.0)
    np.testing.assert_array_equal(T, np.broadcast_to(m.C, T.shape))


@pytest.mark.parametrize("hyp", ["plane_strain", "3d"])
def test_von_mises_tangents(hyp):
    rng = np.random.default_rng(6)
    m = VonMises(EV, NUV, hyp, SY, HV)
    n = 40
    nv = NV[hyp]
    # elastic
    eps = rng.normal(size=(n, nv)) * 1e-4
    st0 = m.init_state(n)
    sig, T, st = m.update(eps, st0)
    assert np.all(st["p"] == 0)
    np.testing.assert_array_equal(T, np.broadcast_to(m.C, T.shape))
    assert_tangent(m, eps, st0)
    # plastic loading from virgin and from a plastic state
    eps = rng.normal(size=(n, nv)) * 5e-3
    _, _, st = m.update(eps, st0)
    eps, st0 = eps[st["p"] > 0], m.init_state(int((st["p"] > 0).sum()))
    _, _, st = m.update(eps, st0)
    n = len(eps)
    assert np.all(st["p"] > 0)
    assert_tangent(m, eps, st0)
    eps2 = 1.5 * eps + rng.normal(size=(n, nv)) * 1e-3
    _, _, st2 = m.update(eps2, st)
    assert np.all(st2["p"] > st["p"])
    assert_tangent(m, eps2, st)
    # elastic unloading from the plastic state: halve the elastic strain
    ep = st["eps_p"] if hyp == "3d" else st["eps_p"][:, [0, 1, 3]]
    eps3 = ep + 0.5 * (eps - ep)
    sig3, T3, st3 = m.update(eps3, st)
    np.testing.assert_array_equal(st3["p"], st["p"])
    np.testing.assert_array_equal(T3, np.broadcast_to(m.C, T3.shape))
    assert_tangent(m, eps3, st)
