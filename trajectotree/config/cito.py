"""Contact-implicit trajectory optimization's configuration (CitoConfig) and IPOPT's options."""

from __future__ import annotations

from dataclasses import dataclass

from trajectotree.config.checks import (
    MAX_WEIGHT,
    ConfigError,
    check_bool,
    check_integer,
    check_length,
    check_range,
)


@dataclass(frozen=True)
class CitoConfig:
    """Contact-implicit trajectory optimization (paper Sec. III-B, III-C) and IPOPT."""

    knots_per_segment: int = 12  # M_hat, time steps per transition segment
    dt: float = 0.1  # s, collocation time step
    # Q diagonal, on (x m, y m, theta rad); theta's weight keeps the final orientation within a degree of the goal.
    weight_pose: tuple[float, float, float] = (100.0, 100.0, 300.0)
    weight_torque: float = 1.0  # R = weight_torque * I, on tau (N m)
    weight_force: float = 0.01  # L = weight_force * I, on lambda (N)
    weight_slack: float = 100.0  # L1 penalty on the complementarity slacks gamma (eqs. 5-6), per unit slack
    # L1 penalty on the slacks of the plan's contact-point equalities (eqs. 12-15, TrajectoTree only), per m,
    # large enough that the equalities hold.
    weight_contact_slack: float = 1.0e4
    # Regularization (not in the paper): sum of squared accelerations, which IPOPT's L-BFGS needs to
    # converge; the fewest iterations before the contact-point slacks grow. 0 disables it.
    weight_acceleration: float = 3e-2
    # 1/m, log-sum-exp sharpness of the smooth box distance, sharp because it over-estimates the distance
    # near corners by up to log(2)/k (0.7 mm here), where a switching fingertip may cut the corner.
    sdf_sharpness: float = 1000.0
    # m, TrajectoTree only (not in the paper; configs/paper.yaml sets 0): the switching finger keeps
    # at least switch_clearance sin(pi j / M_hat) between fingertip and box at its segment's j-th
    # knot, and while lifted its normal force is bounded to 0 (it cannot push across the gap), so the
    # optimum cannot skim the box and push it from a distance, which the physics check refuses.
    switch_clearance: float = 0.01
    # Link rows (cito/links.py, not in the paper; configs/paper.yaml turns them off): at every knot
    # whose pose or joints are free, points on each finger's link collision boxes keep the box's
    # half width plus link_clearance off the object, and the object's vertices keep link_clearance
    # off each link-2 box (smooth distances; never more than the program's fixed end knots, the
    # search's nodes, have), because the fingertip spheres alone let links pass through the object.
    link_rows: bool = True  # false: only the fingertip spheres see the object (the paper)
    # Keyframes: each segment is first solved without the link rows, and again with them (from the
    # plan's guess) only when a link then overlaps the object (the physics check's exact test), since
    # most segments never bring a link near it and the rows cost iterations. false: in every segment
    # program from the start.
    link_rows_on_demand: bool = True
    # With link_rows_on_demand: a segment whose straight joint path between its nodes, the object held at the
    # first node's pose, puts a link inside the object is first solved with the link rows of that path's
    # fingers and of the fingers whose links lie within planning.piece.NEAR_NODE_M of the object at either
    # node: it catches all 41 of the 684 segments of the 76 benchmark goals whose solve without rows left a
    # link inside (a retry each), and one to three fingers' rows cost 1.3x a solve without rows, every row
    # 2.3x (docs/measurements.md). false: every segment first without rows.
    link_rows_predicted: bool = True
    # m, the link rows' margin, so that a link the rows hold off the object does not end up touching it.
    link_clearance: float = 0.001
    # IPOPT tol, on the scaled optimality error, loose because constraints are held to constr_viol_tol regardless.
    tol: float = 1e-3
    constr_viol_tol: float = 1e-6  # IPOPT constr_viol_tol
    acceptable_tol: float = 1e-1  # IPOPT acceptable_tol
    acceptable_constr_viol_tol: float = 1e-6  # IPOPT acceptable_constr_viol_tol
    acceptable_iter: int = 5  # IPOPT acceptable_iter
    max_iter: int = 1000  # IPOPT max_iter
    lbfgs_history: int = 6  # IPOPT limited_memory_max_history (fewer iterations than a shorter history)
    print_level: int = 0  # IPOPT print_level (0 silent, 5 verbose)
    formulation: str = "keyframes"  # TrajectoTree: a program per segment between the search's nodes, or "joint" (paper)

    def __post_init__(self):
        check_integer("cito.knots_per_segment", self.knots_per_segment, 2, 200)
        check_range("cito.dt", self.dt, 0.0, 1.0, low_open=True)
        check_length("cito.weight_pose", self.weight_pose, 3, "on x, y, theta")
        for i, v in enumerate(self.weight_pose):
            check_range("cito.weight_pose", v, 0.0, MAX_WEIGHT, index=(i,))
        for name in ("weight_torque", "weight_force", "weight_slack", "weight_contact_slack", "weight_acceleration"):
            check_range(f"cito.{name}", getattr(self, name), 0.0, MAX_WEIGHT)
        check_range("cito.sdf_sharpness", self.sdf_sharpness, 10.0, 1e5)
        check_range("cito.switch_clearance", self.switch_clearance, 0.0, 0.05)
        for name in ("link_rows", "link_rows_on_demand", "link_rows_predicted"):
            check_bool(f"cito.{name}", getattr(self, name))
        check_range("cito.link_clearance", self.link_clearance, 0.0, 0.02)
        for name in ("tol", "constr_viol_tol", "acceptable_tol", "acceptable_constr_viol_tol"):
            check_range(f"cito.{name}", getattr(self, name), 0.0, 1.0, low_open=True)
        check_integer("cito.acceptable_iter", self.acceptable_iter, 0)
        check_integer("cito.max_iter", self.max_iter, 1)
        check_integer("cito.lbfgs_history", self.lbfgs_history, 1, 100)
        check_integer("cito.print_level", self.print_level, 0, 12)
        if self.formulation not in FORMULATIONS:
            raise ConfigError(
                field="cito.formulation", value=self.formulation, problem="is unknown", choices=FORMULATIONS
            )


FORMULATIONS = (
    "keyframes",
    "joint",
)  # cito.formulation values: trajectotree.planning.keyframes, the paper's one program
