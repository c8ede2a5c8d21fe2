"""UFL expressions of the phase-field model: small strain, plane strain or plane stress,
hybrid formulation (Ambati et al. 2015), AT2 crack surface density, spectral split.

Plane stress (``material["plane"] == "stress"``) condenses the out-of-plane strain out. In the
hybrid formulation the stress is g(phi) sigma_0(eps) with sigma_0 isotropic, so sigma_zz = 0 gives
eps_zz = -lambda / (lambda + 2 mu) tr(eps) whatever phi is: the in-plane stress is sigma_0 with the
plane-stress Lame constant lambda* = 2 lambda mu / (lambda + 2 mu), and the tensile energy of the
split is that of the three principal strains (eps_1, eps_2, eps_zz), so it agrees with the stress.
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


def _positive(x):
    return 0.5 * (x + abs(x))


def tensile_energy_density(u, material):
    """psi_0^+ = lambda/2 <tr eps>_+^2 + mu eps_+ : eps_+ with the principal strains in closed form
    (N/mm^2): of the 2x2 tensor in plane strain; in plane stress with eps_zz = -lambda/(lambda + 2 mu)
    tr(eps) as a third principal strain (module doc)."""
    lam, mu = material["lame_lambda"], material["lame_mu"]
    eps = strain(u)
    mean = 0.5 * ufl.tr(eps)
    radius = ufl.sqrt(0.25 * (eps[0, 0] - eps[1, 1]) ** 2 + eps[0, 1] ** 2)
    eps_1, eps_2 = mean + radius, mean - radius
    if material.get("plane", "strain") == "stress":
        eps_zz = -lam / (lam + 2.0 * mu) * ufl.tr(eps)
        trace = ufl.tr(eps) + eps_zz
        return 0.5 * lam * _positive(trace) ** 2 + mu * (_positive(eps_1) ** 2 + _positive(eps_2) ** 2 + _positive(eps_zz) ** 2)
    return 0.5 * lam * _positive(ufl.tr(eps)) ** 2 + mu * (_positive(eps_1) ** 2 + _positive(eps_2) ** 2)


def degradation(phase_field, residual_stiffness):
    """g(phi) = (1 - phi)^2 + k."""
    return (1.0 - phase_field) ** 2 + residual_stiffness


def equilibrium_form(u, v, phase_field, material):
    """a(u, v) = int g(phi) sigma_0(u) : eps(v) dx (bilinear in u, v)."""
    return degradation(phase_field, material["residual_stiffness"]) * ufl.inner(
        stress_undegraded(u, in_plane_lambda(material), material["lame_mu"]), strain(v)
    )


def phase_field_forms(p, q, history, material):
    """Bilinear and linear integrands of -Gc lc Lap(phi) + (Gc/lc) phi = 2 (1 - phi) H with
    zero flux: int Gc lc grad p . grad q + (Gc/lc + 2H) p q dx = int 2 H q dx."""
    Gc, lc = material["Gc"], material["lc"]
    a = Gc * lc * ufl.inner(ufl.grad(p), ufl.grad(q)) + (Gc / lc + 2.0 * history) * p * q
    L = 2.0 * history * q
    return a, L


def crack_surface_density(phase_field, material):
    """gamma(phi) Gc = Gc/(2 lc) (phi^2 + lc^2 |grad phi|^2): dissipated energy density."""
    Gc, lc = material["Gc"], material["lc"]
    return Gc / (2.0 * lc) * (phase_field**2 + lc**2 * ufl.inner(ufl.grad(phase_field), ufl.grad(phase_field)))
