"""The fingers as the controllers see them: the check that a hand's state is in the planner's
(finger-major) order, and the closed-form kinematics, dynamics and gravity torques of two-link fingers."""

from __future__ import annotations

import numpy as np

from trajectotree.scene.dynamics import HandModel
from trajectotree.scene.kinematics import TwoLinkFinger, jacobian_from_links
from trajectotree.scene.plant import FingerGeometry, Scene


def check_finger_major(scene: Scene) -> None:
    """ValueError unless the hand instance's positions are the description's joints in order
    (finger-major, each finger's from its base out): the controllers read the instance's state
    port as the planner's q."""
    if not scene.hand_state_is_finger_major:
        raise ValueError(
            f"hand {scene.config.hand}: its model's joints are not in the description's (finger-major) order"
        )


class HandKinematics:
    """Closed-form kinematics (kinematics.TwoLinkFinger) and gravity torques of all the
    two-link fingers at once (the controller's hot path)."""

    def __init__(self, fingers: tuple[FingerGeometry, ...], gravity: float):
        self.fingers = TwoLinkFinger.stack(fingers)
        self._model = HandModel.from_fingers(fingers, gravity)  # CITO's hand dynamics: the same closed forms
        self.damping = np.array([f.damping for f in fingers])  # (F, 2) N m s/rad

    def dynamics(self, q, v) -> tuple[np.ndarray, np.ndarray]:
        """At joint angles q and rates v (2F each): each finger's mass matrix M (F, 2, 2) and the
        torques its motion costs besides M qdd, Coriolis and joint damping, (F, 2)."""
        M = self._model.mass_matrices(np.ravel(q))
        q, v = np.reshape(q, (-1, 2)), np.reshape(v, (-1, 2))
        hs = self._model.mass_b * np.sin(q[:, 1])  # M12 = c + b cos q2: the Coriolis terms' b sin q2
        coriolis = np.column_stack([-hs * (2 * v[:, 0] * v[:, 1] + v[:, 1] ** 2), hs * v[:, 0] ** 2])
        return M, coriolis + self.damping * v

    def __call__(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At joint angles q (2F, finger-major): fingertip centres p_WF (F, 2), Jacobians
        J_WF (F, 2, 2) and the joint torques that hold the fingers up, g (F, 2)."""
        q = np.reshape(q, (-1, 2))
        r1, r2 = self.fingers.links(q)
        p = self.fingers.tip_from_links(r1, r2)
        return p, jacobian_from_links(r1, r2), -self._model.gravity_forces(q.ravel())  # gravity's own home
