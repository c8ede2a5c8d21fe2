"""UFL expressions of the phase-field model: plane strain, small strain,
hybrid formulation (Ambati et al. 2015), AT2 crack surface density, spectral split."""

from __future__ import annotations

import ufl


def strain(u):
    return ufl.sym(ufl.grad(u))


def stress_undegraded(u, lame_lambda, lame_mu):
    """sigma_0 = lambda tr(eps) I + 2 mu eps (plane strain, N/mm^2)."""
    eps = strain(u)
    return lame_lambda * ufl.tr(eps) * ufl.Identity(len(u)) + 2.0 * lame_mu * eps


def _positive(x):
    return 0.5 * (x + abs(x))


def tensile_energy_density(u, lame_lambda, lame_mu):
    """psi_0^+ = lambda/2 <tr eps>_+^2 + mu eps_+ : eps_+ with the principal strains of the
    2x2 plane-strain tensor in closed form (N/mm^2)."""
    eps = strain(u)
    mean = 0.5 * ufl.tr(eps)
    radius = ufl.sqrt(0.25 * (eps[0, 0] - eps[1, 1]) ** 2 + eps[0, 1] ** 2)
    eps_1, eps_2 = mean + radius, mean - radius
    return 0.5 * lame_lambda * _positive(ufl.tr(eps)) ** 2 + lame_mu * (_positive(eps_1) ** 2 + _positive(eps_2) ** 2)


def degradation(phase_field, residual_stiffness):
    """g(phi) = (1 - phi)^2 + k."""
    return (1.0 - phase_field) ** 2 + residual_stiffness


def equilibrium_form(u, v, phase_field, material):
    """a(u, v) = int g(phi) sigma_0(u) : eps(v) dx (bilinear in u, v)."""
    return degradation(phase_field, material["residual_stiffness"]) * ufl.inner(
        stress_undegraded(u, material["lame_lambda"], material["lame_mu"]), strain(v)
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
