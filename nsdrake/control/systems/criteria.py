"""Criterion systems: each outputs one packed vector [Φ; p; s; a] (:data:`CRITERION_LAYOUT`).

Every criterion of Section 3.5 gives the priority selector the same four things:
its gradient Φ = ∂p/∂q (Eq. 29), its value p, the quantity s that Fig. 1's tree
compares with the criterion's limit, and the activation a ∈ [0, 1] that weighs its
level in the projection of the levels below (:mod:`nsdrake.control.priority`). One packed
port per criterion keeps a criterion to one Python evaluation per control tick;
the controller splits it with Drake's (C++) ``Demultiplexer`` for its diagnostic
ports (``d_min``, ``manipulability``, …).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from nsdrake.control.criteria.joint_limits import activation as joint_limits_activation
from nsdrake.control.criteria.joint_limits import joint_limits_criterion
from nsdrake.control.criteria.joint_torque import joint_torque_criterion
from nsdrake.control.criteria.manipulability import manipulability
from nsdrake.control.criteria.obstacle import ObstacleDistances, obstacle_potential
from nsdrake.control.criteria.obstacle import activation as obstacle_activation
from nsdrake.control.dynamics import RobotTerms
from nsdrake.control.model import ControllerModel
from nsdrake.control.systems._util import declare_scratch

CRITERION_LAYOUT = ("gradient", "value", "switching", "activation")  # [Φ (n); p; s; a]


def criterion_parts(n: int) -> dict[str, int]:
    """The parts of a criterion port for n joints and their sizes, in order."""
    return dict(zip(CRITERION_LAYOUT, (n, 1, 1, 1), strict=True))


def criterion_size(n: int) -> int:
    """Length of a criterion port for n joints."""
    return sum(criterion_parts(n).values())


@njit(cache=True)
def pack_criterion(Phi: np.ndarray, p: float, s: float, a: float) -> np.ndarray:
    """[Φ; p; s; a] (:data:`CRITERION_LAYOUT`)."""
    out = np.empty(Phi.shape[0] + 3)
    out[: Phi.shape[0]] = Phi
    out[-3], out[-2], out[-1] = p, s, a
    return out


def unpack_criterion(packed: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """(Φ, p, s, a) from a criterion port's value."""
    return packed[:-3], float(packed[-3]), float(packed[-2]), float(packed[-1])


class _CriterionSystem(LeafSystem):
    """A system with a ``robot_terms`` input and one ``criterion`` output [Φ; p; s; a]
    computed by ``self._compute(context) -> (Φ, p, s, a)``. Subclasses call
    ``_declare_ports`` after setting their own attributes."""

    def _declare_ports(self, model_terms: RobotTerms):
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self.DeclareVectorOutputPort(
            "criterion",
            criterion_size(model_terms.n),
            lambda c, o: o.SetFromVector(pack_criterion(*self._compute(c))),
            prerequisites_of_calc={self.input_port_ticket(self._terms.get_index())},
        )

    def _compute(self, context):
        raise NotImplementedError


class JointTorqueCriterionSystem(_CriterionSystem):
    """p = ‖Jᵀ F_d‖² and Φ = ∂p/∂q (Eqs. 32–33) for a fixed desired force F_d.

    .. pydrake_system::

        name: JointTorqueCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - criterion

    ``criterion`` is [Φ (n) [N² m²/rad]; p [N² m²]; s = p; a = 1] (:data:`CRITERION_LAYOUT`).
    """

    def __init__(self, *, F_d: np.ndarray, model_terms: RobotTerms):
        super().__init__()
        self._F_d = np.asarray(F_d, dtype=float)
        self._declare_ports(model_terms)

    def _compute(self, context):
        terms = self._terms.Eval(context)
        p, Phi = joint_torque_criterion(terms.J, terms.dJ_dq, self._F_d)
        return Phi, p, p, 1.0


class ManipulabilityCriterionSystem(_CriterionSystem):
    """w = √det(J Jᵀ) and its gradient (:mod:`nsdrake.control.criteria.manipulability`).

    .. pydrake_system::

        name: ManipulabilityCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - criterion

    ``criterion`` is [∂w/∂q (n); w; s = w, compared with w_lim; a = 1] (:data:`CRITERION_LAYOUT`).
    """

    def __init__(self, *, model_terms: RobotTerms):
        super().__init__()
        self._declare_ports(model_terms)

    def _compute(self, context):
        terms = self._terms.Eval(context)
        w, Phi = manipulability(terms.J, terms.dJ_dq)
        return Phi, w, w, 1.0


class JointLimitsCriterionSystem(_CriterionSystem):
    """p = −⅓ Σ max(0, ρ − margin)³ over both limits of every joint, its gradient, the
    smallest margin and the level's activation (:mod:`nsdrake.control.criteria.joint_limits`).

    .. pydrake_system::

        name: JointLimitsCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - criterion

    ``criterion`` is [Φ (n) [rad²]; p [rad³]; s = the smallest distance of a joint to
    one of its limits [rad] (inf without limits), compared with q_lim; a ∈ [0, 1]]
    (:data:`CRITERION_LAYOUT`).
    """

    def __init__(self, *, lower: np.ndarray, upper: np.ndarray, influence: float, model_terms: RobotTerms):
        super().__init__()
        self._lower = np.asarray(lower, dtype=float)
        self._upper = np.asarray(upper, dtype=float)
        self._influence = float(influence)
        self._declare_ports(model_terms)

    def _compute(self, context):
        q = self._terms.Eval(context).q
        p, Phi, margin = joint_limits_criterion(q, self._lower, self._upper, self._influence)
        return Phi, p, margin, joint_limits_activation(margin, self._influence)


class ObstacleCriterionSystem(_CriterionSystem):
    """The obstacle potential p = −⅓ Σ max(0, d_∞ − d)³ over link–obstacle pairs and its
    gradient (Eq. 31, :mod:`nsdrake.control.criteria.obstacle`), from the controller model's own
    geometry (the arm's links and the obstacles it knows about); also d_min, the
    smallest link–obstacle distance (the tool's geometry is not a link).

    .. pydrake_system::

        name: ObstacleCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - criterion

    ``criterion`` is [Φ (n) [m³/rad]; p [m³]; s = d_min [m], compared with d_lim; a ∈ [0, 1]
    (:func:`nsdrake.control.criteria.obstacle.activation`)] (:data:`CRITERION_LAYOUT`).

    The query and the point Jacobians need the model at the same q; the model
    context written for them is per-context scratch memory.
    """

    def __init__(self, *, model: ControllerModel, influence_distance: float, model_terms: RobotTerms):
        super().__init__()
        self._model = model
        self._distances = ObstacleDistances(
            model.plant, model.link_geometries, model.obstacle_geometries, model.scene_graph.model_inspector()
        )
        self._influence = float(influence_distance)
        self._declare_ports(model_terms)
        self._scratch = declare_scratch(self, model.create_scratch)

    def _compute(self, context):
        terms = self._terms.Eval(context)
        scratch = self._scratch.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()
        model = self._model
        plant_context = model.plant_context(scratch)
        model.plant.SetPositions(plant_context, terms.q)
        scene_graph = model.scene_graph
        pairs = self._distances.pairs(
            plant_context,
            self._influence,
            query=lambda: scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(scratch)),
        )
        p, Phi = obstacle_potential(pairs, self._influence, terms.n)
        d_min = min((pair.distance for pair in pairs), default=np.inf)
        return Phi, p, d_min, obstacle_activation(d_min, self._influence)
