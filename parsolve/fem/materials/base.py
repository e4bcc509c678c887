"""Material interface and Hooke's law in Voigt notation.

Conventions shared by every model of this package:

* Voigt order 2D ``(xx, yy, xy)``, 3D ``(xx, yy, zz, yz, xz, xy)``;
* strains carry the ENGINEERING shear ``gamma = 2 eps``, stresses the plain components, so
  that ``sigma = C @ eps`` and the strain energy is ``sigma . eps / 2``;
* hypotheses ``"plane_stress"`` (3 components, sigma_zz = 0), ``"plane_strain"``
  (3 components, eps_zz = 0, sigma_zz available from the model if needed), ``"3d"``
  (6 components) and ``"axisymmetric"`` (4 components (rr, zz, rz, θθ), x = r, y = z).

A model is evaluated on all quadrature points at once: ``eps`` has shape ``(nq, nvoigt)``.
``update`` is a pure function of the total strain and of the converged state at the start of
the step: it never modifies ``state`` and returns a new (trial) state, so that a Newton loop can
call it any number of times and commit the state only once the step has converged.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

#: Number of Voigt components of each modelling hypothesis.
HYPOTHESES: dict[str, int] = {"plane_stress": 3, "plane_strain": 3, "3d": 6, "axisymmetric": 4}
#: The axisymmetric components (rr, zz, rz, θθ) in the 3D Voigt order (xx, yy, zz, yz, xz, xy)
#: (x = r, y = z, z = θ; the rθ and zθ shears vanish).
AXISYMMETRIC_COLS = [0, 1, 5, 2]


def nvoigt_of(hypothesis: str) -> int:
    """Number of Voigt components of ``hypothesis``; ValueError if it is unknown."""
    try:
        return HYPOTHESES[hypothesis]
    except KeyError:
        raise ValueError(
            f"unknown hypothesis {hypothesis!r}; expected one of {sorted(HYPOTHESES)}"
        ) from None


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lamé coefficients ``(lambda, mu)`` of an isotropic material."""
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))


#: A parameter a model needs (no default).
REQUIRED = None
#: The rules a parameter obeys: name -> (test, what the message says when it fails).
RULES = {
    "positive": (lambda v: v > 0.0, "must be positive"),
    "non_negative": (lambda v: v >= 0.0, "must not be negative"),
    "poisson": (lambda v: -1.0 < v < 0.5, "must lie in (-1, 0.5)"),
    "any": (lambda v: True, ""),
}
#: Hooke's parameters, shared by every model.
ELASTIC_PARAMETERS = {"E": (REQUIRED, "positive"), "nu": (REQUIRED, "poisson")}


def parameter_problem(parameters: dict, values: dict) -> tuple[str, str] | None:
    """(name, message) of the first value breaking its rule (``parameters``: name ->
    (default, rule)), else None. The one place the rules are checked: the scene names the key
    with it, the models' constructors raise it."""
    for name, (_, rule) in parameters.items():
        if name not in values:
            continue
        test, message = RULES[rule]
        value = values[name]
        if not np.isfinite(value) or not test(value):
            return name, message
    return None


def check_parameters(parameters: dict, values: dict) -> None:
    """ValueError naming the first value that breaks its rule."""
    problem = parameter_problem(parameters, values)
    if problem is not None:
        name, message = problem
        raise ValueError(f"{name} {message}, got {name}={values[name]}")


def check_elastic_constants(E: float, nu: float) -> None:
    """ValueError unless ``E > 0`` and ``-1 < nu < 1/2`` (positive-definite isotropic Hooke)."""
    check_parameters(ELASTIC_PARAMETERS, {"E": E, "nu": nu})


def elastic_matrix(E: float, nu: float, hypothesis: str) -> np.ndarray:
    """Isotropic Hooke matrix ``(nvoigt, nvoigt)`` in Voigt notation with engineering shear.

    plane stress: ``E/(1-nu^2) [[1, nu, 0], [nu, 1, 0], [0, 0, (1-nu)/2]]``;
    plane strain: ``E/((1+nu)(1-2nu)) [[1-nu, nu, 0], [nu, 1-nu, 0], [0, 0, (1-2nu)/2]]``;
    3d: ``lambda 1 (x) 1 + 2 mu I`` with ``mu`` (not ``2 mu``) on the shear diagonal;
    axisymmetric: the 3D matrix on (rr, zz, rz, θθ) = 3D rows (xx, yy, xy, zz).
    """
    nv = nvoigt_of(hypothesis)
    check_elastic_constants(E, nu)
    if hypothesis == "plane_stress":
        c = E / (1.0 - nu * nu)
        return c * np.array([[1.0, nu, 0.0], [nu, 1.0, 0.0], [0.0, 0.0, 0.5 * (1.0 - nu)]])
    lam, mu = lame(E, nu)
    if hypothesis == "axisymmetric":
        return elastic_matrix(E, nu, "3d")[np.ix_(AXISYMMETRIC_COLS, AXISYMMETRIC_COLS)]
    C = np.zeros((nv, nv))
    if hypothesis == "plane_strain":
        C[:2, :2] = lam
        C[0, 0] = C[1, 1] = lam + 2.0 * mu
        C[2, 2] = mu
        return C
    C[:3, :3] = lam
    C[[0, 1, 2], [0, 1, 2]] = lam + 2.0 * mu
    C[[3, 4, 5], [3, 4, 5]] = mu
    return C


def check_hypothesis(model: type, hypothesis: str) -> None:
    """ValueError unless ``model`` is written for ``hypothesis``."""
    if hypothesis not in model.HYPOTHESES:
        allowed = ", ".join(repr(h) for h in model.HYPOTHESES)
        raise ValueError(f"{model.__name__} supports {allowed}, not {hypothesis!r}")


class Material(ABC):
    """Constitutive model evaluated at ``nq`` points at once.

    Subclasses set ``hypothesis``, ``nvoigt``, ``E``, ``nu`` and ``C`` (the undamaged elastic
    matrix) through ``Material.__init__`` and implement ``init_state`` and ``update``.
    """

    #: name -> (default or REQUIRED, rule of ``RULES``): what the scene reads and checks
    PARAMETERS: dict = ELASTIC_PARAMETERS
    #: the hypotheses the model is written for
    HYPOTHESES: tuple[str, ...] = tuple(HYPOTHESES)
    hypothesis: str
    nvoigt: int
    E: float
    nu: float
    C: np.ndarray

    def __init__(self, E: float, nu: float, hypothesis: str):
        check_hypothesis(type(self), hypothesis)
        self.hypothesis = hypothesis
        self.nvoigt = nvoigt_of(hypothesis)
        self.E = float(E)
        self.nu = float(nu)
        self.C = elastic_matrix(self.E, self.nu, hypothesis)

    @abstractmethod
    def init_state(self, nq: int) -> dict[str, np.ndarray]:
        """History variables of ``nq`` virgin points (arrays with ``nq`` rows)."""

    @abstractmethod
    def update(
        self, eps: np.ndarray, state: dict[str, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Stress ``(nq, nvoigt)``, consistent tangent ``dsigma/deps`` ``(nq, nvoigt, nvoigt)``
        and the trial state reached at total strain ``eps`` ``(nq, nvoigt)`` from the converged
        ``state`` (which is left untouched)."""

    def _as_strain(self, eps: np.ndarray) -> np.ndarray:
        """``eps`` as a float array ``(nq, nvoigt)``; ValueError on a wrong shape."""
        eps = np.asarray(eps, dtype=float)
        if eps.ndim != 2 or eps.shape[1] != self.nvoigt:
            raise ValueError(
                f"strain must have shape (nq, {self.nvoigt}) for {self.hypothesis!r}, "
                f"got {eps.shape}"
            )
        return eps

    def elastic_tangent(self, nq: int) -> np.ndarray:
        """The undamaged elastic matrix repeated on ``nq`` points (a writable copy)."""
        return np.repeat(self.C[None], nq, axis=0)
