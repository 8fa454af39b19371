"""Collision chains: split, merge, static bodies and fingers never link, thread-count independence."""
import numpy as np
import pytest

import graspcore
from scenes import box_points

DT = 1e-3


def world_with_boxes(positions, threads=1, gravity=(0, 0, -9.81)):
    w = graspcore.World(threads=threads, gravity=gravity)
    floor = w.add_body(box_points(0.5, 0.5, 0.05), static=True, position=(0, 0, -0.05))
    boxes = [w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1, position=p) for p in positions]
    return w, floor, boxes


def test_static_body_never_joins_two_chains():
    w, floor, (a, b) = world_with_boxes([(-0.1, 0, 0.02), (0.1, 0, 0.02)])
    w.step(DT)
    assert w.body_chain(floor) is None
    assert w.chain_count() == 2
    assert w.body_chain(a) != w.body_chain(b)


def test_chains_merge_and_split_as_boxes_touch_and_part():
    w, floor, (a, b, c) = world_with_boxes([(-0.1, 0, 0.02), (0.1, 0, 0.02), (0.3, 0, 0.02)], gravity=(0, 0, 0))
    w.step(DT, steps=5)
    assert w.chain_count() == 3
    # Push a towards b and c towards b with velocities; they collide and merge.
    w.set_body_velocity(a, (0.5, 0, 0), (0, 0, 0))
    w.set_body_velocity(c, (-0.5, 0, 0), (0, 0, 0))
    merged_at = None
    for i in range(500):
        w.step(DT)
        if w.chain_count() == 1:
            merged_at = i
            break
    assert merged_at is not None
    assert w.body_chain(a) == w.body_chain(b) == w.body_chain(c) == 0
    # Pull them apart again: the chain splits.
    w.set_body_velocity(a, (-0.5, 0, 0), (0, 0, 0))
    w.set_body_velocity(b, (0, 0, 0), (0, 0, 0))
    w.set_body_velocity(c, (0.5, 0, 0), (0, 0, 0))
    w.step(DT, steps=50)
    assert w.chain_count() == 3
    assert len({w.body_chain(a), w.body_chain(b), w.body_chain(c)}) == 3
    # Chains are numbered by their lowest body id.
    assert [w.body_chain(x) for x in (a, b, c)] == [0, 1, 2]


def test_stacking_merges_moving_apart_splits():
    w, floor, (a, b) = world_with_boxes([(0, 0, 0.02), (0.2, 0, 0.02)])
    w.step(DT)
    assert w.chain_count() == 2
    w.set_body_pose(b, (0.0, 0.0, 0.0601), (1, 0, 0, 0))   # put b on top of a
    w.step(DT, steps=100)
    assert w.chain_count() == 1
    w.set_body_pose(b, (0.2, 0.0, 0.02), (1, 0, 0, 0))     # and back on the floor
    w.step(DT)
    assert w.chain_count() == 2


def test_fingers_do_not_link_chains():
    # One finger squeezed between two boxes touches both; they stay two chains.
    w, floor, (a, b) = world_with_boxes([(-0.03, 0, 0.02), (0.03, 0, 0.02)], gravity=(0, 0, 0))
    f = w.add_finger(radius=0.008, stiffness=500.0, position=(0, 0, 0.06))
    w.set_hip(f, (0, 0, 0.02))
    w.step(DT, steps=20)
    assert w.chain_count() == 2


def pile(threads):
    w = graspcore.World(threads=threads)
    w.add_body(box_points(0.5, 0.5, 0.05), static=True, position=(0, 0, -0.05))
    rng = np.random.default_rng(7)
    for s in range(12):                      # twelve separate stacks: twelve chains (enough
        for i in range(3):                   # work to put the solver on the pool)
            w.add_body(box_points(0.02, 0.02, 0.02), mass=0.1 + 0.05 * (s % 4),
                       position=(-0.35 + 0.1 * (s % 6), 0.25 + 0.1 * (s // 6), 0.02 + 0.0405 * i))
    for i in range(16):                      # and a pile falling in a heap
        angle = rng.uniform(0, np.pi)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        q = (np.cos(angle / 2), *(np.sin(angle / 2) * axis))
        w.add_body(box_points(0.02, 0.015, 0.01), mass=0.1, orientation=q,
                   position=(rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), 0.03 + 0.03 * i))
    f = w.add_finger(radius=0.008, stiffness=1000.0, position=(-0.35 + 0.02 + 0.009, 0.25, 0.1))
    hashes = []
    for i in range(800):
        w.set_hip(f, (-0.35 + 0.02 + 0.006, 0.25, 0.1 - 0.00006 * min(i, 500)))
        w.step(DT)
        if i % 100 == 99:
            hashes.append(w.state_hash())
    return hashes, w.chain_count()


def test_state_hash_independent_of_thread_count():
    h1, chains = pile(1)
    assert chains >= 13
    assert pile(2)[0] == h1
    assert pile(4)[0] == h1
