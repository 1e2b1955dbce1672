"""The learner chooses each state's frame among the demonstrations' bodies
(:mod:`sctd.learn.objects`): a carry segment is in the table top's frame, never in the
carried cup's; without bodies every state is in the task object's frame."""

from __future__ import annotations

import numpy as np
import pytest

from sctd import se3
from sctd.learn.demos import Demo
from sctd.learn.objects import candidate_bodies, choose_objects

N = 30  # rows per segment


def _pose(p, yaw=0.0):
    return np.array([*p, 0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)])


def _in(T_world_body, T_world_x):
    return se3.pose_from_transform(np.linalg.inv(T_world_body) @ T_world_x)


def _demo(seed: int, bodies: bool = True) -> tuple[Demo, list[int]]:
    """Reach the cup on the shelf, then carry it to 15 cm over the table top; the scene
    varies by a few centimetres and degrees per demonstration."""
    rng = np.random.default_rng(seed)
    near = np.array([0.68, 0.18, 0.74]) + rng.uniform(-0.04, 0.04, 3)
    shelf = se3.transform_from_pose(_pose(near, rng.uniform(-0.3, 0.3)))
    far = np.array([0.60, -0.18, 0.58]) + rng.uniform(-0.05, 0.05, 3)
    table = se3.transform_from_pose(_pose(far, rng.uniform(-0.3, 0.3)))
    cup0 = shelf @ se3.transform_from_pose(_pose([*rng.uniform(-0.03, 0.03, 2), 0.0]))
    grasp = cup0 @ se3.transform_from_pose(_pose([0.0, 0.0, 0.05]))
    start = se3.transform_from_pose(_pose(np.array([0.45, 0.05, 0.78]) + rng.uniform(-0.03, 0.03, 3)))
    over = table @ se3.transform_from_pose(_pose([0.0, 0.0, 0.15]))
    hands, cups = [], []
    for s in np.linspace(0.0, 1.0, N):  # reach: the cup stays on the shelf
        H = start.copy()
        H[:3, 3] = (1 - s) * start[:3, 3] + s * grasp[:3, 3]
        hands.append(H)
        cups.append(cup0)
    for s in np.linspace(0.0, 1.0, N + 1)[1:]:  # carry: the cup moves with the hand
        H = grasp.copy()
        H[:3, 3] = (1 - s) * grasp[:3, 3] + s * over[:3, 3]
        hands.append(H)
        cups.append(H @ np.linalg.inv(grasp) @ cup0)
    poses = np.array([_in(C, H) for C, H in zip(cups, hands, strict=True)])
    extra = {}
    if bodies:
        extra = {"shelf": np.array([_in(C, shelf) for C in cups]),
                 "tabletop": np.array([_in(C, table) for C in cups])}
    demo = Demo(f"demo_{seed:03d}", 0.01 * np.arange(len(poses)), poses, bodies=extra)
    return demo, [0] * (N - 1) + [1] * N


@pytest.fixture(scope="module")
def demos():
    made = [_demo(s) for s in range(5)]
    return [d for d, _ in made], {d.name: lab for d, lab in made}


def test_the_reach_stays_in_the_cups_frame_and_the_carry_is_in_the_table_tops(demos):
    ds, labels = demos
    assert candidate_bodies(ds) == ("shelf", "tabletop")
    reach, carry = choose_objects(ds, labels, 2, "cup")
    assert reach.object == "cup"
    assert reach.spread["cup"] < 1e-9 and reach.spread["tabletop"] > 0.02
    assert carry.object == "tabletop"
    assert carry.spread["cup"] is None  # the carried cup moves with the hand: never chosen
    assert carry.spread["tabletop"] < 1e-9 and carry.spread["shelf"] > 0.02
    assert "moves with the hand" in carry.line("s1")


def test_a_body_that_moves_with_the_hand_is_never_chosen_even_when_it_alone_is_left(demos):
    ds, labels = demos
    only_cup = [Demo(d.name, d.t, d.poses) for d in ds]
    (_, carry) = choose_objects(only_cup, labels, 2, "cup")
    assert carry.object == "cup"  # no other body: the task object, as before


def test_without_bodies_every_state_is_in_the_task_objects_frame():
    made = [_demo(s, bodies=False) for s in range(4)]
    ds, labels = [d for d, _ in made], {d.name: lab for d, lab in made}
    assert candidate_bodies(ds) == ()
    assert [c.object for c in choose_objects(ds, labels, 2, "cup")] == ["cup", "cup"]


def test_a_body_only_some_demonstrations_carry_is_no_candidate(demos):
    ds, labels = demos
    partial = [ds[0], *(Demo(d.name, d.t, d.poses, bodies={"shelf": d.bodies["shelf"]}) for d in ds[1:])]
    assert candidate_bodies(partial) == ("shelf",)
    assert [c.object for c in choose_objects(partial, labels, 2, "cup")] == ["cup", "shelf"]


def test_a_state_no_demonstration_shows_stays_in_the_task_objects_frame(demos):
    ds, labels = demos
    assert choose_objects(ds, labels, 3, "cup")[2].object == "cup"


# --- learning: the frame learned in, and each state's -------------------------------------


def _pick_and_place(seed: int, bodies: bool = True) -> Demo:
    """In the cup's frame, with the fingers: reach the cup on the shelf, close, carry it
    to 15 cm over the table top, open, and back up 10 cm."""
    rng = np.random.default_rng(seed)
    shelf = se3.transform_from_pose(_pose(np.array([0.68, 0.18, 0.74]) + rng.uniform(-0.04, 0.04, 3),
                                          rng.uniform(-0.3, 0.3)))
    table = se3.transform_from_pose(_pose(np.array([0.60, -0.18, 0.58]) + rng.uniform(-0.05, 0.05, 3),
                                          rng.uniform(-0.3, 0.3)))
    cup0 = shelf @ se3.transform_from_pose(_pose([*rng.uniform(-0.03, 0.03, 2), 0.0]))
    grasp = cup0 @ se3.transform_from_pose(_pose([0.0, 0.0, 0.05]))
    start = se3.transform_from_pose(_pose(np.array([0.45, 0.05, 0.9]) + rng.uniform(-0.03, 0.03, 3)))
    over = table @ se3.transform_from_pose(_pose([0.0, 0.0, 0.15]))
    hands, cups, held = [], [], []

    def move(a, b, n, carried, hold):
        for s in np.linspace(0.0, 1.0, n + 1)[1:]:
            H = a.copy()
            H[:3, 3] = (1 - s) * a[:3, 3] + s * b[:3, 3]
            hands.append(H)
            cups.append(H @ np.linalg.inv(grasp) @ cup0 if carried else cups[-1] if cups else cup0)
            held.append(hold)

    move(start, start, 1, False, 0.0)
    move(start, grasp, 60, False, 0.0)
    move(grasp, grasp, 5, False, 1.0)  # closed
    move(grasp, over, 60, True, 1.0)
    move(over, over, 5, False, 0.0)  # opened: the cup stays where it was let go
    up = over.copy()
    up[2, 3] += 0.10
    move(over, up, 30, False, 0.0)
    poses = np.array([_in(C, H) for C, H in zip(cups, hands, strict=True)])
    extra = {}
    if bodies:
        extra = {"shelf": np.array([_in(C, shelf) for C in cups]),
                 "tabletop": np.array([_in(C, table) for C in cups])}
    held_a = np.array(held)
    return Demo(f"demo_{seed:03d}", 0.02 * np.arange(len(poses)), poses, np.where(held_a == 1.0, 0.07, 0.08),
                held_a == 1.0, extra)


@pytest.fixture(scope="module")
def picks():
    return [_pick_and_place(s) for s in range(6)]


def test_a_task_object_carried_by_the_hand_is_not_the_frame_learned_in(picks):
    from sctd.learn.gripper import plan_gripper
    from sctd.learn.objects import learning_frame, rebased

    plan = plan_gripper(picks)
    assert plan is not None and [e.action for e in plan.events] == ["close", "open"]
    assert learning_frame(picks, "cup", plan.phases) == "tabletop"
    assert learning_frame(picks, "cup", None) == "cup"  # one phase: the cup moves, and not only with the hand
    moved = rebased(picks, "tabletop", "cup")
    assert set(moved[0].bodies) == {"cup", "shelf"}
    np.testing.assert_allclose(moved[0].poses_in("cup"), picks[0].poses, atol=1e-9)


@pytest.mark.parametrize("method", ["linear", "vf"])
def test_the_learner_puts_the_carry_in_the_table_tops_frame(picks, method):
    from sctd.learn import learn, skill_bundle
    from sctd.skill import skill_from_bundle

    bundle = skill_bundle(learn(picks, method, object="cup"), "pick")
    assert "# Learned in the frame of tabletop: cup moves with the hand" in bundle.yaml_text
    skill = skill_from_bundle(bundle)
    assert skill.object == "cup" and "tabletop" in skill.objects()
    grips = [s.name for s in skill.states if s.gripper is not None]
    assert [skill.states[skill.state_index(n)].gripper.action for n in grips] == ["close", "open"]
    close, open_ = (skill.state_index(n) for n in grips)
    carry = [skill.state_object(k) for k in range(close + 1, open_)]
    assert carry and set(carry) == {"tabletop"}  # never the carried cup


def test_states_choose_their_frames_in_the_frame_of_a_body_that_stays_put(picks):
    """Learned in the shelf's frame (the demonstrations' own), without the fingers: the
    reach is in the cup's frame, the carry in the table top's, and the skill's
    transitions out of them are fitted in their frames."""
    from sctd.learn import learn, skill_bundle
    from sctd.learn.objects import rebased
    from sctd.skill import skill_from_bundle

    # (ten: with six, the learner's last state gets no displacement and no way in)
    ten = [*picks, *(_pick_and_place(s) for s in range(len(picks), 10))]
    in_shelf = [Demo(d.name, d.t, d.poses, bodies=d.bodies) for d in rebased(ten, "shelf", "cup")]
    result = learn(in_shelf, "linear", object="shelf")
    assert result.frame == "shelf"
    chosen = [c.object for c in result.objects]
    assert chosen[0] == "cup" and "tabletop" in chosen
    carry = chosen.index("tabletop")
    assert result.objects[carry].spread["cup"] is None  # the carried cup: never chosen
    skill = skill_from_bundle(skill_bundle(result, "pick"))
    assert skill.object == "shelf" and skill.state_object(0) == "cup"
    assert skill.state_object(carry) == "tabletop"
    assert "Frames (each state's" in skill_bundle(result, "pick").yaml_text
    # the ways back between states in different frames are planes of their own
    assert set(result.back) == {k for k in range(len(chosen) - 1) if chosen[k] != chosen[k + 1]}


def test_demonstrations_without_bodies_learn_what_they_learned_before(picks):
    from sctd.learn import learn, skill_bundle

    plain = [Demo(d.name, d.t, d.poses, d.width, d.grasped) for d in picks]
    result = learn(plain, "linear", object="cup")
    assert result.frame == "cup" and all(c.object == "cup" and not c.spread for c in result.objects)
    text = skill_bundle(result, "pick").yaml_text
    assert "object: cup" in text and text.count("object:") == 1 and "Frames (" not in text


@pytest.mark.parametrize("task", ["pour", "drawer"])
def test_the_shipped_demonstrations_choose_nothing(task):
    from pathlib import Path

    from sctd.learn import learn, read_demos

    root = Path(__file__).resolve().parents[1]
    result = learn(read_demos(root / "skills" / "demos" / task), "linear", object="o")
    assert result.frame == "o" and {c.object for c in result.objects} == {"o"} and not result.back
