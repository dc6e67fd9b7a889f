"""The paper's fingertip impedance controller with gravity compensation (paper eq. 20):

    tau = sum_i J_WF_i^T (kp (p_ref_i - p_i) + kv (v_ref_i - v_i) + f_ref_i) + g_hand

p_i, v_i are the position and velocity of fingertip i (its sphere centre) in W,
J_WF_i its translational Jacobian, f_ref_i the planned force of finger i on the
box in W (the box pushes back with -f_ref_i, so the motors must supply J^T f_ref),
and g_hand the torques that cancel gravity on the links. The gains are the same
for every planner (paper Sec. IV-D). Torque limits are the plant's effort limits,
which Drake's discrete plant enforces on the actuation input.
"""

from __future__ import annotations

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import BasicVector, LeafSystem

from trajectotree.config import ControllerGains, SceneConfig
from trajectotree.execution.fingers import check_finger_major
from trajectotree.scene.plant import build_scene


class ImpedanceController(LeafSystem):
    """Input ports: `hand_state` (the hand model instance's [q; v], 4F for F fingers), `p_WF_ref`,
    `v_WF_ref`, `f_W_ref` (2F each: finger-major (x, y) in W). Output port:
    `actuation` (2F, the plant's actuation input order)."""

    def __init__(self, scene_config: SceneConfig, gains: ControllerGains):
        super().__init__()
        self.gains = gains
        # Its own plant and context: the controller sees only the measured hand state.
        self._scene = build_scene(scene_config)
        check_finger_major(self._scene)
        self._plant, self._hand = self._scene.plant, self._scene.hand
        self._plant_context = self._plant.CreateDefaultContext()
        self._num_fingers = self._scene.num_fingers
        self._tip_frames = [self._scene.tip_frame(i) for i in range(self._num_fingers)]
        # u = B^T tau_v maps generalized forces to actuators (B is a selection: one actuator per joint).
        self._B = self._plant.MakeActuationMatrix()
        self.hand_state_port = self.DeclareVectorInputPort("hand_state", 2 * self._scene.num_hand_joints)
        self.p_ref_port = self.DeclareVectorInputPort("p_WF_ref", 2 * self._num_fingers)
        self.v_ref_port = self.DeclareVectorInputPort("v_WF_ref", 2 * self._num_fingers)
        self.f_ref_port = self.DeclareVectorInputPort("f_W_ref", 2 * self._num_fingers)
        self.actuation_port = self.DeclareVectorOutputPort(
            "actuation", BasicVector(self._plant.num_actuators()), self.CalcActuation
        )

    def fingertip_kinematics(self, hand_state) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """p_WF (F, 2), v_WF (F, 2) and J_WF (F, 2, nv) at a hand state."""
        plant, ctx = self._plant, self._plant_context
        plant.SetPositionsAndVelocities(ctx, self._hand, hand_state)
        v = plant.GetVelocities(ctx)
        p_WF = np.empty((self._num_fingers, 2))
        J_WF = np.empty((self._num_fingers, 2, plant.num_velocities()))
        for i, frame in enumerate(self._tip_frames):
            p_WF[i] = frame.CalcPoseInWorld(ctx).translation()[:2]
            J_WF[i] = plant.CalcJacobianTranslationalVelocity(
                ctx, JacobianWrtVariable.kV, frame, np.zeros(3), plant.world_frame(), plant.world_frame()
            )[:2]
        return p_WF, J_WF @ v, J_WF

    def compute_actuation(self, hand_state, p_ref, v_ref, f_ref) -> np.ndarray:
        """Eq. 20 for one hand state and references (each (F, 2) or flat (2F,))."""
        p_WF, v_WF, J_WF = self.fingertip_kinematics(hand_state)
        shape = (self._num_fingers, 2)
        F = (
            self.gains.impedance.kp * (np.reshape(p_ref, shape) - p_WF)
            + self.gains.impedance.kv * (np.reshape(v_ref, shape) - v_WF)
            + np.reshape(f_ref, shape)
        )
        tau_v = np.einsum("fiv,fi->v", J_WF, F) - self._plant.CalcGravityGeneralizedForces(self._plant_context)
        return self._B.T @ tau_v

    def CalcActuation(self, context, output):
        output.SetFromVector(
            self.compute_actuation(
                self.hand_state_port.Eval(context),
                self.p_ref_port.Eval(context),
                self.v_ref_port.Eval(context),
                self.f_ref_port.Eval(context),
            )
        )
