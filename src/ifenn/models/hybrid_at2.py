"""AT2 with the hybrid split (Ambati, Gerasimov and De Lorenzis 2015): the paper's model.

Energy per unit volume, phi in [0, 1] the phase field, H the history of the driving force:

    psi = g(phi) psi_0(eps) + Gc gamma(phi, grad phi),
    g(phi) = (1 - phi)^2 + k                                     (degradation; k: residual stiffness)
    gamma = (phi^2 + lc^2 |grad phi|^2) / (2 lc)                   (AT2 crack density)
    H = max over time of psi_0^+(eps)                             (driving force: the tensile energy)

"Hybrid": the stress is g(phi) sigma_0(eps), all of the elastic energy degraded (a linear
displacement problem), while only the tensile part psi_0^+ of the spectral split drives the crack.
The phase-field equation, with zero flux on the boundary,

    -Gc lc Lap(phi) + (Gc/lc) phi = 2 (1 - phi) H,   i.e.   (Gc/lc + 2H) phi - Gc lc Lap(phi) = 2H,

is linear in phi; on the pixel grid it is the pixel equation (:mod:`ifenn.pixel_equation`), whose
coefficients come from :meth:`HybridAT2.pixel_reaction0` and :meth:`HybridAT2.pixel_diffusion`.
"""

from __future__ import annotations


class HybridAT2:
    """The model's functions, for UFL (FEM's forms) and arrays (numpy, torch) alike where both apply.
    UFL is imported by the UFL functions only: the pixel equation runs where no FEM is installed (a GPU
    machine has torch alone)."""

    name = "hybrid-at2"
    #: the phase-field equation is linear in phi (one solve per staggered pass, the pixel equation an M-matrix)
    linear = True

    # ------------------------------------------------------------------ the energy's parts
    @staticmethod
    def degradation(phase_field, residual_stiffness):
        """g(phi) = (1 - phi)^2 + k (UFL or array)."""
        return (1.0 - phase_field) ** 2 + residual_stiffness

    @staticmethod
    def crack_density(phase_field, material):
        """Gc gamma(phi) = Gc/(2 lc) (phi^2 + lc^2 |grad phi|^2): the dissipated energy density (UFL), N/mm^2."""
        import ufl

        Gc, lc = material["Gc"], material["lc"]
        return Gc / (2.0 * lc) * (phase_field**2 + lc**2 * ufl.inner(ufl.grad(phase_field), ufl.grad(phase_field)))

    @staticmethod
    def driving_force(u, material):
        """psi_0^+ = lambda/2 <tr eps>_+^2 + mu eps_+ : eps_+ (UFL, N/mm^2), with the principal strains
        in closed form: of the 2x2 tensor in plane strain; in plane stress with eps_zz = -lambda/(lambda
        + 2 mu) tr(eps) as a third principal strain (the hybrid stress g sigma_0 has sigma_zz = 0 for
        that eps_zz whatever phi is, :mod:`ifenn.fem.elasticity`)."""
        import ufl

        from ifenn.fem.elasticity import positive, principal_strains, strain

        lam, mu = material["lame_lambda"], material["lame_mu"]
        eps = strain(u)
        eps_1, eps_2 = principal_strains(eps)
        if material.get("plane", "strain") == "stress":
            eps_zz = -lam / (lam + 2.0 * mu) * ufl.tr(eps)
            trace = ufl.tr(eps) + eps_zz
            return 0.5 * lam * positive(trace) ** 2 + mu * (positive(eps_1) ** 2 + positive(eps_2) ** 2 + positive(eps_zz) ** 2)
        return 0.5 * lam * positive(ufl.tr(eps)) ** 2 + mu * (positive(eps_1) ** 2 + positive(eps_2) ** 2)

    @staticmethod
    def notch_history(distance, material):
        """H0 of a 'history' notch (Borden et al. 2012) at ``distance`` (mm, array) from its segment:
        B Gc/(2 lc) (1 - 4 d/lc) for d <= lc/4, else 0 (N/mm^2; B = ``history_notch_B``): the history
        at which AT2's local phase field reaches 1 - 1/(B + 1) on the notch line."""
        import numpy as np

        Gc, lc, B = material["Gc"], material["lc"], material["history_notch_B"]
        return np.where(distance <= lc / 4, B * Gc / (2 * lc) * (1 - 4 * distance / lc), 0.0)

    # ------------------------------------------------------------------ FEM's forms
    def equilibrium_form(self, u, v, phase_field, material):
        """a(u, v) = int g(phi) sigma_0(u) : eps(v) dx (bilinear in u, v; linear in g at each point)."""
        import ufl

        from ifenn.fem.elasticity import in_plane_lambda, strain, stress_undegraded

        return self.degradation(phase_field, material["residual_stiffness"]) * ufl.inner(
            stress_undegraded(u, in_plane_lambda(material), material["lame_mu"]), strain(v)
        )

    @staticmethod
    def phase_field_forms(p, q, history, material):
        """Bilinear and linear integrands of -Gc lc Lap(phi) + (Gc/lc) phi = 2 (1 - phi) H with
        zero flux: int Gc lc grad p . grad q + (Gc/lc + 2H) p q dx = int 2 H q dx."""
        import ufl

        Gc, lc = material["Gc"], material["lc"]
        a = Gc * lc * ufl.inner(ufl.grad(p), ufl.grad(q)) + (Gc / lc + 2.0 * history) * p * q
        L = 2.0 * history * q
        return a, L

    # ------------------------------------------------------------------ the pixel equation
    @staticmethod
    def pixel_reaction0(Gc: float, lc: float) -> float:
        """Gc/lc, N/mm^2: the reaction where H = 0 (the pixel equation's a = Gc/lc + 2H)."""
        return Gc / lc

    @staticmethod
    def pixel_diffusion(Gc: float, lc: float) -> float:
        """Gc lc, N: the Laplacian's coefficient (D = Gc lc / h_px^2 on pixels of h_px mm)."""
        return Gc * lc

    @staticmethod
    def pixel_driving(phase_field, history):
        """2 (1 - phi) H (array): the right-hand side of the equation as the network's loss writes it."""
        return 2.0 * (1.0 - phase_field) * history
