"""ContactMonitor: counts contacts that the task does not allow."""

from __future__ import annotations

from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.multibody.tree import BodyIndex

from nsdrake.control.leaf_system import LeafSystem


class ContactMonitor(LeafSystem):
    """The number of contacts between a ``watched`` body (the plate, obstacles)
    and any body outside ``allowed`` (the tool), from the plant's contact
    results (point-pair and hydroelastic).

    .. pydrake_system::

        name: ContactMonitor
        input_ports:
        - contact_results
        output_ports:
        - forbidden_contacts

    ``forbidden_contacts`` (1) is a count.
    """

    def __init__(self, *, plant: MultibodyPlant, watched: set, allowed: set):
        super().__init__()
        self._watched = {int(b) for b in watched}
        self._allowed = {int(b) for b in allowed}
        self._inspector_body = _geometry_to_body(plant)
        self._results = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self.DeclareVectorOutputPort(
            "forbidden_contacts",
            1,
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(self._results.get_index())},
        )

    def _forbidden(self, a: int, b: int) -> bool:
        return (a in self._watched and b not in self._allowed) or (
            b in self._watched and a not in self._allowed
        )

    def _calc(self, context, output):
        results = self._results.Eval(context)
        count = 0
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            count += self._forbidden(int(info.bodyA_index()), int(info.bodyB_index()))
        for i in range(results.num_hydroelastic_contacts()):
            surface = results.hydroelastic_contact_info(i).contact_surface()
            a = self._inspector_body[surface.id_M()]
            b = self._inspector_body[surface.id_N()]
            count += self._forbidden(a, b)
        output.SetAtIndex(0, float(count))


def _geometry_to_body(plant: MultibodyPlant) -> dict:
    """Collision GeometryId → body index, for every body of the plant."""
    table = {}
    for i in range(plant.num_bodies()):
        for geometry in plant.GetCollisionGeometriesForBody(plant.get_body(BodyIndex(i))):
            table[geometry] = i
    return table
