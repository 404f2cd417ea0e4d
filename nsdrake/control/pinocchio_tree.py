"""Pinocchio's model of an arm, read from the Drake plant that parsed the arm's file.

Whatever the file (URDF, SDF, Drake model directives) and whatever Drake did with it
(``package://`` and relative URIs, a payload welded to the tool), the finalized
``MultibodyPlant`` holds the kinematic tree: each joint's frames on its parent and child
bodies, its axis, and each body's spatial inertia. :func:`pinocchio_model` copies these
numbers into a ``pinocchio.Model``, so Drake and Pinocchio compute from the same numbers
(no second parser, no URDF text written and read back; Pinocchio's SDF reader is not in
the ``pin`` wheel). :func:`nsdrake.control.model.check_agreement` then compares the two
libraries' H, g, C q̇, C and J at random states, as for any Pinocchio model.

Frames, in Drake's monogram notation. A Drake joint connects frame F (fixed on the parent
body P, ``X_PF``) to frame M (fixed on the child body C, ``X_CM``); at q = 0, X_FM = I for
revolute and prismatic joints (their axis is expressed in F and M). Pinocchio's joint
frame J is F, placed in its parent joint's frame J_P by X_J_P,F = X_J_P,P X_PF, and the
child body lies at X_JC = X_CM⁻¹ in it. A weld joint (X_FM fixed) adds no Pinocchio joint:
the child body's inertia joins the parent's joint at X_J_P,C = X_J_P,P X_PF X_FM X_MC.
Axis-aligned joints become Pinocchio's RX, RY, RZ (PX, PY, PZ), the others its unaligned
revolute (prismatic) joints, as Pinocchio's own URDF parser does.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import PrismaticJoint, RevoluteJoint, WeldJoint


def pinocchio_model(plant: MultibodyPlant, frames=()):
    """A ``pinocchio.Model`` of the finalized ``plant``'s tree (module docstring): one
    Pinocchio joint per revolute or prismatic Drake joint (named as in Drake), a BODY frame
    per body, and an OP_FRAME for each Drake frame in ``frames`` that is not a body frame.
    ValueError (one line) for a joint of another kind (floating, ball, planar, …)."""
    import pinocchio as pin

    model = pin.Model()
    world = plant.world_body().index()
    where = {world: (0, pin.SE3.Identity())}  # body → (its Pinocchio joint, X_JB)
    children: dict = {}
    frame_of = {0: 0}  # Pinocchio joint → its joint frame (the universe's is frame 0)
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        children.setdefault(joint.parent_body().index(), []).append(joint)
    queue = [world]
    while queue:
        for joint in children.get(queue.pop(0), []):
            child = joint.child_body()
            where[child.index()] = _add_joint(pin, model, joint, where[joint.parent_body().index()])
            joint_id, X_JC = where[child.index()]
            M_CCo = child.default_spatial_inertia()
            if M_CCo.get_mass() > 0.0:
                c = M_CCo.get_com()
                I_Ccm = M_CCo.Shift(c).CalcRotationalInertia().CopyToFullMatrix3()
                model.appendBodyToJoint(joint_id, pin.Inertia(M_CCo.get_mass(), c, I_Ccm), X_JC)
            if joint_id not in frame_of:
                frame_of[joint_id] = model.addJointFrame(joint_id, frame_of[model.parents[joint_id]])
            model.addBodyFrame(child.name(), joint_id, X_JC, frame_of[joint_id])
            queue.append(child.index())
    for frame in frames:
        if not model.existFrame(frame.name(), pin.BODY) and not model.existFrame(frame.name(), pin.OP_FRAME):
            joint_id, X_JB = where[frame.body().index()]
            X_JT = X_JB * _se3(pin, frame.GetFixedPoseInBodyFrame())
            model.addFrame(
                pin.Frame(frame.name(), joint_id, frame_of[joint_id], X_JT, pin.FrameType.OP_FRAME)
            )
    return model


def _se3(pin, X):
    return pin.SE3(X.rotation().matrix(), X.translation())


def _add_joint(pin, model, joint, parent) -> tuple:
    """(the child body's Pinocchio joint, X_JC) after adding ``joint`` (module docstring)."""
    J_P, X_JP = parent
    X_JF = X_JP * _se3(pin, joint.frame_on_parent().GetFixedPoseInBodyFrame())
    X_MC = _se3(pin, joint.frame_on_child().GetFixedPoseInBodyFrame().inverse())
    if isinstance(joint, WeldJoint):
        return J_P, X_JF * _se3(pin, joint.X_FM()) * X_MC
    if isinstance(joint, RevoluteJoint):
        axis = joint.revolute_axis()
        aligned, unaligned = (
            (pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ),
            pin.JointModelRevoluteUnaligned,
        )
    elif isinstance(joint, PrismaticJoint):
        axis = joint.translation_axis()
        aligned, unaligned = (
            (pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ),
            pin.JointModelPrismaticUnaligned,
        )
    else:
        raise ValueError(
            f"joint '{joint.name()}' is a {joint.type_name()} joint: nsdrake's Pinocchio model takes "
            "revolute, prismatic and fixed joints"
        )
    axis = np.asarray(axis, dtype=float)
    unit = [k for k in range(3) if axis[k] == 1.0 and np.count_nonzero(axis) == 1]
    joint_model = aligned[unit[0]]() if unit else unaligned(axis)
    return model.addJoint(J_P, joint_model, X_JF, joint.name()), X_MC
