"""Plan a quarter turn of the paper's box, check it, execute it and save a browser playback."""

import math

import trajectotree as tt

result = tt.plan(goal=math.pi / 2)  # contact search + CITO, the paper's scene and defaults
print(f"{result.status}: {len(result.contact_plan.nodes)} nodes, {result.total_time_s:.1f} s")
print("physics check passed:", result.physics_check.passed)  # Newton-Euler, cones, no force at a distance
run = tt.run_simulation(plan=result, html_path="playback.html")  # grasp controller, full dynamics
print(f"dropped: {run.dropped}, final error: {math.degrees(run.final_error[2]):.2f} deg")
tt.save_plan(result, "quarter_turn")  # quarter_turn/plan.json + plan.npz
