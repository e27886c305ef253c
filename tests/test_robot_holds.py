"""A hold in the states the controller skipped is seen through the robot's count (controller.robot_holds)."""

from __future__ import annotations

from controller.robot_holds import RobotHolds


def test_a_hold_in_a_skipped_state_is_seen_through_the_count():
    h = RobotHolds()
    assert h.held_since_last(-1, 1)  # state 0: nothing applied yet (counted by the robot side)
    assert not h.held_since_last(0, 1)
    assert h.held_since_last(-1, 2)  # the state's own hold
    assert not h.held_since_last(2, 2) and h.missed == 0
    # states 4..6 held, 7 applied again; the controller answers 3 and then only 7: the count rose by 3
    assert not h.held_since_last(3, 2)
    assert h.held_since_last(7, 5) and h.missed == 3
    assert not h.held_since_last(8, 5)
    # skipped held states and a held newest one: held, the newest not counted as missed
    assert h.held_since_last(-1, 8) and h.missed == 5
    assert h.held == 4  # the ticks after a hold, either way


def test_the_first_state_and_a_restarted_robot_side_set_the_count_without_a_hold():
    h = RobotHolds()
    assert not h.held_since_last(120, 40)  # a controller (re)started beside a robot that held before
    assert not h.held_since_last(0, 1)  # the robot side restarted: its count starts again, lower
    assert h.held_since_last(5, 3) and h.missed == 2
    assert h.missed == 2 and not h.held_since_last(6, 3)


def test_a_robot_side_without_the_count_leaves_the_flag_alone():
    """A robot side that sends no ``held_cycles`` (0 always) is judged by each state's own flag, as before."""
    h = RobotHolds()
    assert [h.held_since_last(c, 0) for c in (-1, 0, 1, -1, -1, 4)] == [True, False, False, True, True, False]
    assert h.missed == 0


def test_a_robot_back_after_a_loss_sets_the_count_afresh():
    """A real-time robot side restarted holds at 1 kHz until answered: those holds were no skipped states."""
    h = RobotHolds()
    assert not h.held_since_last(10, 1)
    h.reset()  # the controller's robot_back
    assert not h.held_since_last(0, 397) and h.missed == 0
    assert h.held_since_last(3, 398) and h.missed == 1
