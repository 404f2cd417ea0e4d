"""Generalised inverses of the task Jacobian and their null-space projectors.

Section 3.2 of Nemec & Zlajpah (2000). Every inverse here is a member of one
family, the weighted, optionally damped right inverse

    J^# = W⁻¹ Jᵀ (J W⁻¹ Jᵀ + λ² I)⁻¹,

with

- W = H, λ = 0: the dynamically consistent (inertia-weighted) inverse
  J̄ = H⁻¹ Jᵀ Λ, Λ = (J H⁻¹ Jᵀ)⁻¹ (Eq. 13);
- W = I, λ = 0: the Moore–Penrose inverse J⁺ = Jᵀ (J Jᵀ)⁻¹;
- W = I, λ > 0: the damped least-squares inverse.

The null-space projector is N = I − J^# J (Eq. 4). For λ = 0, J J^# = I and
J N = 0; for λ > 0 neither holds exactly, which is what damping costs.

Shapes: J is (m, n) [m/rad], H and W are (n, n), J^# is (n, m).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numba import njit
from pydrake.math import inv


class PseudoInverseKind(str, enum.Enum):
    """Which generalised inverse the null-space controller and projection use."""

    dynamically_consistent = "dynamically_consistent"  # Eq. (13)
    moore_penrose = "moore_penrose"
    damped_least_squares = "damped_least_squares"


@dataclass(frozen=True)
class InverseAtState:
    """A generalised inverse evaluated at one state."""

    J_pinv: np.ndarray  # (n, m) J^#
    N: np.ndarray  # (n, n) null-space projector I − J^# J (Eq. 4)
    A_inv: np.ndarray  # (m, m) (J W⁻¹ Jᵀ + λ² I)⁻¹; Λ for Eq. 13
    W_inv: np.ndarray  # (n, n) the weight's inverse: H⁻¹ (Eq. 13) or I


@dataclass(frozen=True)
class GeneralizedInverse:
    """A choice of J^# (one of :class:`PseudoInverseKind`) with its damping λ [m]."""

    kind: PseudoInverseKind = PseudoInverseKind.dynamically_consistent
    damping: float = 0.0

    def __post_init__(self):
        kind = PseudoInverseKind(self.kind)
        object.__setattr__(self, "kind", kind)
        if not np.isfinite(self.damping) or self.damping < 0:
            raise ValueError(f"pseudo-inverse damping must be a finite number >= 0, got {self.damping}")
        if kind is PseudoInverseKind.damped_least_squares and self.damping == 0:
            raise ValueError("the damped least-squares inverse needs a damping > 0")
        if kind is not PseudoInverseKind.damped_least_squares and self.damping != 0:
            raise ValueError(f"damping is only used by damped_least_squares, not by {kind.value}")

    @property
    def inertia_weighted(self) -> bool:
        return self.kind is PseudoInverseKind.dynamically_consistent

    def at(self, terms) -> InverseAtState:
        """J^#, N, A⁻¹ at the state of ``terms`` (a :class:`nsdrake.control.dynamics.RobotTerms`),
        computed once per RobotTerms and shared by every consumer."""
        return terms.memo(("inverse", self), lambda: self._at(terms))

    def _at(self, terms) -> InverseAtState:
        J, n = terms.J, terms.n
        if self.inertia_weighted:
            W_inv, A_inv = terms.H_inv, terms.Lambda
            J_pinv, N = right_inverse_and_projector(terms.H_inv_Jt, A_inv, J)
        else:
            W_inv = np.eye(n)
            A = J @ J.T
            if self.damping:
                A = A + self.damping**2 * np.eye(J.shape[0])
            A_inv = inv(A)
            J_pinv, N = right_inverse_and_projector(np.ascontiguousarray(J.T), A_inv, J)
        return InverseAtState(J_pinv=J_pinv, N=N, A_inv=A_inv, W_inv=W_inv)


@njit(cache=True)
def right_inverse_and_projector(W_inv_Jt: np.ndarray, A_inv: np.ndarray, J: np.ndarray):
    """(J^#, N): J^# = W⁻¹ Jᵀ A⁻¹ and N = I − J^# J (Eq. 4), in one compiled call."""
    J_pinv = W_inv_Jt @ A_inv
    N = -(J_pinv @ J)
    for i in range(N.shape[0]):
        N[i, i] += 1.0
    return J_pinv, N
