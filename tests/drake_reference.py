"""Independent recomputation of model quantities with Drake's AutoDiffXd and plain
plant calls, for comparing nsdrake's analytic versions against."""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.math import inv as drake_inv
from pydrake.multibody.tree import JacobianWrtVariable

from nsdrake.control.dynamics import ArmModel


class AutoDiffArm:
    """The arm's plant converted to AutoDiffXd."""

    def __init__(self, arm: ArmModel):
        self.arm = arm
        self.plant = arm.plant.ToAutoDiffXd()
        self.context = self.plant.CreateDefaultContext()
        self.tool = self.plant.GetFrameByName(arm.tool_frame.name(), arm.tool_frame.model_instance())
        self.world = self.plant.world_frame()

    def _jacobian(self, q_ad):
        """The task rows of the tool's spatial Jacobian [J_w; J_v] (translational rows first)."""
        self.plant.SetPositions(self.context, q_ad)
        J = self.plant.CalcJacobianSpatialVelocity(
            self.context, JacobianWrtVariable.kV, self.tool, np.zeros(3), self.world, self.world
        )
        return J[self.arm.spatial_rows]

    def dJ_dq(self, q) -> np.ndarray:
        """(n, m, n): ∂J/∂q_k by forward-mode AutoDiff w.r.t. all of q."""
        J = self._jacobian(InitializeAutoDiff(q))
        m, n = J.shape
        grad = ExtractGradient(J.reshape(-1))  # (m*n, n)
        return grad.T.reshape(n, m, n)

    def Jdot(self, q, v) -> np.ndarray:
        """J̇ along q̇ = v, by one-direction AutoDiff."""
        J = self._jacobian(InitializeAutoDiff(q, np.asarray(v).reshape(-1, 1)))
        return ExtractGradient(J.reshape(-1)).reshape(J.shape)

    def Hdot(self, q, v) -> np.ndarray:
        """Ḣ along q̇ = v."""
        self.plant.SetPositions(self.context, InitializeAutoDiff(q, np.asarray(v).reshape(-1, 1)))
        M = self.plant.CalcMassMatrix(self.context)
        return ExtractGradient(M.reshape(-1)).reshape(M.shape)

    def Jbar_and_dot(self, q, v):
        """J̄ = H⁻¹ Jᵀ (J H⁻¹ Jᵀ)⁻¹ and its time derivative along q̇ = v."""
        q_ad = InitializeAutoDiff(q, np.asarray(v).reshape(-1, 1))
        self.plant.SetPositions(self.context, q_ad)
        M = self.plant.CalcMassMatrix(self.context)
        J = self._jacobian(q_ad)
        M_inv = drake_inv(M)
        Jbar = M_inv @ J.T @ drake_inv(J @ M_inv @ J.T)
        return ExtractValue(Jbar), ExtractGradient(Jbar.reshape(-1)).reshape(Jbar.shape)


def plant_terms(arm: ArmModel, q, v):
    """H, C q̇, g, J, J̇ q̇, x and R_WT straight from the plant (no nsdrake code). J and
    J̇ q̇ take the task rows (translational, then rotational) of the tool's spatial
    Jacobian and of its spatial acceleration bias."""
    plant = arm.plant
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, np.concatenate([q, v]))
    world = plant.world_frame()
    J_spatial = plant.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), world, world
    )
    bias = plant.CalcBiasSpatialAcceleration(
        context, JacobianWrtVariable.kV, arm.tool_frame, np.zeros(3), world, world
    )
    Jdot_v = np.concatenate([bias.rotational(), bias.translational()])
    X_WT = arm.tool_frame.CalcPoseInWorld(context)
    x = X_WT.translation()
    return {
        "H": plant.CalcMassMatrix(context),
        "Cv": plant.CalcBiasTerm(context),
        "g": -plant.CalcGravityGeneralizedForces(context),
        "J": J_spatial[arm.spatial_rows],
        "Jdot_v": Jdot_v[arm.spatial_rows],
        "J_spatial": J_spatial,
        "x": x[arm.rows],
        "p_WT": x,
        "R_WT": X_WT.rotation().matrix(),
    }


def christoffel_C(arm, q, v):
    """C_ij = Σ_k ½ (∂H_ij/∂q_k + ∂H_ik/∂q_j − ∂H_jk/∂q_i) v_k, with ∂H/∂q from AutoDiff."""
    ad = AutoDiffArm(arm)
    ad.plant.SetPositions(ad.context, InitializeAutoDiff(q))
    M = ad.plant.CalcMassMatrix(ad.context)
    n = len(q)
    dH = ExtractGradient(M.reshape(-1)).reshape(n, n, n)  # dH[i, j, k] = ∂H_ij/∂q_k
    # G[i, j, k] = ½(∂_k H_ij + ∂_j H_ik − ∂_i H_jk)
    G = 0.5 * (dH + np.einsum("ikj->ijk", dH) - np.einsum("jki->ijk", dH))
    return np.einsum("ijk,k->ij", G, v)
