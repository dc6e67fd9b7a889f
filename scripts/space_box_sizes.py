"""Which cube sizes the hand in space has an initial grasp of at the grasp point: the check `plan` and `search`
run before planning (cli.space_options.check_space_graspable: search.space_tree.space_initial_grasp, four reachable
contacts in closure at mu_plan, links clear, held within the motors), on cubes every `--step` m from `--low` to
`--high`, the default config's friction, the hand's own mass; prints each size's answer and the ranges that have
one, one process, this machine's CPU.

    python scripts/space_box_sizes.py                       # fingerpro4, 1 mm steps from 5 to 300 mm
    python scripts/space_box_sizes.py --low 0.02 --high 0.03 --step 0.0005
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from trajectotree.config import Config, mu_plan
from trajectotree.scene.spatial import START_POSE, build_space_scene
from trajectotree.search.space_tree import space_initial_grasp


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hand", default="fingerpro4")
    parser.add_argument("--low", type=float, default=0.005)
    parser.add_argument("--high", type=float, default=0.3)
    parser.add_argument("--step", type=float, default=0.001)
    args = parser.parse_args()
    config = Config()
    mu = mu_plan(config.scene, config.search)
    sizes = np.round(np.arange(args.low, args.high + args.step / 2, args.step), 6)
    graspable, times = [], []
    for s in sizes:
        t0 = time.perf_counter()
        scene = build_space_scene(args.hand, mu=config.scene.mu, gravity=config.scene.gravity, size=(s, s, s))
        ok = space_initial_grasp(scene, START_POSE[:4], config.search, mu).success
        times.append(time.perf_counter() - t0)
        graspable.append(ok)
        print(f"{s * 1000:7.1f} mm: {'grasp' if ok else 'none'} ({times[-1]:.2f} s)", flush=True)
    edges = np.flatnonzero(np.diff(np.r_[False, graspable, False]))
    ranges = [f"{sizes[a] * 1000:g}-{sizes[b - 1] * 1000:g} mm" for a, b in zip(edges[::2], edges[1::2])]
    print(
        f"cubes with an initial grasp: {', '.join(ranges) or 'none'}; check time max {max(times):.2f} s, "
        f"median {np.median(times):.2f} s over {len(sizes)} sizes"
    )


if __name__ == "__main__":
    main()
