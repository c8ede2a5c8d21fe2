"""UFL expressions of small-strain linear elasticity in 2-D: plane strain, or plane stress.

Plane stress (``material["plane"] == "stress"``) condenses the out-of-plane strain out. With a stress
g(phi) sigma_0(eps) and sigma_0 isotropic, sigma_zz = 0 gives eps_zz = -lambda / (lambda + 2 mu)
tr(eps) whatever phi is: the in-plane stress is sigma_0 with the plane-stress Lame constant
lambda* = 2 lambda mu / (lambda + 2 mu). The phase-field model (:mod:`ifenn.models`) degrades it and
splits the energy.
"""

from __future__ import annotations

import ufl


def strain(u):
    return ufl.sym(ufl.grad(u))


def in_plane_lambda(material) -> float:
    """The Lame constant of the in-plane stress: lambda (plane strain), 2 lambda mu / (lambda + 2 mu)
    (plane stress)."""
    lam, mu = material["lame_lambda"], material["lame_mu"]
    return 2.0 * lam * mu / (lam + 2.0 * mu) if material.get("plane", "strain") == "stress" else lam


def stress_undegraded(u, lame_lambda, lame_mu):
    """sigma_0 = lambda tr(eps) I + 2 mu eps (in-plane, N/mm^2; plane stress: lambda = lambda*)."""
    eps = strain(u)
    return lame_lambda * ufl.tr(eps) * ufl.Identity(len(u)) + 2.0 * lame_mu * eps


def positive(x):
    """<x>_+ = (x + |x|) / 2."""
    return 0.5 * (x + abs(x))


def principal_strains(eps):
    """The in-plane principal strains (eps_1 >= eps_2) of a 2x2 strain tensor, in closed form."""
    mean = 0.5 * ufl.tr(eps)
    radius = ufl.sqrt(0.25 * (eps[0, 0] - eps[1, 1]) ** 2 + eps[0, 1] ** 2)
    return mean + radius, mean - radius
