"""Contact-implicit trajectory optimization (paper Sec. III-B, III-C).

variables: the decision-variable layout per knot. hand / contact: closed-form
finger kinematics and dynamics and the smooth box distance. knot: the one
nonlinear evaluator per knot (dynamics and contact rows, analytic Jacobian).
program: the general CITO program. transition: the plan-constrained program.
guess: initial guesses. solve: IPOPT and the per-group violation report.
"""
