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
        weighted = self.inertia_weighted
        A_inv = terms.Lambda if weighted else _NO_MATRIX
        J_pinv, N, A_inv = inverse_at_state(weighted, self.damping, terms.H_inv_Jt, A_inv, terms.J)
        W_inv = terms.H_inv if weighted else np.eye(terms.n)
        return InverseAtState(J_pinv=J_pinv, N=N, A_inv=A_inv, W_inv=W_inv)


_NO_MATRIX = np.zeros((0, 0))  # stands for Λ where the inverse does not use it


@njit(cache=True)
def gram_and_inverse(J: np.ndarray, damping: float) -> tuple[np.ndarray, np.ndarray]:
    """(A, A⁻¹) for A = J Jᵀ + λ² I (λ = ``damping``): the Gram matrix of the unweighted
    inverses (J⁺ = Jᵀ (J Jᵀ)⁻¹, damped least squares) and of the manipulability
    w = √det(J Jᵀ) (:mod:`nsdrake.control.criteria.manipulability`). (m, m) each; A⁻¹ is
    NaN where A is singular (det A = 0: J loses rank and λ = 0)."""
    A = J @ np.ascontiguousarray(J.T)
    if damping != 0.0:
        for i in range(A.shape[0]):
            A[i, i] += damping * damping
    if np.linalg.det(A) == 0.0:
        return A, np.full(A.shape, np.nan)
    return A, np.ascontiguousarray(np.linalg.inv(A))


@njit(cache=True)
def inverse_at_state(inertia_weighted: bool, damping: float, H_inv_Jt, Lambda, J):
    """(J^#, N, A⁻¹) of the module docstring's family: for the dynamically consistent
    inverse (Eq. 13) A⁻¹ = Λ (given, with H⁻¹ Jᵀ), else A⁻¹ = (J Jᵀ + λ² I)⁻¹ and W = I."""
    if inertia_weighted:
        A_inv, W_inv_Jt = Lambda, H_inv_Jt
    else:
        A_inv = gram_and_inverse(J, damping)[1]
        W_inv_Jt = np.ascontiguousarray(J.T)
    J_pinv, N = right_inverse_and_projector(W_inv_Jt, A_inv, J)
    return J_pinv, N, A_inv


@njit(cache=True)
def right_inverse_and_projector(W_inv_Jt: np.ndarray, A_inv: np.ndarray, J: np.ndarray):
    """(J^#, N): J^# = W⁻¹ Jᵀ A⁻¹ and N = I − J^# J (Eq. 4), in one compiled call."""
    J_pinv = W_inv_Jt @ A_inv
    N = -(J_pinv @ J)
    for i in range(N.shape[0]):
        N[i, i] += 1.0
    return J_pinv, N
