"""The plan-based initial guess: on the planned contacts, the switching finger off the
box, at rest where the program demands it."""

import numpy as np
import pytest

from trajectotree.cito.guess import plan_guess, rest_to_rest_progress
from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program, general_spec
from trajectotree.cito.transition import transition_spec
from trajectotree.config import Config, mu_plan
from trajectotree.geometry import world_to_box
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan

CONFIG = Config()


@pytest.fixture(scope="module")
def setup():
    scene = build_scene(CONFIG.scene)
    plan = find_contact_plan(scene, -1.2, CONFIG.search)
    assert plan.success
    return scene, plan


def distances(scene, guess):
    """(K, 4) exact distance of each fingertip sphere from the box, m."""
    tips = BodyParams(scene, 1000.0, mu=scene.config.mu).hand.fingertips(guess.q)
    box = scene.config.shape
    return (
        np.array([[box.signed_distance(world_to_box(x, p)) for p in p_WF] for x, p_WF in zip(guess.x, tips)])
        - scene.tip_radius
    )


def test_rest_to_rest_progress_is_monotone_and_starts_and_ends_at_rest():
    u = rest_to_rest_progress(12)
    assert u[0] == 0.0 and u[-1] == pytest.approx(1.0)
    assert np.all(np.diff(u) > 0)
    assert np.diff(u)[0] < 0.02 and np.diff(u)[-1] < 0.02  # slow at both ends


@pytest.mark.parametrize("method", ["trajectotree", "cito-warm"])
def test_plan_guess_keeps_contacts_and_lifts_the_switching_finger(setup, method):
    scene, plan = setup
    c = CONFIG.cito
    if method == "trajectotree":
        spec = transition_spec(plan, radius=scene.tip_radius, config=c)
    else:
        spec = general_spec(x0=plan.nodes[0].object_pose, q0=plan.nodes[0].q, object_path=plan.object_path, config=c)
    program = build_program(c, spec, BodyParams(scene, c.sdf_sharpness, mu=mu_plan(CONFIG.scene, CONFIG.search)))
    guess = plan_guess(program.rows, spec, plan)
    phi = distances(scene, guess)
    M = c.knots_per_segment
    assert phi.min() > -1e-6  # nothing cuts through the box
    for s, new in enumerate(plan.nodes[1:]):
        ks = np.arange(s * M, (s + 1) * M + 1)
        for i in range(4):
            if i == new.switching_finger:
                assert phi[ks[M // 2], i] > 0.01  # lifted mid-move
            else:
                assert np.abs(phi[ks, i]).max() < 1e-6  # stays on its contact
    np.testing.assert_allclose(guess.x[::M], [n.object_pose for n in plan.nodes], atol=1e-12)
    assert np.abs(guess.xd[spec.rest_knots]).max() == 0.0 and np.abs(guess.qd[spec.rest_knots]).max() == 0.0
