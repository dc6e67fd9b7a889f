"""Contact-implicit trajectory optimization (paper Sec. III-B, III-C).

variables: the decision-variable layout per knot. hand / contact: closed-form
finger kinematics and dynamics and the smooth box distance. knot: the one
nonlinear evaluator per knot (dynamics and contact rows, analytic Jacobian).
program: the general CITO program. transition: the plan-constrained program.
guess: initial guesses. solve: IPOPT and the per-group violation report.
A hand in space: space_hand (SO(3) and the fingers' kinematics), spatial (the
keyframes segment program), space_fingers, space_cito, space_joint.
"""
