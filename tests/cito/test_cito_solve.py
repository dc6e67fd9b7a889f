"""cito/solve.py on a real one-segment plan: IPOPT's options from the config, the iteration
count and timing read from IPOPT's log, and the per-group violation report, each group
checked against a breach of known size (fingertips from the Drake plant, not the CITO model)."""

import contextlib
import dataclasses
import re

import numpy as np
import pytest
from pydrake.solvers import IpoptSolver

from trajectotree.cito import solve as cito_solve
from trajectotree.cito.guess import plan_guess
from trajectotree.cito.knot import BodyParams
from trajectotree.cito.program import build_program
from trajectotree.cito.transition import transition_spec
from trajectotree.config import CitoConfig, SearchConfig
from trajectotree.geometry import world_to_box
from trajectotree.scene.plant import build_scene
from trajectotree.search.tree import find_contact_plan

CONFIG = CitoConfig(knots_per_segment=6)
MU_PLAN = 0.49


@pytest.fixture(scope="module")
def setup():
    """A 0.2 rad plan of one segment (one finger switches), its program, guess and converged solve
    (the paper's order of the search's children: the push order turns 0.2 rad with all four holding)."""
    scene = build_scene()
    plan = find_contact_plan(scene, 0.2, SearchConfig(num_nodes=2, push_capacity=0.0))
    assert plan.success and plan.nodes[1].switching_finger is not None
    spec = transition_spec(plan, radius=scene.tip_radius, config=CONFIG)
    program = build_program(CONFIG, spec, BodyParams(scene, CONFIG.sdf_sharpness, mu=MU_PLAN))
    guess = plan_guess(program.rows, spec, plan)
    outcome = cito_solve.solve(program, guess, CONFIG)
    assert outcome.success, outcome.status
    return scene, spec, program, guess, outcome


def test_ipopt_options_come_from_the_config():
    config = CitoConfig(
        tol=2e-3,
        constr_viol_tol=3e-6,
        acceptable_tol=0.2,
        acceptable_iter=7,
        max_iter=77,
        lbfgs_history=4,
        print_level=1,
    )
    options = cito_solve.ipopt_options(config).options[IpoptSolver.id().name()]
    assert {
        k: options[k]
        for k in (
            "tol",
            "constr_viol_tol",
            "acceptable_tol",
            "acceptable_iter",
            "max_iter",
            "limited_memory_max_history",
            "print_level",
        )
    } == {
        "tol": 2e-3,
        "constr_viol_tol": 3e-6,
        "acceptable_tol": 0.2,
        "acceptable_iter": 7,
        "max_iter": 77,
        "limited_memory_max_history": 4,
        "print_level": 1,
    }
    assert options["linear_solver"] == "spral" and options["hessian_approximation"] == "limited-memory"
    assert "output_file" not in options
    logged = cito_solve.ipopt_options(config, "/tmp/ipopt.txt").options[IpoptSolver.id().name()]
    assert logged["output_file"] == "/tmp/ipopt.txt" and logged["print_timing_statistics"] == "no"
    timed = cito_solve.ipopt_options(config, "/tmp/ipopt.txt", timing_statistics=True)
    assert timed.options[IpoptSolver.id().name()]["print_timing_statistics"] == "yes"


def test_iterations_and_timing_are_read_from_ipopts_log(setup):
    scene, spec, program, guess, outcome = setup
    table = []  # the last iteration number in IPOPT's own iteration table, read as the solve ends

    @contextlib.contextmanager
    def read_table(log_path):
        yield
        with open(log_path) as f:
            table.extend(int(m.group(1)) for m in re.finditer(r"^\s*(\d+)r?\s+[-+]?\d\.\d+e[-+]\d+", f.read(), re.M))

    capped = cito_solve.solve(program, guess, dataclasses.replace(CONFIG, max_iter=3), read_table, None, True)
    again = cito_solve.solve(program, guess, CONFIG, read_table)
    assert not capped.success and capped.iterations == 3  # stopped by max_iter
    assert again.success and again.iterations == outcome.iterations > 3
    assert table[-1] == again.iterations  # the summary line agrees with the table
    assert set(outcome.timing) == {"ipopt_total_s"}  # without the timing statistics, the total alone
    for result in (capped,):  # with the timing statistics
        assert set(result.timing) == {
            "ipopt_total_s",
            "function_evaluations_s",
            "ipopt_without_function_evaluations_s",
            "nlp_function_evaluations_s",
            "linear_system_factorization_s",
            "linear_system_back_solve_s",
        }
        assert all(v >= 0.0 for v in result.timing.values())
    assert cito_solve._iterations("") == -1 and cito_solve._timing("") == {}  # no log: nothing made up


def plant_penetration(scene, sol) -> float:
    """Deepest fingertip sphere in the box over all knots, with fingertips from the Drake plant."""
    box = scene.config.shape
    phi = [
        [box.signed_distance(world_to_box(x, p)) for p in scene.fingertip_positions(q)] for x, q in zip(sol.x, sol.q)
    ]
    return max(0.0, scene.tip_radius - float(np.min(phi)))


def test_violations_of_the_solution_are_within_ipopts_tolerances(setup):
    scene, spec, program, guess, outcome = setup
    v = cito_solve.violations(program, outcome.solution, scene)
    assert tuple(v) == cito_solve.VIOLATION_GROUPS
    assert v["dynamics"] <= CONFIG.constr_viol_tol and v["friction_cone"] <= CONFIG.constr_viol_tol
    # contact points and distances are slack-relaxed rows (L1 weight 1e4 per m): held to ~10 um
    assert v["contact_point"] <= 1e-5 and v["complementarity"] <= 1e-5
    assert v["penetration"] == pytest.approx(plant_penetration(scene, outcome.solution), abs=1e-12)


def test_each_group_reports_a_breach_of_known_size(setup):
    scene, spec, program, guess, outcome = setup
    sol, k = outcome.solution, 3
    base = cito_solve.violations(program, sol, scene)
    pinned = int(np.flatnonzero(spec.pinned[k])[0])
    free = int(np.flatnonzero(~spec.pinned[k])[0])

    xd = sol.xd.copy()
    xd[k, 0] += 0.1  # the object's velocity jumps: trapezoidal collocation of xd by xdd breaks by 0.1
    assert cito_solve.violations(program, dataclasses.replace(sol, xd=xd), scene)["dynamics"] == pytest.approx(
        0.1, abs=base["dynamics"] + 1e-12
    )

    lambda_n, lambda_t = sol.lambda_n.copy(), sol.lambda_t.copy()
    lambda_n[k, pinned], lambda_t[k, pinned] = -0.03, 0.0  # a finger pulling on the box
    pulled = cito_solve.violations(program, dataclasses.replace(sol, lambda_n=lambda_n, lambda_t=lambda_t), scene)
    assert pulled["friction_cone"] == pytest.approx(0.03, abs=1e-12)
    assert pulled["complementarity"] == base["complementarity"]  # only free fingers count there

    lambda_n = sol.lambda_n.copy()
    lambda_n[k, free] = 0.5  # the lifted switching finger pushes
    phi = (
        scene.config.shape.signed_distance(world_to_box(sol.x[k], scene.fingertip_positions(sol.q[k])[free]))
        - scene.tip_radius
    )
    assert phi > 1e-3
    pushed = cito_solve.violations(program, dataclasses.replace(sol, lambda_n=lambda_n), scene)
    assert pushed["complementarity"] >= 0.5 * phi - 1e-9

    depths = []
    for step in (0.02, -0.02):  # a pinned finger's second joint turns: it slides off its point, one way into the box
        q = sol.q.copy()
        q[k, 2 * pinned + 1] += step
        moved = dataclasses.replace(sol, q=q)
        report = cito_solve.violations(program, moved, scene)
        shift = np.linalg.norm(scene.fingertip_positions(q[k])[pinned] - scene.fingertip_positions(sol.q[k])[pinned])
        assert report["contact_point"] == pytest.approx(shift, abs=base["contact_point"] + 1e-12)
        assert report["penetration"] == pytest.approx(plant_penetration(scene, moved), abs=1e-12)
        depths.append(report["penetration"])
    assert max(depths) > 5e-4  # one of the two turns pushed the fingertip into the box
