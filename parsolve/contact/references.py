"""Analytic references for the contact and friction tests (derivations in docs/contact.md).

* Hertz, cylinder on a plane (2D plane strain) and sphere on a plane (3D) — Johnson,
  *Contact Mechanics* (1985), §4.2 eqs. (4.22)-(4.23) and (4.45)-(4.46).
* A block pressed on a rigid rough plane and pulled tangentially: resultants and the
  homogeneous simple-shear field (stick and uniform slip).
* The V-wedge: a homogeneous field with a stick face and a slip face side by side, exact in
  any P1/Q1 mesh whose nodes include the wedge's apex.

Elastic constants are Lamé's (lam, G) of the *2D law used*: plane strain takes the 3D lam;
plane stress takes lam* = 2 lam G / (lam + 2 G).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def effective_modulus(e1: float, nu1: float, e2: float = math.inf, nu2: float = 0.0) -> float:
    """Contact modulus E* with 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2 (E2 = inf: rigid)."""
    inv = (1.0 - nu1**2) / e1 + (0.0 if math.isinf(e2) else (1.0 - nu2**2) / e2)
    return 1.0 / inv


@dataclass(frozen=True)
class Hertz:
    """Contact half-width/radius a, peak pressure p0, approach delta (nan where undefined)."""

    a: float
    p0: float
    delta: float

    def pressure(self, r: np.ndarray) -> np.ndarray:
        """p(r) = p0 sqrt(1 - r^2/a^2) inside the contact, 0 outside."""
        r = np.asarray(r, dtype=float)
        return self.p0 * np.sqrt(np.clip(1.0 - (r / self.a) ** 2, 0.0, None))


def hertz_cylinder(load: float, radius: float, e_star: float) -> Hertz:
    """Cylinder on a plane, plane strain, load P per unit length: a = sqrt(4 P R / (pi E*)),
    p0 = 2 P / (pi a). The approach of two 2D bodies depends on their size: nan here."""
    a = math.sqrt(4.0 * load * radius / (math.pi * e_star))
    return Hertz(a, 2.0 * load / (math.pi * a), math.nan)


def hertz_sphere(load: float, radius: float, e_star: float) -> Hertz:
    """Sphere on a plane, load P: a = (3 P R / (4 E*))^(1/3), p0 = 3 P / (2 pi a^2),
    approach delta = a^2 / R."""
    a = (3.0 * load * radius / (4.0 * e_star)) ** (1.0 / 3.0)
    return Hertz(a, 3.0 * load / (2.0 * math.pi * a**2), a**2 / radius)


# ----------------------------------------------------------------------------- block on a plane


@dataclass(frozen=True)
class BlockResultants:
    normal: float      # N (total normal force, compressive)
    tangential: float  # T (total friction force transmitted, |T| <= mu N)
    sliding: bool      # the applied tangential load reached mu N


def block_on_plane(normal_force: float, tangential_load: float, mu: float) -> BlockResultants:
    """A body pressed by N on a rigid rough plane and pulled by Q (load, or the reaction of a
    prescribed tangential displacement): stick while |Q| < mu N with T = Q; at |Q| >= mu N every
    contact node slips and T = sign(Q) mu N exactly (sum of nodal mu Rn, whatever their
    distribution). Under load control |Q| > mu N has no static solution."""
    limit = mu * normal_force
    sliding = abs(tangential_load) >= limit
    t = math.copysign(limit, tangential_load) if sliding else tangential_load
    return BlockResultants(normal_force, t, sliding)


@dataclass(frozen=True)
class ShearedBlock:
    """Homogeneous state of a block of height H on the rigid plane y = 0 (2D, plane law of
    (lam, G)): top pressed by p and moved tangentially by ``shift``; lateral faces loaded by
    the homogeneous stress (traction sigma . n, see ``stress``)."""

    tau: float       # shear stress sigma_xy = friction traction on the block (opposing slip)
    slip: float      # uniform slip of the bottom (0 in stick)
    sliding: bool
    gx: float        # u(x, y) = (slip + gx y, gy y)
    gy: float
    stress: np.ndarray  # (2, 2)

    def displacement(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return np.column_stack([self.slip + self.gx * x[:, 1], self.gy * x[:, 1]])


def sheared_block(lam: float, g: float, p: float, mu: float, height: float,
                  shift: float) -> ShearedBlock:
    """u = (d + gx y, gy y): eps_yy = gy, gamma_xy = gx, eps_xx = 0, so sigma_yy = (lam + 2G) gy
    = -p, sigma_xx = lam gy, sigma_xy = G gx. Stick (d = 0): gx = shift / H while
    G |gx| < mu p; beyond, slip: |sigma_xy| = mu p, d = shift - H sigma_xy / G."""
    gy = -p / (lam + 2.0 * g)
    tau = g * shift / height
    sliding = abs(tau) >= mu * p
    if sliding:
        tau = math.copysign(mu * p, shift)
    gx = tau / g
    slip = shift - gx * height
    stress = np.array([[lam * gy, tau], [tau, -p]])
    return ShearedBlock(tau, slip, sliding, gx, gy, stress)


# ----------------------------------------------------------------------------- V-wedge stick-slip


@dataclass(frozen=True)
class WedgeStickSlip:
    """Exact stick/slip field on a rigid V-wedge (see :func:`wedge_stick_slip`)."""

    beta: float
    kappa: float
    mu: float                 # the friction coefficient for which face 2 slides
    normal1: np.ndarray       # (2,) master normal of face 1 (y = 0, x >= 0)
    normal2: np.ndarray       # (2,) master normal of face 2 (from the apex along e2)
    e2: np.ndarray            # (2,) direction of face 2 from the apex
    tangent2: np.ndarray      # (2,) t2 = (-n2_y, n2_x) = e2 (pairing convention)
    stress: np.ndarray        # (2, 2) homogeneous stress
    face1: tuple[float, float]  # (Rn, Rt) tractions on the block on face 1, Rt along t1
    face2: tuple[float, float]  # same on face 2, Rt along t2

    def displacement(self, x: np.ndarray) -> np.ndarray:
        """u(x) = kappa y e2 (n, 2): zero on face 1, tangential on face 2."""
        x = np.asarray(x, dtype=float)
        return self.kappa * x[:, 1:2] * self.e2[None, :]

    def traction(self, normal: np.ndarray) -> np.ndarray:
        """Traction sigma . n (m, 2) on boundary facets of outward normal n (m, 2)."""
        return np.asarray(normal, dtype=float) @ self.stress.T


def wedge_stick_slip(lam: float, g: float, beta: float, kappa: float = -1e-3) -> WedgeStickSlip:
    """A block resting on a rigid V-wedge: face 1 is y = 0 (x >= 0), face 2 leaves the apex
    (origin) along e2 = (-cos b, sin b), 0 < b < pi/2; the block lies above both faces.

    The homogeneous field u = kappa y e2 (kappa < 0) vanishes on face 1 (stick), is tangent to
    face 2 (closed gap, slip kappa y along e2) and gives the uniform stress
    sigma_xx = lam kappa sin b, sigma_yy = (lam + 2G) kappa sin b, sigma_xy = -G kappa cos b.
    Tractions on the block (pressure Rn > 0, friction Rt along the master tangent t = (-n_y, n_x):
    t1 = (-1, 0), t2 = e2; the slip of face 2 along t2 is kappa y < 0, i.e. s = -1):
      face 1: Rn = -(lam + 2G) kappa sin b, Rt = -G kappa cos b  (ratio G cot b / (lam + 2G))
      face 2: Rn = -lam kappa sin b,        Rt = -G kappa cos b  (ratio G cot b / lam)
    With mu = G cot(b) / lam face 2 slides at the cone, friction opposing the slip, and face 1
    sticks strictly inside it. The rest of the boundary carries the traction sigma . n.
    """
    if not 0.0 < beta < math.pi / 2:
        raise ValueError("beta must lie in (0, pi/2)")
    if not kappa < 0.0:
        raise ValueError("kappa must be negative (compression on both faces)")
    if not lam > 0.0:
        raise ValueError("the wedge solution needs lam > 0 (nu > 0)")
    sb, cb = math.sin(beta), math.cos(beta)
    stress = np.array([[lam * kappa * sb, -g * kappa * cb], [-g * kappa * cb, (lam + 2 * g) * kappa * sb]])
    n1 = np.array([0.0, 1.0])
    n2 = np.array([sb, cb])
    e2 = np.array([-cb, sb])

    def face(n):
        # traction on the block: t = sigma . (-n); pressure n . t, friction along (-n_y, n_x)
        t = -stress @ n
        return float(n @ t), float(np.array([-n[1], n[0]]) @ t)

    return WedgeStickSlip(beta, kappa, g * cb / (lam * sb), n1, n2, e2,
                          np.array([-n2[1], n2[0]]), stress, face(n1), face(n2))
