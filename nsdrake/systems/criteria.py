"""Criterion systems: each outputs a criterion value p and its gradient Φ = ∂p/∂q."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from ..controller_model import ControllerModel
from ..criteria.joint_torque import joint_torque_criterion
from ..criteria.manipulability import manipulability
from ..criteria.obstacle import ObstacleDistances, activation, obstacle_potential
from ..dynamics import RobotTerms
from ._util import declare_scratch, python_value_producer


class _CriterionSystem(LeafSystem):
    """A system with a ``robot_terms`` input and ``value``/``gradient`` outputs computed
    once per evaluation by ``self._compute(context) -> (p, Φ, *extra)``. Subclasses
    call ``_declare_ports`` after setting their own attributes."""

    def _declare_ports(self, model_terms: RobotTerms):
        """Declares ``robot_terms``, then the outputs."""
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self._deps = {self.input_port_ticket(self._terms.get_index())}
        self._result = self.DeclareCacheEntry(
            description="criterion",
            value_producer=python_value_producer(self._compute),
            prerequisites_of_calc=self._deps,
        )
        self.DeclareVectorOutputPort(
            "value",
            1,
            lambda c, o: o.SetAtIndex(0, self._result.Eval(c)[0]),
            prerequisites_of_calc=self._deps,
        )
        self.DeclareVectorOutputPort(
            "gradient",
            model_terms.n,
            lambda c, o: o.SetFromVector(self._result.Eval(c)[1]),
            prerequisites_of_calc=self._deps,
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
        - value
        - gradient

    ``value`` (1) [N² m²]; ``gradient`` (n) [N² m²/rad].
    """

    def __init__(self, *, F_d: np.ndarray, model_terms: RobotTerms):
        super().__init__()
        self._F_d = np.asarray(F_d, dtype=float)
        self._declare_ports(model_terms)

    def _compute(self, context):
        terms = self._terms.Eval(context)
        return joint_torque_criterion(terms.J, terms.dJ_dq, self._F_d)


class ManipulabilityCriterionSystem(_CriterionSystem):
    """w = √det(J Jᵀ) and its gradient (:mod:`nsdrake.criteria.manipulability`).

    .. pydrake_system::

        name: ManipulabilityCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - value
        - gradient

    ``value`` is w (1); ``gradient`` is ∂w/∂q (n).
    """

    def __init__(self, *, model_terms: RobotTerms):
        super().__init__()
        self._declare_ports(model_terms)

    def _compute(self, context):
        terms = self._terms.Eval(context)
        return manipulability(terms.J, terms.dJ_dq)


class ObstacleCriterionSystem(_CriterionSystem):
    """The obstacle potential p = −⅓ Σ max(0, d_∞ − d)³ over link–obstacle pairs and its
    gradient (Eq. 31, :mod:`nsdrake.criteria.obstacle`), from signed-distance queries
    on the controller model's own scene graph (the arm's link geometry and the
    obstacles it knows about); also d_min, the smallest link–obstacle distance (the
    tool's geometry is not a link).

    .. pydrake_system::

        name: ObstacleCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - value
        - gradient
        - d_min
        - activation

    ``value`` (1) [m³];
    ``gradient`` (n) [m³/rad]; ``d_min`` (1) [m]; ``activation`` (1) ∈ [0, 1], the
    weight of this level in the priority stack (:func:`nsdrake.criteria.obstacle.activation`).

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
        self.DeclareVectorOutputPort(
            "d_min",
            1,
            lambda c, o: o.SetAtIndex(0, self._result.Eval(c)[2]),
            prerequisites_of_calc=self._deps,
        )
        self.DeclareVectorOutputPort(
            "activation",
            1,
            lambda c, o: o.SetAtIndex(0, activation(self._result.Eval(c)[2], self._influence)),
            prerequisites_of_calc=self._deps,
        )

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
        return p, Phi, min((pair.distance for pair in pairs), default=np.inf)
