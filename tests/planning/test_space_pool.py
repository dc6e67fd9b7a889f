"""The segments of a plan in space solved at once on the segment pool (planning.spatial.solve_space_segments):
from the main thread on the pool the process keeps, the same plan as one after another in this process."""

import os
import threading

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from trajectotree.config import Config
from trajectotree.planning.segment_pool import kept_pool
from trajectotree.planning.spatial import plan_space
from trajectotree.planning.workers import kill_pool
from trajectotree.scene.spatial import START_POSE, build_space_scene

ABOUT_Z = Rotation.from_rotvec([0.0, 0.0, np.radians(30.0)])


@pytest.fixture(scope="module")
def scene_config():
    config = Config()
    scene = build_space_scene("fingerpro4", mu=config.scene.mu, gravity=config.scene.gravity)
    start = Rotation.from_quat(START_POSE[:4], scalar_first=True)
    return scene, config, (ABOUT_Z * start).as_quat(scalar_first=True)


@pytest.mark.slow
def test_the_pool_gives_the_serial_plan(scene_config):
    scene, config, goal = scene_config
    serial = plan_space(scene, goal, config, workers=1)
    pooled = plan_space(scene, goal, config, workers=2)
    assert serial.success and pooled.success, (serial.status, pooled.status)
    assert len(pooled.segments) >= 2
    assert {s["pid"] for s in serial.segments} == {os.getpid()}
    assert os.getpid() not in {s["pid"] for s in pooled.segments}  # solved by the pool's workers
    a, b = serial.trajectory.arrays(), pooled.trajectory.arrays()
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    kill_pool(kept_pool(2, os.getpid()))  # the pool this process kept for workers=2
    kept_pool.cache_clear()


@pytest.mark.slow
def test_another_thread_gets_its_own_pool(scene_config):
    scene, config, goal = scene_config
    made = kept_pool.cache_info().misses
    out = {}
    thread = threading.Thread(target=lambda: out.update(result=plan_space(scene, goal, config, workers=2)))
    thread.start()
    thread.join()
    result = out["result"]
    assert result.success, result.status
    assert os.getpid() not in {s["pid"] for s in result.segments}
    assert kept_pool.cache_info().misses == made  # no pool kept from another thread
