"""Whether CITO's programs fit a hand (`check_cito_hand`); the hand's closed-form dynamics they use are
trajectotree.scene.dynamics.HandModel."""

from __future__ import annotations

from trajectotree.config import ConfigError
from trajectotree.scene.plant import Scene


def check_cito_hand(scene: Scene) -> None:
    """ConfigError (CLI exit 2, before any planning) unless CITO's link rows (links.py) fit scene's
    hand: a box on every finger's link 2 and the same links boxed on every finger (a link 1
    without one, as on Drake's gripper, has no rows). Any number of fingers plans."""
    boxed = [tuple(box is not None for box in f.link_boxes) for f in scene.hand_description.fingers]
    problem = None
    if any(not b[1] for b in boxed):
        i = next(i for i, b in enumerate(boxed) if not b[1])
        problem = f"has no collision box on finger {i}'s link 2; CITO's link rows need one"
    elif len(set(boxed)) > 1:
        problem = "boxes different links on different fingers; CITO's link rows need the same on every finger"
    if problem:
        raise ConfigError(
            field="scene.hand",
            value=scene.config.hand,
            problem=problem,
            valid="two-link fingers with a collision box on link 2 (`trajectotree scene` and `search` take any hand)",
            label="valid",
        )
