"""The Williams near-tip expansion of a traction-free straight crack (Williams 1957), in
Kolosov–Muskhelishvili form; its first term is the auxiliary field of the interaction integral.

With the crack along ``theta = +-pi`` of the tip frame (:class:`~.frame.TipFrame`), every
term ``n = 1, 2, ...`` of

.. math::
    \\phi(z) = \\sum_n A_n z^{n/2},\\qquad
    \\psi(z) = -\\sum_n \\left(\\tfrac n2 A_n + (-1)^n \\bar A_n\\right) z^{n/2}

leaves both faces traction-free (``phi + z conj(phi') + conj(psi) = 0`` at ``theta = +-pi``),
for any complex ``A_n``. ``A_1 = (K_I - i K_II) / sqrt(2 pi)`` gives the classical mode I and II
fields (``sigma_22 = K_I / sqrt(2 pi r)``, ``sigma_12 = K_II / sqrt(2 pi r)`` ahead of the tip);
``A_2 = T / 4`` is the T-stress (``sigma_11 = T``, plus a rigid rotation for ``Im A_2``);
``n >= 3`` are the higher terms (stresses ``O(r^{n/2 - 1})``), which carry no energy release
rate and leave the stress intensity factors unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..physics.materials import LinearElastic
from .frame import TipFrame
from .kolosov import PotentialField, kolosov_fields

__all__ = ["WilliamsField"]


@dataclass(frozen=True)
class WilliamsField(PotentialField):
    """The near-tip field ``K_I``, ``K_II``, ``T`` (+ higher terms) at a tip, vectorised.

    Args:
        material: 2D :class:`~dolfinx_meshfree.LinearElastic` (plane stress or strain: ``kappa``
            and ``mu``). K_I, K_II: stress intensity factors. T: T-stress. higher: complex
            ``A_3, A_4, ...`` of the expansion above. tip, direction: the tip frame (defaults:
            the tip at the origin, the crack along the negative x axis).

    Points are global; displacements, gradients and stresses are returned in global components.
    Points on the crack behind the tip (``theta = +-pi``) take the upper face (principal branch).
    """

    material: LinearElastic
    K_I: float = 0.0
    K_II: float = 0.0
    T: float = 0.0
    higher: tuple[complex, ...] = ()
    tip: tuple[float, float] = (0.0, 0.0)
    direction: tuple[float, float] = (1.0, 0.0)

    @property
    def frame(self) -> TipFrame:
        return TipFrame(np.asarray(self.tip), np.asarray(self.direction))

    @property
    def coefficients(self) -> np.ndarray:
        """Complex ``A_1, A_2, ...`` of the expansion."""
        a1 = (self.K_I - 1j * self.K_II) / np.sqrt(2.0 * np.pi)
        return np.array([a1, self.T / 4.0, *self.higher], dtype=complex)

    def fields(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Displacement (m, 2), displacement gradient (m, 2, 2) (``[:, i, j] = du_i/dx_j``) and
        stress (m, 2, 2) at global points (m, 2), none of them at the tip itself."""
        frame = self.frame
        x = frame.to_local(np.asarray(points, dtype=float).reshape(-1, 2))
        z = x[:, 0] + 1j * x[:, 1]
        if np.any(z == 0):
            raise ValueError(f"the Williams field is singular at the tip {frame.tip.tolist()}")
        root = np.sqrt(z)  # branch cut along the crack, theta = +-pi
        phi, dphi, d2phi = (np.zeros_like(z) for _ in range(3))
        psi, dpsi = np.zeros_like(z), np.zeros_like(z)
        for n, a in enumerate(self.coefficients, start=1):
            lam = 0.5 * n
            b = -(lam * a + (-1) ** n * np.conj(a))
            zl, zl1, zl2 = root**n, root ** (n - 2), root ** (n - 4)
            phi += a * zl
            dphi += a * lam * zl1
            d2phi += a * lam * (lam - 1.0) * zl2
            psi += b * zl
            dpsi += b * lam * zl1
        u, grad, sigma = kolosov_fields(z, phi, dphi, d2phi, psi, dpsi, self.material)
        return (
            frame.vectors_to_global(u),
            frame.tensors_to_global(grad),
            frame.tensors_to_global(sigma),
        )
